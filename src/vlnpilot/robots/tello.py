"""The real DJI Tello as an Environment: djitellopy over UDP, the paper's commands, exactly-once moves, safety.

Commands: A2/A3 are `forward 25/50`; B/C are `cw`/`ccw` 15, 45, 90; A1, D1 and D2 (10 cm, below the SDK's
20 cm minimum) are calibrated rc pulses; E sends nothing. A motion is never resent: a rotation whose "ok" is
lost is judged from the state packet's yaw, a translation whose "ok" is lost ends the episode with the drone
hovering until the operator says to land. The pose is dead reckoning from the commands, with the yaw from the
state packet. The Tello senses no contact, so `collided` is None (unknown). Safety: the first Ctrl-C sends
`land`, the second `emergency`; a low battery, the flight-time limit and the geofence land the drone. Every
safety event goes to `events` and, if given, one JSON line each in `event_log`.
"""

from __future__ import annotations

import json
import signal
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from vlnpilot.commands import Command, Kind, get_command
from vlnpilot.environment import Capabilities
from vlnpilot.errors import RobotHalt
from vlnpilot.robots.clock import Clock, WallClock
from vlnpilot.robots.operator import ConsoleOperator
from vlnpilot.robots.tello_config import TelloConfig, load_tello_config
from vlnpilot.robots.tello_link import RobotError, TelloLink
from vlnpilot.scene import Scene, Spawn, load_scene
from vlnpilot.types import Motion, Observation, Pose, wrap_deg

NO_REAR = np.zeros((1, 1, 3), np.uint8)  # the Tello has no rear camera (recordings skip 1x1 placeholders)
SDK_MIN_CM = 20


