"""A Tello SDK 2.0 peer on loopback that flies our simulated drone (`vln-pilot tello-emulator`).

It answers commands on UDP 8889 (replying to the sender's address, as the Tello does), sends state packets to
the sender's port 8890 at 10 Hz and streams the front camera as H.264 to port 11111 (`emulator_video`). Every
accepted motion moves the simulator's drone with its collision sweep. It keeps the Tello's rules: moves of
20-500 cm only (`forward 10` gets "out of range"), rotations of 1-360°, auto-landing after 15 s without a
command, a draining battery, and no reply to `rc`. For tests it can drop a fraction of its replies (seeded),
the replies to some commands, or the commands themselves, delay the video, and counts every motion it executed.
"""

from __future__ import annotations

import ipaddress
import random
import socket
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from vlnpilot.core.errors import ConfigError
from vlnpilot.core.ranging import TT_TOF_BEYOND_MM
from vlnpilot.core.records import Motion, Pose, wrap_deg
from vlnpilot.robots.clock import Clock, WallClock
from vlnpilot.robots.emulator_video import VideoStreamer
from vlnpilot.scene.detail import check_detail

MOVES = {"forward": (1, 0, 0), "back": (-1, 0, 0), "left": (0, 1, 0), "right": (0, -1, 0),
         "up": (0, 0, 1), "down": (0, 0, -1)}
QUERIES = {"battery?", "speed?", "time?", "height?", "temp?", "attitude?", "baro?", "tof?", "wifi?", "sdk?",
           "sn?", "acceleration?"}
OUT_OF_RANGE = "out of range"  # the SDK's reply to a distance or angle outside its limits
NOT_FLYING = "error Motor stop"


@dataclass
class EmulatorConfig:
    host: str = "127.0.0.1"
    port: int = 8889  # commands
    state_port: int = 8890  # where state packets go (on the sender's address)
    video_port: int = 11111  # where the video goes
    battery_pct: float = 100.0
    battery_drain_pct_per_s: float = 0.12  # about 13 minutes of flight, like the Tello
    auto_land_s: float = 15.0
    takeoff_height_m: float = 0.8
    rc_full_scale_mps: float = 1.0  # speed at rc 100
    rc_full_scale_dps: float = 90.0  # yaw rate at rc 100
    drop_replies: float = 0.0  # fraction of command replies never sent
    drop_verbs: tuple[str, ...] = ()  # commands whose replies are always dropped, e.g. ("forward",)
    drop_first: tuple[str, ...] = ()  # commands whose first reply only is dropped, e.g. ("streamon",)
    lose_verbs: tuple[str, ...] = ()  # commands lost on the way to the drone: neither executed nor answered
    video_delay_s: float = 0.0
    fps: float = 15.0
    seed: int = 0
    keepalive_known: bool = False  # firmware before SDK 3.0 answers "unknown command: keepalive"
    ext_tof: bool = False  # emulate a RoboMaster TT: `EXT tof?` answers the simulator's forward range, in mm
    # What the video shows (docs/camera.md): ideal renders, or the Tello's camera (`tello-emulator` defaults to it;
    # its lag is `video_delay_s`, in real time); `randomize`: the seed of a randomised world
    camera: str = "ideal"
    randomize: int | None = None
    detail: str = "plain"  # the scene detail its camera renders (scene/detail.py): plain | rich

    def __post_init__(self) -> None:
        from vlnpilot.core.cameras import check_camera

        object.__setattr__(self, "camera", check_camera(self.camera))
        try:
            loopback = ipaddress.ip_address(self.host).is_loopback
        except ValueError:
            loopback = False
        if not loopback:
            raise ConfigError(f"the Tello emulator listens on loopback only; got host {self.host!r} "
                              "(use 127.0.0.1 or another 127.x.y.z address)")
        check_detail(self.detail)
        if not 0.0 <= self.drop_replies < 1.0:
            raise ConfigError(f"drop_replies must be within 0..1, got {self.drop_replies}")


@dataclass
class EmulatorFaults:
    """Faults a test switches on while the emulator runs (the settings above hold from the start): one channel
    silent while the others live, commands refused or lost on the way, replies that come late."""

    state_silent: bool = False  # no state packets (commands and video go on)
    refuse: set[str] = field(default_factory=set)  # verbs answered "error" and not carried out, e.g. {"land"}
    lose: set[str] = field(default_factory=set)  # verbs lost on the way to the drone: neither executed nor answered
    late: dict[str, float] = field(default_factory=dict)  # verb -> seconds its reply comes after it was carried out


