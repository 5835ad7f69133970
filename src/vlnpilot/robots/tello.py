"""The real DJI Tello as an Environment: djitellopy over UDP, the paper's commands, exactly-once moves, safety.

Commands: A2/A3 are `forward 25/50`; B/C are `cw`/`ccw` 15, 45, 90; A1, D1 and D2 (10 cm, below the SDK's
20 cm minimum) are calibrated rc pulses; E sends nothing. A motion is never resent: a rotation whose "ok" is
lost is judged from the state packet's yaw (one that did not happen is recorded as not executed), a
translation whose "ok" is lost ends the episode with the drone hovering until the operator says to land. The
pose is dead reckoning from confirmed commands only (an "ok", or for an rc pulse a state packet after it and an
answer to a query sent after it), with the yaw from the state packet. The Tello senses no contact, so `collided`
is None (unknown). Safety: the first Ctrl-C stops any rc pulse and lands the drone (`land` resent until it is
down), the second sends `emergency`; a low battery and the flight-time limit land it, between steps too (the
watchdog checks them while the pilot or the operator takes its time), and so does the geofence; a landing the
drone does not confirm is resent, then `emergency`; the link watchdog (`tello_watchdog`) lands it when the state
packets or the video go silent, and the episode ends `link_lost`; a drone found on the ground (it landed by
itself) ends the episode. Every safety event goes to `events` and, if given, one JSON line each in `event_log`.
"""

from __future__ import annotations

import json
import signal
import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from vlnpilot.core.commands import Command, Kind, get_command
from vlnpilot.core.environment import Capabilities, check_sensors
from vlnpilot.core.errors import LinkLost, RobotHalt
from vlnpilot.core.ranging import RangeReading, range_sensor, tof_reading
from vlnpilot.core.records import Motion, Observation, Pose, wrap_deg
from vlnpilot.robots.clock import Clock, WallClock
from vlnpilot.robots.operator import ConsoleOperator
from vlnpilot.robots.tello_config import TelloConfig, load_tello_config
from vlnpilot.robots.tello_link import LinkError, RobotError, TelloLink, on_ground
from vlnpilot.robots.tello_watchdog import LinkWatchdog
from vlnpilot.scene import Scene, Spawn, load_scene

NO_REAR = np.zeros((1, 1, 3), np.uint8)  # the Tello has no rear camera (recordings skip 1x1 placeholders)
SDK_MIN_CM = 20
STREAMON_TRIES = 3  # `streamon` only starts the video: resending it when its reply is lost is safe


def tello_capabilities(config: TelloConfig) -> Capabilities:
    """What the drone the settings describe carries: a RoboMaster TT its forward ToF (`ext_tof`)."""
    return replace(TelloEnv.capabilities, range_sensor="tof" if config.ext_tof else "none")


