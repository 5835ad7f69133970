"""The UDP link to a Tello through djitellopy: one lock, single-shot commands, keep-alive, fresh state and frames.

djitellopy binds its reply socket (class constant CONTROL_UDP_PORT) and its state socket (STATE_UDP_PORT) once
per process, on all interfaces, and sends to `Tello.address`. We bind the reply socket to port 9000 (as DJI's
own SDK samples do; the Tello answers whichever port asked) and point `address` at the drone's port 8889, so
an emulator on 127.0.0.1:8889 and the controller share one machine without a port clash.

djitellopy's `send_control_command` resends a command whose "ok" was lost, which repeats a move. Here every
command is sent exactly once (`send`); whoever sends a motion decides what a missing reply means. Once the link
watchdog (`tello_watchdog`) sets `lost`, nothing is sent but its `land` / `emergency`, and every wait ends.
"""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np

from vlnpilot.core.errors import LinkFault, VLNPilotError
from vlnpilot.robots.clock import Clock
from vlnpilot.robots.tello_config import TelloConfig

CLOSED_HOST = "127.255.255.254"
MIN_GAP_S = 0.1  # the Tello drops commands sent closer together than this (djitellopy's TIME_BTW_COMMANDS)
RESYNC_TRIES = 3
GROUND_TOF_CM = 20  # the time-of-flight sensor reads 10 cm on the ground; a Tello flies at 30 cm or more


def on_ground(state: dict[str, Any]) -> bool:
    """Whether a state packet shows the drone on the ground: no height over take-off, the floor within reach."""
    try:
        return bool(state) and int(state.get("h", 1)) <= 0 and int(state.get("tof", GROUND_TOF_CM + 1)) <= GROUND_TOF_CM
    except (TypeError, ValueError):
        return False


class RobotError(VLNPilotError):
    """The robot cannot be reached or refuses to start; the message says what to check."""


class LinkError(RobotError, LinkFault):
    """No reply, no state packets or no video: the link is at fault, not the input (its own exit code)."""


def _tello_class() -> Any:
    import logging

    from djitellopy import Tello

    Tello.LOGGER.setLevel(logging.ERROR)  # its per-command INFO lines would drown the episode's own output
    return Tello


def _bind_ports(config: TelloConfig) -> None:
    """Set djitellopy's process-wide local ports before its first Tello binds them."""
    import djitellopy.tello as dt

    Tello = _tello_class()
    wanted = (config.local_port, config.state_port)
    if dt.threads_initialized:
        if (Tello.CONTROL_UDP_PORT, Tello.STATE_UDP_PORT) != wanted:
            raise RobotError(f"djitellopy already listens on UDP ports {Tello.CONTROL_UDP_PORT} and "
                             f"{Tello.STATE_UDP_PORT} in this process; it cannot move to {wanted[0]} and {wanted[1]}")
        return
    Tello.CONTROL_UDP_PORT, Tello.STATE_UDP_PORT = wanted


class StampedFrames:
    """djitellopy's own frame reader (PyAV), with the wall-clock time each frame was decoded and a count."""

    def __init__(self, tello: Any, address: str):
        from djitellopy.tello import BackgroundFrameRead

        outer = self

        class _Reader(BackgroundFrameRead):
            @property
            def frame(self) -> np.ndarray:
                with self.lock:
                    return self._frame

            @frame.setter
            def frame(self, value: np.ndarray) -> None:
                with self.lock:
                    self._frame = value
                    outer.stamp = time.monotonic()
                    outer.count += 1

        self.stamp, self.count = 0.0, 0
        self.reader = _Reader(tello, address)
        self.stamp, self.count = 0.0, 0  # the reader's black placeholder is no frame: real ones count from 1
        self.reader.start()

    def latest(self) -> tuple[np.ndarray, float, int]:
        with self.reader.lock:
            return self.reader._frame, self.stamp, self.count

    def stop(self) -> None:
        self.reader.stop()


