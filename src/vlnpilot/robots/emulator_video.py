"""The emulator's video: the simulator's front camera as a raw H.264 stream over UDP, like the Tello's.

The Tello sends an Annex-B H.264 elementary stream (SPS/PPS before every key frame) in UDP datagrams of at
most 1460 bytes to port 11111; djitellopy's frame reader opens it with PyAV (`udp://@0.0.0.0:11111`). We
encode with PyAV's libx264 (ultrafast, zerolatency, a key frame every second so that a late reader can start),
so the reader decodes exactly the format it decodes from a real drone. Frames are rendered only when the
drone has moved; otherwise the last frame is encoded again. All rendering happens on the streamer's one thread
(an EGL context is current in one thread at a time), which lives as long as the emulator: `streamon` and
`streamoff` only switch sending on and off.
"""

from __future__ import annotations

import socket
import threading
import time
from collections import deque
from collections.abc import Callable
from fractions import Fraction

import av
import numpy as np

DATAGRAM = 1460  # the Tello's video datagram size
# H.264 as the Tello sends it; if this PyAV build has no H.264 encoder, raw MPEG-4 Part 2, the closest stream
# that the same reader (`av.open` on the UDP address, format probed) also decodes.
CODECS = ("libx264", "libopenh264", "mpeg4")


def pick_codec() -> str:
    """The first encoder of CODECS that this PyAV build offers."""
    for name in CODECS:
        try:
            av.codec.Codec(name, "w")
        except (av.codec.codec.UnknownCodecError, ValueError):
            continue
        return name
    raise RuntimeError(f"PyAV offers none of the video encoders {', '.join(CODECS)}")


class VideoStreamer:
    """Encodes frames from `grab()` at `fps` and, while on, sends them to `target` after `delay_s` (wall clock).

    `grab` runs on the streamer's thread only; `release` (if given) runs there once when the streamer closes.
    """

    def __init__(self, sock: socket.socket, target: tuple[str, int], grab: Callable[[], np.ndarray], *,
                 fps: float = 15.0, delay_s: float = 0.0, release: Callable[[], None] | None = None):
        self.sock, self.target, self.grab, self.release = sock, target, grab, release
        self.fps, self.delay_s = fps, delay_s
        self.frames_sent = 0
        self.on = threading.Event()
        self._stop = threading.Event()
        self._codec: av.VideoCodecContext | None = None
        self._pending: deque[tuple[float, bytes]] = deque()  # (due time, encoded access unit)
        self.codec = pick_codec()
        self._thread = threading.Thread(target=self._run, name="tello-emulator-video", daemon=True)
        self._thread.start()

    def start(self) -> None:
        self.on.set()

    def stop(self) -> None:
        self.on.clear()

    @property
    def running(self) -> bool:
        return self.on.is_set()

    def close(self) -> None:
        self.on.clear()
        self._stop.set()
        self._thread.join(timeout=10)

    def _encoder(self, height: int, width: int) -> av.VideoCodecContext:
        ctx = av.CodecContext.create(self.codec, "w")
        assert isinstance(ctx, av.VideoCodecContext)  # every codec of CODECS is a video encoder
        ctx.width, ctx.height = width, height
        ctx.pix_fmt = "yuv420p"
        ctx.time_base = Fraction(1, int(self.fps))
        ctx.framerate = Fraction(int(self.fps), 1)
        ctx.gop_size = max(1, int(self.fps))
        if self.codec == "libx264":
            ctx.options = {"preset": "ultrafast", "tune": "zerolatency"}
        return ctx

    def _run(self) -> None:
        try:
            self._stream()
        finally:
            if self.release is not None:
                self.release()

    def _stream(self) -> None:
        period = 1.0 / self.fps
        next_t = time.monotonic()
        index = 0
        while not self._stop.is_set():
            if not self.on.is_set():
                self._codec = None  # a new stream starts with a key frame
                self._pending.clear()
                self.on.wait(0.1)
                next_t = time.monotonic()
                continue
            image = self.grab()
            if self._codec is None:
                self._codec = self._encoder(*image.shape[:2])
            frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(image), format="rgb24")
            frame.pts = index
            index += 1
            data = b"".join(bytes(p) for p in self._codec.encode(frame))
            if data:
                self._pending.append((time.monotonic() + self.delay_s, data))
            self._flush()
            next_t += period
            self._stop.wait(max(0.0, next_t - time.monotonic()))

    def _flush(self) -> None:
        now = time.monotonic()
        while self._pending and self._pending[0][0] <= now:
            _, data = self._pending.popleft()
            for i in range(0, len(data), DATAGRAM):
                try:
                    self.sock.sendto(data[i:i + DATAGRAM], self.target)
                except OSError:
                    return  # the reader is gone; the Tello keeps streaming regardless
            self.frames_sent += 1
