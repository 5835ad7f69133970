"""The layer the controller uses: guard, assist and shield in order, one verdict per proposed command."""

from __future__ import annotations

from vlnpilot.core.commands import COMMANDS, HOVER, Command, Kind
from vlnpilot.core.environment import Environment, mover_sensing_of
from vlnpilot.core.fsm import State
from vlnpilot.core.records import Observation, Pose
from vlnpilot.safety.assist import DoorAssist
from vlnpilot.safety.config import (
    ASSIST_NOTE,
    DOOR_STATES,
    GUARD_NOTE,
    SHIELD_NOTE,
    Intervention,
    OscillationEvent,
    SafetyConfig,
    SafetyVerdict,
)
from vlnpilot.safety.guard import OscillationGuard
from vlnpilot.safety.movers import MOVER_REASON, MoverShield, NoWalls
from vlnpilot.safety.shields import Shield, make_shield
from vlnpilot.scene.model import Scene


# -- the layer the controller uses ---------------------------------------------------------------------------------
class SafetyLayer:
    """Guard, assist and shield in the controller's step. `active=False` (shield off): detection only."""

    def __init__(self, scene: Scene, config: SafetyConfig | None = None, shield: Shield | None = None,
                 active: bool = True):
        self.config = config or SafetyConfig()
        self.shield = shield
        self.active = active
        self.assist = DoorAssist(scene, self.config)
        self.guard = OscillationGuard(self.config.oscillation)
        self.interventions: list[Intervention] = []
        self.events: list[OscillationEvent] = []

    @property
    def name(self) -> str:
        if not self.active:
            return "off"
        return self.shield.name if self.shield is not None else "assist"

    def reset(self, obs: Observation) -> None:
        self.guard.reset()
        self.interventions, self.events = [], []
        if self.active and self.shield is not None:
            self.shield.reset(obs)

    def observe(self, obs: Observation) -> None:
        if self.active and self.shield is not None:
            self.shield.observe(obs)

    def filter(self, step: int, state: State, command: Command, next_state: State, pose: Pose) -> SafetyVerdict:
        """The command to execute (and next state) for a validated proposal, with what changed and why."""
        cfg = self.config
        found: list[Intervention] = []
        notes: list[str] = []
        event: OscillationEvent | None = None
        cmd, nxt = command, next_state
        guard_on = self.active and cfg.oscillation_guard

        fired = self.guard.propose(state, command)
        if fired is not None:
            self.guard.committed = True  # one event per stretch; only an active guard acts on it
            self.guard.veto_pending = guard_on
            action = "detection only (safety layer off)"
            if guard_on:
                action = "veto reversals; accept the current alignment"
                notes.append(f"{GUARD_NOTE}: you reversed rotation or sideways direction {fired} times in the last "
                             f"{cfg.oscillation.window} steps without moving forward. Your alignment is good "
                             f"enough; stop re-centring and commit (move forward, or go through the door).")
            event = OscillationEvent(step, state.value, fired, cfg.oscillation.window, guard_on, action)
            self.events.append(event)

        if guard_on and self.guard.veto_pending and self.guard.reverses(cmd):
            self.guard.veto_pending = False
            before = cmd
            al = self.assist.alignment(pose, cfg.oscillation.accept_distance_m)
            band = cfg.oscillation.accept_heading_deg
            if state is State.ORIENTED_TOWARDS_DOOR and al is not None and al.fits and abs(al.heading_err_deg) <= band:
                cmd, nxt = COMMANDS["A1"], State.GO_THROUGH_DOOR
                why = (f"accepted the alignment with the doorway ({abs(al.lateral_m) * 100:.0f} cm off the centre "
                       f"line, within ±{al.clearance_m * 100:.0f} cm; heading {abs(al.heading_err_deg):.0f}° off, "
                       f"within ±{band:.0f}°) and committed to the crossing: A1, state {nxt.value}")
            else:
                cmd = HOVER
                axis = "rotation" if before.is_rotation else "sideways"
                why = (f"vetoed {before.code}, which reverses the last {axis} direction; the current alignment is "
                       f"accepted as good enough, so the drone hovers: move on")
            found.append(Intervention(step, "oscillation_guard", before.code, cmd.code, why))
            notes.append(f"{GUARD_NOTE}: {why}.")

        if self.active and cfg.door_assist and state in DOOR_STATES:
            fix = self.assist.correction(pose, cmd)
            if fix is not None:
                found.append(Intervention(step, "door_assist", cmd.code, fix[0].code, fix[1]))
                notes.append(f"{ASSIST_NOTE}: {fix[1]} (executed {fix[0].code} instead of {cmd.code}).")
                cmd = fix[0]

        if self.active and self.shield is not None:
            safe, blocked = self.shield.filter(pose, cmd)
            side = None
            if blocked is not None and cfg.door_assist and state in DOOR_STATES and cmd.kind is Kind.FORWARD \
                    and safe.kind is Kind.NONE and not blocked.startswith(MOVER_REASON):
                side = self.assist.centring(pose)  # blocked near a doorway: step towards its centre line instead
            if side is not None and self.shield.hazard(pose, side[0].motion()) is None:
                centring, al = side
                text = (f"{cmd.code} is blocked ({blocked}); the drone is {abs(al.lateral_m) * 100:.0f} cm off the "
                        f"centre line of the doorway, so it moves {'right' if al.lateral_m > 0 else 'left'} 10 cm "
                        "instead")
                found.append(Intervention(step, "door_assist", cmd.code, centring.code, text))
                notes.append(f"{ASSIST_NOTE}: {text}.")
                cmd = centring
            elif blocked is not None:
                found.append(Intervention(step, "shield", cmd.code, safe.code, blocked))
                notes.append(f"{SHIELD_NOTE}: {cmd.code} ({cmd.description}) is unsafe: {blocked}; executed "
                             f"{safe.code} ({safe.description}) instead.")
                cmd = safe

        self.guard.executed(cmd)
        self.interventions += found
        return SafetyVerdict(cmd, nxt, tuple(found), event, tuple(notes))


def make_safety(shield: str, env: Environment, scene: Scene, config: SafetyConfig | None = None) -> SafetyLayer:
    """The controller's safety layer for a shield name; 'off' gives a passive layer (oscillation detection only).
    Where people or pets move (`Capabilities.movers`), a shield also keeps the drone clear of them (`MoverShield`)."""
    config = config or SafetyConfig()
    s = make_shield(shield, env, config)
    assist = str(shield).strip().lower() == "assist"  # the parts that need only the map and the pose
    if (s is not None or assist) and (sensing := mover_sensing_of(env)) is not None:
        s = MoverShield(s or NoWalls(config), sensing.movers)  # every shield but `off` keeps clear of movers
    return SafetyLayer(scene, config, s, active=s is not None or assist)