@dataclass
class EmulatorLog:
    """What the emulator saw and did, for tests and the operator."""

    received: list[tuple[float, str]] = field(default_factory=list)  # (clock time, command)
    executed: list[str] = field(default_factory=list)  # every motion it carried out, e.g. "forward 50"
    dropped: list[str] = field(default_factory=list)  # commands whose reply it dropped
    lost: list[str] = field(default_factory=list)  # commands it never received (lose_verbs)
    events: list[str] = field(default_factory=list)  # takeoff, land, auto_land, emergency

    def gaps(self, since: float | None = None) -> list[float]:
        """Seconds between consecutive commands received (after `since`)."""
        times = [t for t, _ in self.received if since is None or t >= since]
        return [b - a for a, b in zip(times, times[1:], strict=False)]


class TelloEmulator:
    """Serve the Tello SDK for a simulated drone in `scene` until `close()`; use as a context manager.

    Two simulators share the scene: a render-free one for the motions (command thread) and one that only
    renders the video (video thread), because an EGL context is current in one thread at a time.
    """

    def __init__(self, scene: str = "cabin", config: EmulatorConfig | None = None, *, spawn: str | None = None,
                 clock: Clock | None = None, width: int = 640, height: int = 480):
        from vlnpilot.sim import SimConfig, Simulator

        self.config, self.clock = config or EmulatorConfig(), clock or WallClock()
        self.sim = sim = Simulator(scene, SimConfig(render=False, sensors="tof" if self.config.ext_tof else "none"))
        self._camera = (scene, SimConfig(width=width, height=height, rear_camera=False, camera=self.config.camera,
                                         camera_lag_ms=0.0 if self.config.camera == "tello" else None,
                                         randomize=self.config.randomize, detail=self.config.detail))
        self._viewer: Simulator | None = None  # created on the video thread
        spawn_obj = sim.scene.spawn(spawn) if spawn else sim.scene.spawns[0]
        self.home = spawn_obj.pose
        self.log = EmulatorLog()
        self.faults = EmulatorFaults()
        self._replies_due = 0.0  # when the last late reply goes out (monotonic): later ones wait behind it
        self.landed = threading.Event()  # set by land, emergency and the auto-land
        self.auto_landed = threading.Event()
        self._rng = random.Random(self.config.seed)
        self._dropped_once: set[str] = set()
        self._sim_lock = threading.RLock()
        self._state_lock = threading.Lock()
        self._stop = threading.Event()
        self.flying = self.sdk_mode = False
        self.battery = self.config.battery_pct
        self._yaw0 = self.home.yaw_deg
        self._rc = (0.0, 0.0, 0.0, 0.0)  # lateral (right +), forward, vertical, yaw (cw +), as -1..1
        self._last_update = self._last_command = self.clock.now()
        self._takeoff_t: float | None = None
        self._client: str | None = None
        self._frame: np.ndarray | None = None
        self._frame_pose: Pose | None = None
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.bind((self.config.host, self.config.port))
        except OSError as exc:
            self.sock.close()
            raise ConfigError(f"the Tello emulator cannot listen on {self.config.host}:{self.config.port}: "
                              f"{exc.strerror or exc} (is another emulator running?)") from None
        self.sock.settimeout(0.2)
        self.address = self.sock.getsockname()
        with self._sim_lock:
            sim.reset(self.home)
        self.video = VideoStreamer(self.sock, (self.config.host, self.config.video_port), self._grab,
                                   fps=self.config.fps, delay_s=self.config.video_delay_s, release=self._release)
        self._threads = [threading.Thread(target=self._serve, name="tello-emulator-cmd", daemon=True),
                         threading.Thread(target=self._tick, name="tello-emulator-state", daemon=True)]
        for t in self._threads:
            t.start()

    # -- life cycle -----------------------------------------------------------------------------------------
    def close(self) -> None:
        self._stop.set()
        self.video.close()
        for t in self._threads:
            t.join(timeout=5)
        self.sock.close()
        self.sim.close()

    def __enter__(self) -> TelloEmulator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def pose(self) -> Pose:
        with self._sim_lock:
            return self.sim.pose

    # -- commands ---------------------------------------------------------------------------------------------
    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                data, sender = self.sock.recvfrom(2048)
            except TimeoutError:
                continue
            except OSError:
                return
            text = data.decode("utf-8", "replace").strip()
            self._client = sender[0]
            verb = text.split()[0].lower() if text else ""
            if verb in self.config.lose_verbs or verb in self.faults.lose:
                self.log.lost.append(text)
                continue
            reply = self._refuse(text) if verb in self.faults.refuse else self.handle(text)
            if reply is None:
                continue
            if self._drops(verb):
                self.log.dropped.append(text)
                continue
            self._reply(reply, sender, self.faults.late.get(verb, 0.0))

    def _refuse(self, text: str) -> str:
        """A command received and answered "error", not carried out (`faults.refuse`)."""
        self.log.received.append((self.clock.now(), text))
        return "error"

    def _reply(self, reply: str, sender: tuple[str, int], late_s: float) -> None:
        """Send `reply`, `late_s` late; the replies after a late one wait behind it, in order, as a drone that
        answers one command at a time does (and UDP on one hop keeps)."""
        now = time.monotonic()
        due = max(now + late_s, self._replies_due)
        self._replies_due = due + 1e-3 if due > now else 0.0
        if due <= now:
            self._send_reply(reply, sender)
        else:
            threading.Timer(due - now, self._send_reply, (reply, sender)).start()

    def _send_reply(self, reply: str, sender: tuple[str, int]) -> None:
        try:
            self.sock.sendto(reply.encode(), sender)
        except OSError:
            pass

    def _drops(self, verb: str) -> bool:
        c = self.config
        if verb in c.drop_first and verb not in self._dropped_once:
            self._dropped_once.add(verb)
            return True
        return verb in c.drop_verbs or bool(c.drop_replies and self._rng.random() < c.drop_replies)

    def handle(self, text: str) -> str | None:
        """Execute one SDK command and return the reply (None for `rc`, which the Tello never answers)."""
        with self._state_lock:  # the state thread integrates rc motion and drains the battery meanwhile
            return self._handle(text)

    def _handle(self, text: str) -> str | None:
        now = self.clock.now()
        self.log.received.append((now, text))
        self._integrate(now)
        self._last_command = now
        words = text.split()
        if not words:
            return "error"
        verb, args = words[0].lower(), words[1:]
        if verb == "command":
            self.sdk_mode = True
            return "ok"
        if not self.sdk_mode:
            return None  # outside SDK mode the Tello ignores text commands
        if verb == "rc":
            self._set_rc(args)
            return None  # rc has no reply
        if verb in QUERIES:
            return self._query(verb)
        if text.strip().lower() == "ext tof?" and self.config.ext_tof:
            return self._ext_tof()
        if verb == "keepalive" and self.config.keepalive_known:
            return "ok"
        if verb in ("streamon", "streamoff"):
            (self.video.start if verb == "streamon" else self.video.stop)()
            return "ok"
        if verb == "takeoff":
            return self._takeoff()
        if verb in ("land", "emergency"):
            self._land(verb)
            return "ok"
        if verb == "speed":
            return "ok"
        if verb in MOVES or verb in ("cw", "ccw"):
            return self._motion(verb, args)
        return f"unknown command: {text}"

    def _motion(self, verb: str, args: list[str]) -> str:
        if not self.flying:
            return NOT_FLYING
        try:
            amount = int(args[0])
        except (IndexError, ValueError):
            return "error"
        if verb in ("cw", "ccw"):
            if not 1 <= amount <= 360:
                return OUT_OF_RANGE
            self._move(Motion(yaw_deg=-amount if verb == "cw" else amount))
        else:
            if not 20 <= amount <= 500:
                return OUT_OF_RANGE
            f, l, v = MOVES[verb]
            self._move(Motion(forward_m=f * amount / 100, lateral_m=l * amount / 100, vertical_m=v * amount / 100))
        self.log.executed.append(f"{verb} {amount}")
        return "ok"

    def _move(self, motion: Motion) -> None:
        with self._sim_lock:
            self.sim.move(motion)

    def _takeoff(self) -> str:
        if self.battery < 10:
            return "error No valid imu"  # what a Tello with a flat battery tends to say
        with self._sim_lock:
            h = self.home
            self.sim.reset(Pose(h.x, h.y, self.config.takeoff_height_m, h.yaw_deg))
        self.flying, self._takeoff_t = True, self.clock.now()
        self.landed.clear()
        self.log.events.append("takeoff")
        return "ok"

    def _land(self, why: str) -> None:
        self.flying, self._rc = False, (0.0, 0.0, 0.0, 0.0)
        self.landed.set()
        self.log.events.append(why)

    def _set_rc(self, args: list[str]) -> None:
        try:
            values = [max(-100, min(100, int(a))) / 100 for a in args[:4]]
        except ValueError:
            return None
        if len(values) == 4:
            self._rc = tuple(values)  # type: ignore[assignment]
        return None

    def _query(self, verb: str) -> str:
        s = self.state()
        return {"battery?": str(s["bat"]), "speed?": "10.0", "time?": f"{s['time']}s", "height?": f"{s['h'] // 10}dm",
                "temp?": "60~62C", "attitude?": f"pitch:0;roll:0;yaw:{s['yaw']};", "baro?": f"{s['baro']:.2f}",
                "tof?": f"{s['tof'] * 10}mm", "wifi?": "90", "sdk?": "20", "sn?": "0TQZEMULATOR01",
                "acceleration?": "agx:0.00;agy:0.00;agz:-1000.00;"}[verb]

    def _ext_tof(self) -> str:
        """The TT's forward ToF from the simulator: 'tof MM', 8192 when nothing is within its range."""
        with self._sim_lock:
            (reading,) = self.sim.ranges()
        return f"tof {TT_TOF_BEYOND_MM if reading.metres is None else round(reading.metres * 1000)}"

    # -- time: rc motion, battery, auto-land, state packets -------------------------------------------------
    def _integrate(self, now: float) -> None:
        """Carry out the rc velocities held since the last update (event based, so exact on a manual clock)."""
        dt, self._last_update = now - self._last_update, now
        if dt <= 0:
            return
        if self.flying:
            self.battery = max(0.0, self.battery - self.config.battery_drain_pct_per_s * dt)
            lr, fb, ud, yaw = self._rc
            if any(self._rc):
                c = self.config
                self._move(Motion(forward_m=fb * c.rc_full_scale_mps * dt, lateral_m=-lr * c.rc_full_scale_mps * dt,
                                  vertical_m=ud * c.rc_full_scale_mps * dt, yaw_deg=-yaw * c.rc_full_scale_dps * dt))
        if self.flying and now - self._last_command > self.config.auto_land_s:
            self._land("auto_land")
            self.auto_landed.set()

    def _tick(self) -> None:
        while not self._stop.wait(0.1):
            with self._state_lock:
                self._integrate(self.clock.now())
            if self._client is not None and not self.faults.state_silent:
                packet = ";".join(f"{k}:{v}" for k, v in self.state().items()) + ";\r\n"
                try:
                    self.sock.sendto(packet.encode(), (self._client, self.config.state_port))
                except OSError:
                    pass
            if self.video.running:
                self.video.target = (self._client or self.config.host, self.config.video_port)

    def state(self) -> dict[str, Any]:
        """The fields of a Tello SDK 2.0 state packet (yaw relative to take-off heading, + clockwise)."""
        pose = self.pose
        height_cm = int(round(pose.z * 100)) if self.flying else 0
        flight = int(self.clock.now() - self._takeoff_t) if self._takeoff_t is not None else 0
        return {"mid": -1, "x": 0, "y": 0, "z": 0, "mpry": "0,0,0", "pitch": 0, "roll": 0,
                "yaw": int(round(wrap_deg(self._yaw0 - pose.yaw_deg))), "vgx": 0, "vgy": 0, "vgz": 0,
                "templ": 60, "temph": 62, "tof": max(10, height_cm), "h": height_cm, "bat": int(self.battery),
                "baro": round(height_cm / 100, 2), "time": flight, "agx": 0.0, "agy": 0.0, "agz": -1000.0}

    def _grab(self) -> np.ndarray:
        """The front camera at the drone's pose (video thread only); rendered again only after a move."""
        from vlnpilot.sim import Simulator

        pose = self.pose
        if self._frame is None or pose != self._frame_pose:
            if self._viewer is None:
                self._viewer = Simulator(*self._camera)
                self._frame = self._viewer.reset(pose, seed=self.config.seed).front_rgb
            else:  # the camera follows: its exposure adapts, a move since the last frame streaks it
                self._frame = self._viewer.place(pose).front_rgb
            self._frame_pose = pose
        return self._frame

    def _release(self) -> None:
        if self._viewer is not None:
            self._viewer.close()