class TelloEnv:
    """A DJI Tello behind the Environment protocol. One instance flies one episode; `close()` lands it."""

    capabilities = Capabilities(ground_truth=False, depth=False, rear_view=False, contact_sensing=False)

    def __init__(self, scene: str | Scene = "cabin", config: TelloConfig | None = None, *,
                 clock: Clock | None = None, operator: ConsoleOperator | None = None,
                 event_log: str | Path | None = None, handle_sigint: bool = True):
        self.scene = load_scene(scene)
        self.config = config or load_tello_config()
        self.clock = clock or WallClock()
        self.operator = operator or ConsoleOperator()
        self.event_log = Path(event_log) if event_log else None
        self.handle_sigint = handle_sigint
        self.link: TelloLink | None = None
        self.events: list[dict[str, Any]] = []
        self._unreported: list[dict[str, Any]] = []
        self.flying = self.awaiting_operator = self.streaming = self.closed = False
        self.interrupts = 0
        self._old_sigint: Any = None
        self._home = self._pose = Pose(0.0, 0.0, self.scene.flight_altitude, 0.0)
        self._yaw_ref = 0
        self._takeoff_t = 0.0
        self._step = 0

    @property
    def _connected(self) -> TelloLink:
        """The link of the episode under way (`reset` made it)."""
        if self.link is None:
            raise RobotError("the Tello is not connected: reset() starts the episode")
        return self.link

    # -- Environment -----------------------------------------------------------------------------------------
    def reset(self, spawn: str | Spawn | Pose | None = None, seed: int | None = None) -> Observation:
        """Connect, check the battery, start the video, take off, reach flight height; the first observation."""
        if self.link is not None:
            raise RobotError("a TelloEnv flies one episode; make a new one for the next")
        spawn = self.scene.spawns[0] if spawn is None else spawn
        home = (self.scene.spawn(spawn) if isinstance(spawn, str) else spawn)
        home = home.pose if isinstance(home, Spawn) else home
        cfg = self.config
        self.link = link = TelloLink(cfg, self.clock)
        self._install_sigint()
        self._connect(link)
        state = link.fresh_state(2.0)
        if not state:
            raise RobotError(f"the Tello answers but no state packet reaches UDP port {cfg.state_port}; "
                             "check the firewall")
        battery = int(state.get("bat", 0))
        if battery < cfg.takeoff_battery_pct:
            self._event("battery_refused", battery_pct=battery)
            raise RobotError(f"the Tello's battery is at {battery} %, below the take-off floor of "
                             f"{cfg.takeoff_battery_pct} %: charge it before flying")
        if link.send("streamon", cfg.connect_timeout_s) != "ok":
            raise RobotError("the Tello did not start its video stream (streamon); update its firmware")
        self.streaming = True
        link.start_video()
        self._takeoff(link)
        self._event("takeoff", battery_pct=battery)
        self._reach_height(link)
        state = link.fresh_state() or link.state()
        self._yaw_ref = int(state.get("yaw", 0))
        self._home = self._pose = Pose(home.x, home.y, int(state.get("tof", 0)) / 100, home.yaw_deg)
        link.start_keepalive()
        return self._observe(time.monotonic())

    def step(self, command: Command | str) -> Observation:
        cmd = command if isinstance(command, Command) else get_command(command)
        self._check_limits()
        cal = self.config.calibration
        if cmd.is_rotation:
            self._rotate(cmd)
        elif cmd.kind is Kind.FORWARD and cmd.amount * 100 >= SDK_MIN_CM:
            self._translate(f"forward {round(cmd.amount * 100)}", cmd.motion())
        elif cmd.kind is not Kind.NONE:  # A1, D1, D2: rc pulses (rc's first channel is right +)
            pulse = {Kind.FORWARD: cal.forward_10cm, Kind.LATERAL_LEFT: cal.left_10cm,
                     Kind.LATERAL_RIGHT: cal.right_10cm}[cmd.kind]
            lr = {Kind.LATERAL_LEFT: -pulse.speed, Kind.LATERAL_RIGHT: pulse.speed}.get(cmd.kind, 0)
            self._connected.pulse(lr, pulse.speed if cmd.kind is Kind.FORWARD else 0, pulse.duration_s, pulse.settle_s)
            self._pose = cmd.motion().apply(self._pose)
        self._step += 1
        self._update_attitude()
        obs = self._observe(time.monotonic())
        away = self._pose.distance_xy(self._home)
        if away > self.config.geofence_m:
            self._land_and_halt(f"dead reckoning puts the drone {away:.1f} m from take-off, past the geofence of "
                                f"{self.config.geofence_m:g} m", "geofence", obs)
        return obs

    # -- start-up ----------------------------------------------------------------------------------------------
    def _connect(self, link: TelloLink) -> None:
        cfg = self.config
        reply = link.send("command", cfg.connect_timeout_s) or link.send("command", cfg.connect_timeout_s)
        if reply is None:  # "command" only enters SDK mode: asking twice is harmless
            raise RobotError(f"no reply from a Tello at {cfg.host}:{cfg.command_port} within "
                             f"{2 * cfg.connect_timeout_s:g} s: is this computer on the Tello's Wi-Fi "
                             "(TELLO-XXXXXX) and the drone switched on?")
        if reply != "ok":
            raise RobotError(f"the device at {cfg.host}:{cfg.command_port} answered {reply!r} to 'command'; "
                             "is it a Tello?")

    def _takeoff(self, link: TelloLink) -> None:
        reply = link.send("takeoff", self.config.takeoff_timeout_s)
        if reply is None:
            state = link.fresh_state() or {}
            if int(state.get("tof", 0)) < 30:
                raise RobotError("no reply to 'takeoff' and the drone is not airborne")
        elif reply != "ok":
            raise RobotError(f"the Tello refused to take off: {reply}")
        self.flying, self._takeoff_t = True, self.clock.now()

    def _reach_height(self, link: TelloLink) -> None:
        """Climb or descend to the flight height by the time-of-flight sensor (SDK moves of 20 cm or more)."""
        target = self.config.flight_height_m or self.scene.flight_altitude
        state = link.fresh_state() or link.state()
        cm = round(target * 100 - int(state.get("tof", 0)))
        if abs(cm) >= SDK_MIN_CM:
            verb = "up" if cm > 0 else "down"
            try:
                self._translate(f"{verb} {min(abs(cm), 500)}", Motion(vertical_m=cm / 100))
            except RobotHalt as halt:
                self.land()
                raise RobotError(f"could not reach flight height: {halt}") from None

    # -- motions (each sent once) ---------------------------------------------------------------------------
    def _translate(self, sdk: str, motion: Motion) -> None:
        reply = self._connected.send(sdk)
        if reply == "ok":
            self.clock.sleep(self.config.calibration.move_settle_s)
            self._pose = motion.apply(self._pose)
            return
        if reply is None:
            self.awaiting_operator = True
            self._event("lost_reply", command=sdk, action="not resent; hovering until the operator says to land")
            raise RobotHalt(f"no reply to '{sdk}': the move may or may not have happened, so it is not sent again; "
                            "the drone hovers until the operator says to land", self._observe(time.monotonic()),
                            landed=False)
        self._land_and_halt(f"the Tello refused '{sdk}': {reply}", "refused")

    def _rotate(self, cmd: Command) -> None:
        verb = "cw" if cmd.kind is Kind.ROTATE_RIGHT else "ccw"
        sdk = f"{verb} {round(cmd.amount)}"
        before = int(self._connected.state().get("yaw", 0))
        reply = self._connected.send(sdk)
        if reply == "ok":
            self.clock.sleep(self.config.calibration.move_settle_s)
            return
        if reply is not None:
            self._land_and_halt(f"the Tello refused '{sdk}': {reply}", "refused")
        after = self._connected.fresh_state() or self._connected.state()
        turned = wrap_deg(int(after.get("yaw", before)) - before)  # Tello yaw grows clockwise
        expected = cmd.amount if verb == "cw" else -cmd.amount
        tol = self.config.calibration.yaw_tolerance_deg
        if abs(wrap_deg(turned - expected)) <= tol:
            self._event("lost_reply", command=sdk, action=f"yaw turned {turned:.0f}°: the rotation happened")
        elif abs(turned) <= tol:
            self._event("lost_reply", command=sdk, action="yaw unchanged: the rotation did not happen; not resent")
        else:
            self.awaiting_operator = True
            self._event("lost_reply", command=sdk, action=f"yaw turned {turned:.0f}° of {expected:.0f}°: unclear")
            raise RobotHalt(f"no reply to '{sdk}' and the yaw turned {turned:.0f}° of {expected:.0f}°; the drone "
                            "hovers until the operator says to land", self._observe(time.monotonic()), landed=False)

    def _update_attitude(self) -> None:
        """Yaw from the state packet (relative to take-off, clockwise), height from the time-of-flight sensor."""
        state = self._connected.fresh_state() or self._connected.state()
        yaw = wrap_deg(self._home.yaw_deg - wrap_deg(int(state.get("yaw", self._yaw_ref)) - self._yaw_ref))
        z = int(state.get("tof", round(self._pose.z * 100))) / 100
        self._pose = Pose(self._pose.x, self._pose.y, z, yaw)

    def _observe(self, settled_at: float) -> Observation:
        image, timing = self._connected.fresh_frame(settled_at)
        state = self._connected.state()
        info = {**timing, "battery_pct": state.get("bat"), "tof_cm": state.get("tof"),
                "keepalives": self._connected.keepalives, "events": self._unreported}
        self._unreported = []
        return Observation(front_rgb=image, rear_rgb=NO_REAR, pose=self._pose, collided=None, step=self._step,
                           info=info)

    # -- safety -----------------------------------------------------------------------------------------------
    def _check_limits(self) -> None:
        cfg = self.config
        battery = self._connected.state().get("bat")
        if battery is not None and int(battery) < cfg.land_battery_pct:
            self._land_and_halt(f"battery at {battery} %, below the landing floor of {cfg.land_battery_pct} %",
                                "battery_low")
        flown = self.clock.now() - self._takeoff_t
        if flown > cfg.max_flight_s:
            self._land_and_halt(f"{flown:.0f} s of flight passed the limit of {cfg.max_flight_s:g} s", "flight_time")

    def _land_and_halt(self, reason: str, kind: str, obs: Observation | None = None) -> None:
        self._event(kind, reason=reason, action="land")
        self.land()
        raise RobotHalt(reason, obs or self._observe(time.monotonic()), landed=True)

    def land(self) -> None:
        if self.flying and self.link is not None:
            reply = None
            for _ in range(3):  # unlike a move, a repeated `land` is harmless: ask again when the "ok" is lost
                reply = self.link.send("land")  # the Tello answers once it is down (a few seconds)
                if reply is not None:
                    break
            self.flying = self.awaiting_operator = False
            self._event("land", reply=reply)

    def _event(self, kind: str, **facts: Any) -> None:
        event = {"event": kind, "t": round(self.clock.now() - self._takeoff_t, 3) if self._takeoff_t else 0.0,
                 **facts}
        self.events.append(event)
        self._unreported.append(event)
        if self.event_log is not None:
            with open(self.event_log, "a", encoding="utf-8") as f:
                f.write(json.dumps(event) + "\n")

    def _install_sigint(self) -> None:
        if self.handle_sigint and threading.current_thread() is threading.main_thread():
            self._old_sigint = signal.signal(signal.SIGINT, self._on_sigint)

    def _on_sigint(self, signum: int, frame: object) -> None:
        """First Ctrl-C: `land`; any further one: `emergency` (motors off). Both bypass the command lock."""
        self.interrupts += 1
        command = "land" if self.interrupts == 1 else "emergency"
        if self.link is not None:
            self.link.emergency_send(command)
        self.flying = self.awaiting_operator = False
        self._event("operator_interrupt", action=command)
        raise KeyboardInterrupt

    # -- shutdown ---------------------------------------------------------------------------------------------
    def close(self) -> None:
        """Land (after the operator's word if a lost reply left the drone hovering), stop the video, let go."""
        if self.link is None or self.closed:
            return
        self.closed = True
        try:
            if self.flying and self.awaiting_operator:
                self.operator.wait("The Tello is hovering after a lost reply. Press Enter to land it.")
            self.land()
            if self.streaming:
                self.link.send("streamoff", self.config.connect_timeout_s)
        finally:
            self.link.close()
            if self._old_sigint is not None:
                signal.signal(signal.SIGINT, self._old_sigint)
                self._old_sigint = None

    def __enter__(self) -> TelloEnv:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