class TelloLink:
    """One Tello over djitellopy. Every command goes through `send` (or `pulse`) under one lock."""

    def __init__(self, config: TelloConfig, clock: Clock):
        self.config, self.clock = config, clock
        _bind_ports(config)
        try:
            self.tello = _tello_class()(config.host, retry_count=1, vs_udp=config.video_port)
        except OSError as exc:
            raise RobotError(f"cannot listen for Tello replies on UDP port {config.local_port}: "
                             f"{exc.strerror or exc}") from None
        self.tello.address = (config.host, config.command_port)
        self.lock = threading.Lock()
        self.sent: list[str] = []  # every command sent, in order, once each
        self.keepalives = 0
        self.last_sent = clock.now()
        self._last_reply = 0.0
        self.replies = 0  # replies received, a sign of life for the watchdog
        self.lost = threading.Event()  # set by the watchdog: the link is dead
        self._state_seen: Any = None  # the state packet last counted (held, so a new one cannot reuse its id)
        self._state_packets = 0
        self._unsynced = False  # a reply did not come in time: it may yet come, and pass for the next one's
        self.frames: StampedFrames | None = None
        self._stop = threading.Event()
        self._keepalive: threading.Thread | None = None

    # -- commands ----------------------------------------------------------------------------------------------
    def send(self, command: str, timeout: float | None = None) -> str | None:
        """Send `command` once and return the reply, or None when none came within `timeout`. Never resent."""
        with self.lock:
            return self._send(command, self.config.reply_timeout_s if timeout is None else timeout)

    def _send(self, command: str, timeout: float) -> str | None:
        if self.lost.is_set() or (self._unsynced and not self._resync()):
            return None  # not sent: the link is lost, or lost track of which reply answers what
        responses = self._responses()
        responses.clear()  # a late reply to an earlier command must not pass for this one's
        time.sleep(max(0.0, MIN_GAP_S - (time.monotonic() - self._last_reply)))
        self._raw(command)
        deadline = time.monotonic() + timeout
        while not responses:
            if time.monotonic() > deadline or self.lost.is_set():  # a reply after the loss may be the land's
                self._unsynced = True  # its reply may still come, during the next command's wait
                return None
            time.sleep(0.005)
        self._last_reply = time.monotonic()
        self.replies += 1
        return responses.pop(0).decode("utf-8", "replace").strip()

    def _resync(self) -> bool:
        """After a reply that did not come in time: `battery?` until a number answers it, which no late "ok" or
        "error" can pass for; what came before it answered earlier commands and is dropped. False if none did."""
        responses = self._responses()
        for _ in range(RESYNC_TRIES):
            responses.clear()
            time.sleep(max(0.0, MIN_GAP_S - (time.monotonic() - self._last_reply)))
            self._raw("battery?")
            deadline = time.monotonic() + self.config.query_timeout_s
            while time.monotonic() < deadline and not self.lost.is_set():
                while responses:
                    if responses.pop(0).decode("utf-8", "replace").strip().isdigit():
                        self._last_reply, self._unsynced = time.monotonic(), False
                        self.replies += 1
                        return True
                time.sleep(0.005)
        return False

    def _responses(self) -> list[bytes]:
        return self.tello.get_own_udp_object()["responses"]

    def _raw(self, command: str) -> None:
        self.sent.append(command)
        self.last_sent = self.clock.now()
        self.tello.send_command_without_return(command)

    def pulse(self, left_right: int, forward: int, duration_s: float, settle_s: float) -> None:
        """A timed rc velocity pulse, then zero velocity (sent twice: repeating a stop is harmless) and a settle."""
        with self.lock:
            if self.lost.is_set():
                return
            self._raw(f"rc {left_right} {forward} 0 0")
            self.clock.sleep(duration_s)
            self._raw("rc 0 0 0 0")
            self._raw("rc 0 0 0 0")
        self.clock.sleep(settle_s)

    def emergency_send(self, command: str) -> None:
        """`land` or `emergency` from a signal handler or the watchdog: bypasses the lock, which a motion may hold."""
        self.sent.append(command)
        self.tello.send_command_without_return(command)

    def poll_reply(self) -> str | None:
        """A reply nobody is waiting for (the watchdog's `land`), or None."""
        responses = self._responses()
        return responses.pop(0).decode("utf-8", "replace").strip() if responses else None

    def evidence(self) -> tuple[int, int, int]:
        """Signs of life so far: state packets, decoded frames, replies (read by the watchdog's thread only)."""
        state = self.tello.get_current_state()
        if state is not self._state_seen and state:
            self._state_seen, self._state_packets = state, self._state_packets + 1
        return self._state_packets, self.frames.count if self.frames is not None else 0, self.replies

    def on_ground(self) -> bool:
        """Whether the newest state packet shows the drone on the ground (the watchdog's landing check)."""
        return on_ground(self.tello.get_current_state())

    # -- state -------------------------------------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        return dict(self.tello.get_current_state())

    def fresh_state(self, timeout: float = 1.5) -> dict[str, Any] | None:
        """The first state packet received after this call (djitellopy stores each packet as a new dict)."""
        old = self.tello.get_current_state()
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and not self.lost.is_set():
            now = self.tello.get_current_state()
            if now is not old and now:
                return dict(now)
            time.sleep(0.01)
        return None

    # -- video -------------------------------------------------------------------------------------------------
    def start_video(self) -> None:
        from djitellopy.tello import TelloException

        try:
            self.frames = StampedFrames(self.tello, self.tello.get_udp_video_address())
        except (TelloException, OSError) as exc:
            raise LinkError(f"no video from the Tello on UDP port {self.config.video_port} ({exc}); check that no "
                             "other program reads the stream and that the firewall lets UDP in") from None

    def first_frame(self, timeout: float) -> bool:
        """Whether a frame was decoded within `timeout` of now (before take-off: the pilot must not fly blind)."""
        assert self.frames is not None, "start_video() first"
        deadline = time.monotonic() + timeout
        while self.frames.count < 1:
            if time.monotonic() > deadline:
                return False
            time.sleep(0.01)
        return True

    def fresh_frame(self, settled_at: float) -> tuple[np.ndarray, dict[str, Any]]:
        """The newest frame decoded at least `video_latency_s` after `settled_at` (wall clock), and its timing.

        Frames decoded sooner show the drone before or during the motion (the stream lags 300-800 ms): they
        are dropped. If no fresh frame comes within `frame_timeout_s`, the newest one is returned, marked stale.
        """
        assert self.frames is not None, "start_video() first"
        wanted = settled_at + self.config.video_latency_s
        _, _, count_at_settle = self.frames.latest()
        started = time.monotonic()
        deadline = time.monotonic() + self.config.video_latency_s + self.config.frame_timeout_s
        while True:
            image, stamp, count = self.frames.latest()
            if stamp >= wanted and count >= 1:
                fresh = True
                break
            if time.monotonic() > deadline or self.lost.is_set():
                fresh = False
                break
            time.sleep(0.01)
        now = time.monotonic()
        # A decoder catching up on a backlog decodes faster than the stream's frame rate: recorded, to be seen.
        decoded_fps = (count - count_at_settle) / max(now - started, 1e-3)
        return image.copy(), {"frame_fresh": fresh, "frame_age_s": round(now - stamp, 3),
                              "frame_after_settle_s": round(stamp - settled_at, 3),
                              "frames_dropped": max(0, count - count_at_settle - 1),
                              "decoded_fps": round(decoded_fps, 1)}

    # -- keep-alive --------------------------------------------------------------------------------------------
    def start_keepalive(self) -> None:
        if self._keepalive is None:
            self._keepalive = threading.Thread(target=self._keep_alive, name="tello-keepalive", daemon=True)
            self._keepalive.start()

    def _keep_alive(self) -> None:
        """`battery?` whenever nothing was sent for `keepalive_s` (older firmware refuses `keepalive`)."""
        try:
            while not self.clock.wait_until(self.last_sent + self.config.keepalive_s, self._stop):
                if self.lost.is_set():  # after a loss only the watchdog speaks (land, emergency)
                    break
                if self.clock.now() < self.last_sent + self.config.keepalive_s:
                    continue
                if not self.lock.acquire(blocking=False):  # a motion is under way: it is traffic itself
                    if self.clock.wait_until(self.clock.now() + 0.1, self._stop):
                        break
                    continue
                try:
                    self.keepalives += 1
                    self._send("battery?", self.config.query_timeout_s)
                finally:
                    self.lock.release()
        finally:
            self.clock.done()

    def close(self) -> None:
        self._stop.set()
        self.clock.wake()
        if self._keepalive is not None:
            self._keepalive.join(timeout=10)
        if self.frames is not None:
            self.frames.stop()
        import djitellopy.tello as dt

        dt.drones.pop(self.config.host, None)
        # djitellopy keys its reply queues by host and its __del__ lands, stops the stream and deletes the queue
        # of `address[0]`: point this closed object at an unused loopback address (no name, so no DNS look-up),
        # so that it cannot touch a newer link to the same host.
        self.tello.is_flying = self.tello.stream_on = False
        self.tello.address = (CLOSED_HOST, self.config.command_port)