class TelloEnv:
    """A DJI Tello behind the Environment protocol. One instance flies one episode; `close()` lands it."""

    capabilities = Capabilities(ground_truth=False, depth=False, rear_view=False, contact_sensing=False)

    def __init__(self, scene: str | Scene = "cabin", config: TelloConfig | None = None, *,
                 clock: Clock | None = None, operator: ConsoleOperator | None = None,
                 event_log: str | Path | None = None, handle_sigint: bool = True, link_clock: Clock | None = None,
                 sensors: str = "none"):
        self.scene = load_scene(scene)
        self.config = config or load_tello_config()
        check_sensors(tello_capabilities(self.config), "plain Tello (tello.yaml: ext_tof false)", sensors)
        self.range_sensor = range_sensor(sensors)
        if self.range_sensor is not None:  # flown with its ToF: the pilot is told its readings
            self.capabilities = replace(TelloEnv.capabilities, range_sensor=self.range_sensor.name)
        self.clock = clock or WallClock()
        # The link's packets arrive in real time, so the watchdog judges their silence on the wall clock unless a
        # test drives it with a clock of its own.
        self.link_clock = link_clock or WallClock()
        self.watchdog: LinkWatchdog | None = None
        # the watchdog reports from its own thread; re-entrant, as a Ctrl-C may land while this thread holds it
        self._event_lock = threading.RLock()
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
    def ranges(self) -> tuple[RangeReading, ...]:
        """The TT's forward ToF (`EXT tof?`, mm, 8192 beyond range); () without it or when no reply came."""
        if self.range_sensor is None or self.link is None:
            return ()
        answer = self.link.send("EXT tof?", self.config.query_timeout_s)
        try:
            return (tof_reading(answer or "", self.range_sensor),)
        except ValueError:
            self._event("tof_unread", answer=answer)
            return ()

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
            raise LinkError(f"the Tello answers but no state packet reaches UDP port {cfg.state_port}; "
                            "check the firewall")
        battery = int(state.get("bat", 0))
        if battery < cfg.takeoff_battery_pct:
            self._event("battery_refused", battery_pct=battery)
            raise RobotError(f"the Tello's battery is at {battery} %, below the take-off floor of "
                             f"{cfg.takeoff_battery_pct} %: charge it before flying")
        self._stream_on(link)
        link.start_video()
        if not link.first_frame(cfg.frame_timeout_s):
            raise LinkError(f"no video frame from the Tello within {cfg.frame_timeout_s:g} s of 'streamon' (UDP port "
                            f"{cfg.video_port}): it is not taking off blind; check the firewall")
        self.watchdog = LinkWatchdog(link, self.link_clock, silence_s=cfg.link_silence_s,
                                     video_silence_s=cfg.video_silence_s, land_confirm_s=cfg.land_confirm_s,
                                     report=self._event, limits=self._limit_passed)
        self.watchdog.start()  # from take-off on, a dead link lands the drone
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
        self._check_link()  # a link found dead (or the drone landed) while the pilot thought: nothing is sent
        self._check_airborne()
        self._check_limits()
        executed = True
        if cmd.is_rotation:
            executed = self._rotate(cmd)
        elif cmd.kind is Kind.FORWARD and cmd.amount * 100 >= SDK_MIN_CM:
            self._translate(f"forward {round(cmd.amount * 100)}", cmd.motion())
        elif cmd.kind is not Kind.NONE:
            self._pulse(cmd)
        self._step += 1
        self._update_attitude()
        obs = self._observe(time.monotonic(), executed)
        self._check_link(executed, obs)  # the move was confirmed, but no fresh frame will show it
        away = self._pose.distance_xy(self._home)
        if away > self.config.geofence_m:
            self._land_and_halt(f"dead reckoning puts the drone {away:.1f} m from take-off, past the geofence of "
                                f"{self.config.geofence_m:g} m", "geofence", obs, executed=True)
        return obs

    # -- start-up ----------------------------------------------------------------------------------------------
    def _connect(self, link: TelloLink) -> None:
        cfg = self.config
        reply = link.send("command", cfg.connect_timeout_s) or link.send("command", cfg.connect_timeout_s)
        if reply is None:  # "command" only enters SDK mode: asking twice is harmless
            raise LinkError(f"no reply from a Tello at {cfg.host}:{cfg.command_port} within "
                            f"{2 * cfg.connect_timeout_s:g} s: is this computer on the Tello's Wi-Fi "
                            "(TELLO-XXXXXX) and the drone switched on?")
        if reply != "ok":
            raise RobotError(f"the device at {cfg.host}:{cfg.command_port} answered {reply!r} to 'command'; "
                             "is it a Tello?")

    def _stream_on(self, link: TelloLink) -> None:
        """`streamon`, resent while its reply is lost (it only starts the video); a refusal is the firmware's."""
        timeout = self.config.connect_timeout_s
        for _ in range(STREAMON_TRIES):
            reply = link.send("streamon", timeout)
            if reply is not None:
                break
            self._event("lost_reply", command="streamon", action="resent (it only starts the video)")
        else:
            raise LinkError(f"no reply to 'streamon' in {STREAMON_TRIES} tries of {timeout:g} s: the link loses "
                            "the Tello's replies; move closer to the drone or away from other Wi-Fi")
        if reply != "ok":
            raise RobotError(f"the Tello refused to start its video stream (streamon: {reply!r}); update its "
                             "firmware")
        self.streaming = True

    def _takeoff(self, link: TelloLink) -> None:
        """`takeoff`, its reply awaited `takeoff_timeout_s` (well inside the Tello's 15 s auto-land), else judged
        from the time-of-flight sensor. From here on `close()` lands the drone whatever happens."""
        self.flying, self._takeoff_t = True, self.clock.now()
        reply = link.send("takeoff", self.config.takeoff_timeout_s)
        if reply is None:
            state = None if link.lost.is_set() else link.fresh_state()
            if state is None:
                raise LinkError(f"the link to the Tello died during take-off ({self._lost_reason()}); 'land' sent")
            if int(state.get("tof", 0)) < 30:
                raise LinkError(f"no reply to 'takeoff' within {self.config.takeoff_timeout_s:g} s and the drone "
                                "is not airborne")
            self._event("lost_reply", command="takeoff", action=f"airborne at {state.get('tof')} cm: flying on")
        elif reply != "ok":
            raise RobotError(f"the Tello refused to take off: {reply}")

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
                raise (LinkError if isinstance(halt, LinkLost) else RobotError)(
                    f"could not reach flight height: {halt}") from None

    # -- motions (each sent once) ---------------------------------------------------------------------------
    def _translate(self, sdk: str, motion: Motion) -> None:
        reply = self._connected.send(sdk)
        if reply == "ok":
            self.clock.sleep(self.config.calibration.move_settle_s)
            self._pose = motion.apply(self._pose)
            return
        if reply is None:
            self._confirm_link(f"no reply to '{sdk}'")
            self.awaiting_operator = True
            self._event("lost_reply", command=sdk, action="not resent; hovering until the operator says to land")
            raise RobotHalt(f"no reply to '{sdk}': the move may or may not have happened, so it is not sent again; "
                            "the drone hovers until the operator says to land", self._observe(time.monotonic(), False),
                            landed=False)
        self._land_and_halt(f"the Tello refused '{sdk}': {reply}", "refused")

    def _rotate(self, cmd: Command) -> bool:
        """Whether the rotation happened: its "ok", or with the reply lost, the yaw of a state packet after it."""
        verb = "cw" if cmd.kind is Kind.ROTATE_RIGHT else "ccw"
        sdk = f"{verb} {round(cmd.amount)}"
        before = int(self._connected.state().get("yaw", 0))
        reply = self._connected.send(sdk)
        if reply == "ok":
            self.clock.sleep(self.config.calibration.move_settle_s)
            return True
        if reply is not None:
            self._land_and_halt(f"the Tello refused '{sdk}': {reply}", "refused")
        after = self._confirm_link(f"no reply to '{sdk}'")
        turned = wrap_deg(int(after.get("yaw", before)) - before)  # Tello yaw grows clockwise
        expected = cmd.amount if verb == "cw" else -cmd.amount
        tol = self.config.calibration.yaw_tolerance_deg
        if abs(wrap_deg(turned - expected)) <= tol:
            self._event("lost_reply", command=sdk, action=f"yaw turned {turned:.0f}°: the rotation happened")
            return True
        if abs(turned) <= tol:
            self._event("lost_reply", command=sdk, action="yaw unchanged: the rotation did not happen; not resent")
            return False
        self.awaiting_operator = True
        self._event("lost_reply", command=sdk, action=f"yaw turned {turned:.0f}° of {expected:.0f}°: unclear")
        raise RobotHalt(f"no reply to '{sdk}' and the yaw turned {turned:.0f}° of {expected:.0f}°; the drone "
                        "hovers until the operator says to land", self._observe(time.monotonic(), False), landed=False)

    def _pulse(self, cmd: Command) -> None:
        """A1, D1, D2: a timed rc pulse (rc's first channel is right +). The Tello never answers `rc`, so a
        state packet after the pulse is the evidence that it went over a live link; only then does the pose move."""
        cal = self.config.calibration
        pulse = {Kind.FORWARD: cal.forward_10cm, Kind.LATERAL_LEFT: cal.left_10cm,
                 Kind.LATERAL_RIGHT: cal.right_10cm}[cmd.kind]
        lr = {Kind.LATERAL_LEFT: -pulse.speed, Kind.LATERAL_RIGHT: pulse.speed}.get(cmd.kind, 0)
        self._connected.pulse(lr, pulse.speed if cmd.kind is Kind.FORWARD else 0, pulse.duration_s, pulse.settle_s)
        self._confirm_link(f"the rc pulse of {cmd.code}")
        self._confirm_uplink(f"the rc pulse of {cmd.code}")
        self._pose = cmd.motion().apply(self._pose)

    # -- the link ---------------------------------------------------------------------------------------------
    def _confirm_link(self, what: str) -> dict[str, Any]:
        """A state packet that arrived after `what`; none within 1.5 s means the link is dead: land, end."""
        link = self._connected
        state = None if link.lost.is_set() else link.fresh_state()
        if state is None:
            self._declare_lost(f"{what} and no state packet after it")
        return state

    def _confirm_uplink(self, what: str) -> None:
        """A state packet shows that the drone's packets reach us, not that ours reach it: a query answered after
        `what` does. None answered: the commands no longer reach the drone; land (it lands by itself 15 s after
        the last command it received), end."""
        link = self._connected
        if link.send("battery?", self.config.query_timeout_s) is None and not link.lost.is_set():
            self._declare_lost(f"{what} and no answer to a query after it: commands do not reach the drone")

    def _declare_lost(self, reason: str) -> NoReturn:
        """The backend saw the link die itself: the watchdog lands the drone at once, the episode ends."""
        if self.watchdog is not None:
            self.watchdog.declare_lost(reason)
        self._link_lost(executed=False)

    def _check_link(self, executed: bool = False, obs: Observation | None = None) -> None:
        """Once the watchdog has landed the drone, end the episode: `link_lost`, or halted by the limit it landed
        for."""
        if self.link is None or not self.link.lost.is_set():
            return
        dog = self.watchdog
        if dog is not None and dog.cause not in ("", "link"):
            self.flying = self.awaiting_operator = False  # the watchdog lands it; nothing else is sent
            raise RobotHalt(f"{dog.reason}: 'land' sent", obs or self._observe(time.monotonic(), executed),
                            landed=True, executed=executed)
        self._link_lost(executed, obs)

    def _check_airborne(self) -> None:
        """A drone found on the ground landed by itself (the Tello does 15 s after its last command, as when this
        computer slept): nothing more is flown."""
        if self.flying and on_ground(self._connected.state()):
            self.flying = self.awaiting_operator = False
            self._event("auto_landed", action="the episode ends")
            raise RobotHalt("the drone is on the ground: it landed by itself (a Tello lands 15 s after the last "
                            "command it received)", self._observe(time.monotonic(), False), landed=True)

    def _link_lost(self, executed: bool, obs: Observation | None = None) -> NoReturn:
        self.flying = self.awaiting_operator = False  # the watchdog lands it; nothing else is sent
        raise LinkLost(f"the link to the Tello is lost ({self._lost_reason()}): 'land' sent, nothing more is "
                       "executed", obs or self._observe(time.monotonic(), executed), landed=True, executed=executed)

    def _lost_reason(self) -> str:
        return (self.watchdog.reason if self.watchdog is not None else "") or "no sign of life"

    def _update_attitude(self) -> None:
        """Yaw from the state packet (relative to take-off, clockwise), height from the time-of-flight sensor."""
        state = self._connected.fresh_state() or self._connected.state()
        yaw = wrap_deg(self._home.yaw_deg - wrap_deg(int(state.get("yaw", self._yaw_ref)) - self._yaw_ref))
        z = int(state.get("tof", round(self._pose.z * 100))) / 100
        self._pose = Pose(self._pose.x, self._pose.y, z, yaw)

    def _observe(self, settled_at: float, executed: bool = True) -> Observation:
        link = self._connected
        image, timing = link.fresh_frame(settled_at)
        state = link.state()
        with self._event_lock:
            events, self._unreported = self._unreported, []
        info = {**timing, "battery_pct": state.get("bat"), "tof_cm": state.get("tof"),
                "keepalives": link.keepalives, "events": events}
        return Observation(front_rgb=image, rear_rgb=NO_REAR, pose=self._pose, collided=None, step=self._step,
                           info=info, executed=executed)

    # -- safety -----------------------------------------------------------------------------------------------
    def _check_limits(self) -> None:
        passed = self._limit_passed()
        if passed is not None:
            self._land_and_halt(passed[1], passed[0])

    def _limit_passed(self) -> tuple[str, str] | None:
        """(event kind, reason) of a limit the flight has passed, or None; read by the watchdog's thread too."""
        cfg, link = self.config, self.link
        if not self.flying or link is None:
            return None
        battery = link.state().get("bat")
        if battery is not None and int(battery) < cfg.land_battery_pct:
            return "battery_low", f"battery at {battery} %, below the landing floor of {cfg.land_battery_pct} %"
        flown = self.clock.now() - self._takeoff_t
        if flown > cfg.max_flight_s:
            return "flight_time", f"{flown:.0f} s of flight passed the limit of {cfg.max_flight_s:g} s"
        return None

    def _land_and_halt(self, reason: str, kind: str, obs: Observation | None = None, *,
                       executed: bool = False) -> None:
        self._event(kind, reason=reason, action="land")
        self.land()
        raise RobotHalt(reason, obs or self._observe(time.monotonic(), executed), landed=True, executed=executed)

    def land(self) -> None:
        """`land`, confirmed by its "ok" or a state packet on the ground; else the watchdog's landing sequence
        (`land` resent until the drone is down, then `emergency`), which `close()` lets finish."""
        if not (self.flying and self.link is not None) or self.link.lost.is_set():  # else the watchdog lands it
            return
        reply = None
        for _ in range(3):  # unlike a move, a repeated `land` is harmless: ask again when the "ok" is lost
            reply = self.link.send("land")  # the Tello answers once it is down (a few seconds)
            if reply is not None:
                break
        self.flying = self.awaiting_operator = False
        if reply == "ok" or on_ground(self.link.fresh_state() or {}):
            self._event("land", reply=reply)
            return
        self._event("land_unconfirmed", reply=reply, action="land resent until the drone is down, then emergency")
        if self.watchdog is not None:
            self.watchdog.declare_lost(f"'land' answered {reply!r} and the drone is not down", "land_unconfirmed")

    def _event(self, kind: str, **facts: Any) -> None:
        event = {"event": kind, "t": round(self.clock.now() - self._takeoff_t, 3) if self._takeoff_t else 0.0,
                 **facts}
        with self._event_lock:
            self.events.append(event)
            self._unreported.append(event)
            if self.event_log is not None:
                with open(self.event_log, "a", encoding="utf-8") as f:
                    f.write(json.dumps(event) + "\n")

    def _install_sigint(self) -> None:
        if self.handle_sigint and threading.current_thread() is threading.main_thread():
            self._old_sigint = signal.signal(signal.SIGINT, self._on_sigint)

    def _on_sigint(self, signum: int, frame: object) -> None:
        """First Ctrl-C: stop any rc pulse under way, `land`, and the watchdog resends it until the drone is down
        (then `emergency`); any further one: `emergency` (motors off). All bypass the command lock."""
        self.interrupts += 1
        command = "land" if self.interrupts == 1 else "emergency"
        if self.link is not None:
            if command == "land":
                self.link.emergency_send("rc 0 0 0 0")  # an rc pulse cut short holds its velocity otherwise
            self.link.emergency_send(command)
            if command == "land" and self.flying and self.watchdog is not None:
                self.watchdog.declare_lost("the operator pressed Ctrl-C", "operator_interrupt")
        self.flying = self.awaiting_operator = False
        self._event("operator_interrupt", action=command)
        raise KeyboardInterrupt

    # -- shutdown ---------------------------------------------------------------------------------------------
    def close(self) -> None:
        """Land (after the operator's word if a lost reply left the drone hovering), stop the video, let go.

        After a link loss nobody is asked anything: the watchdog's landing sequence is let finish."""
        if self.link is None or self.closed:
            return
        self.closed = True
        try:
            if self.flying and self.awaiting_operator and not self.link.lost.is_set():
                # a limit that passes meanwhile lands it (the watchdog) and ends the wait
                self.operator.wait("The Tello is hovering after a lost reply. Press Enter to land it.",
                                   until=self.link.lost)
            self.land()
            if self.streaming and not self.link.lost.is_set():
                self.link.send("streamoff", self.config.connect_timeout_s)
        finally:
            if self.watchdog is not None:
                self.watchdog.close()
            self.link.close()
            if self._old_sigint is not None:
                signal.signal(signal.SIGINT, self._old_sigint)
                self._old_sigint = None

    def __enter__(self) -> TelloEnv:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
