"""What the front camera delivers: `ideal` (the render itself) or `tello` (what a Tello's video stream sends).

The `tello` model turns a pinhole render into a 960x720 frame with the Tello's 82.6° diagonal field of view,
barrel distortion, motion blur along the last move, auto-exposure that adapts over a step, sensor noise and
JPEG compression at the stream's bitrate. Frame lag is the simulator's part (it renders at the pose the frame
shows, `lagged_fraction`: the settled one unless the lag outlasts the controller's wait). Every parameter, with its
source, is in docs/camera.md.

Cost matters (bench/camera_cost.py: at most 1.3x the ideal step), and every pass over the image costs about the
same, so there are few: the lens is one precomputed table of source pixels read with one numpy gather of 4-byte
pixels (straight from the GL read-back, `GLPixels`, whose row order the table absorbs), which Pillow then shares
without a copy; the streak is Pillow's box blur along the move, the exposure a lookup table, the noise (one of a few
crops of a seeded tile) Pillow's `ImageChops.add_modulo`, the compression Pillow's JPEG encoder and decoder, the
stream's size a nearest-neighbour resize, packed to RGB in one pass. Deterministic: the same renders, seeds and
moves give the same frames, from an RGB render or from the GL read-back alike.
"""

from __future__ import annotations

import functools
import io
import math
from dataclasses import dataclass

import numpy as np
from PIL import Image, ImageChops, ImageFilter

from vlnpilot.core.cameras import DEFAULT_CAMERA, check_camera
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.records import Motion
from vlnpilot.core.tello_spec import ASPECT, DIAGONAL_FOV_DEG


@dataclass(frozen=True)
class TelloCameraParams:
    """The Tello's stream as modelled; sources in docs/camera.md."""

    width: int = 960  # the stream's frame (Tello SDK 2.0 user guide: 720p stream at 960x720)
    height: int = 720
    diagonal_fov_deg: float = DIAGONAL_FOV_DEG  # spec sheet; kept corner to corner under the distortion
    k1: float = -0.05  # Brown radial coefficients (barrel: k1 < 0), on the pinhole's normalised image plane
    k2: float = 0.0
    jpeg_quality: int = 40  # about 20 kB a frame at 960x720: the SDK's 2-5 Mbit/s stream at 30 fps, I-frame sized
    noise_sigma: float = 2.5  # sensor noise, grey levels (of 255), before compression
    exposure_s: float = 1 / 30  # the shutter at indoor light: one frame time at 30 fps
    speed_mps: float = 0.5  # how fast a move flies (SDK `speed`), for the lag and the blur
    yaw_rate_dps: float = 60.0  # how fast a rotation turns
    scene_depth_m: float = 2.0  # a typical distance to what is seen, for the blur of a sideways or vertical move
    lag_ms: float = 300.0  # the stream shows the world this long ago (djitellopy #77: 300-800)
    # The real backend takes a step's frame only after the move replied, hovered `move_settle_s` (0.3 s) and its
    # stream delivered a frame decoded `video_latency_s` (0.8 s) later (robots/tello.yaml): a lag shorter than that
    # wait shows the settled pose, as the prompt promises; only a longer lag shows a stale, streaked frame.
    frame_wait_s: float = 1.1
    ae_rate: float = 0.5  # the share of an exposure error the auto-exposure corrects per step
    ae_target: float = 100.0  # the mean grey level it aims at: the median of the renders' means (docs/camera.md)
    ae_range: tuple[float, float] = (0.6, 1.6)  # the gains it can reach

    def __post_init__(self) -> None:
        if not 0 <= self.lag_ms <= 2000:
            raise ConfigError(f"camera lag must be within 0..2000 ms, got {self.lag_ms}")
        if not 1 <= self.jpeg_quality <= 95:
            raise ConfigError(f"camera jpeg quality must be within 1..95, got {self.jpeg_quality}")


@dataclass(frozen=True)
class FrameMotion:
    """What the camera moved through while the frame was exposed: pixels of streak along x and y, and the
    relative zoom of a forward (+) or backward (-) move."""

    blur_x_px: float = 0.0
    blur_y_px: float = 0.0
    zoom: float = 0.0

    @property
    def still(self) -> bool:
        return self.blur_x_px < 1 and self.blur_y_px < 1 and abs(self.zoom) < 1e-3


STILL = FrameMotion()


def move_duration_s(motion: Motion, params: TelloCameraParams) -> float:
    """How long a Tello takes to fly `motion` (translation and rotation in turn, as the SDK flies them)."""
    trans = math.hypot(motion.forward_m, motion.lateral_m) + abs(motion.vertical_m)
    return trans / params.speed_mps + abs(motion.yaw_deg) / params.yaw_rate_dps


def lagged_fraction(motion: Motion, flown: float, params: TelloCameraParams) -> float | None:
    """The fraction of `motion` the world had reached when the frame shown was exposed: `lag_ms` before the
    controller took it, `frame_wait_s` after the move ended after `flown` of it. `flown`: the move had ended (the
    settled pose, no streak); None: the frame is from before the move began (the drone hovered: no streak)."""
    duration = move_duration_s(motion, params) * flown
    if duration <= 0:
        return None
    at = duration + params.frame_wait_s - params.lag_ms / 1000
    if at >= duration:
        return flown
    return None if at <= 0 else flown * at / duration


def frame_motion(motion: Motion, params: TelloCameraParams, focal_px: float) -> FrameMotion:
    """The streak that the drone's velocity on `motion` draws during one exposure (flown at the Tello's speeds)."""
    duration = move_duration_s(motion, params)
    if duration <= 0:
        return STILL
    t = params.exposure_s
    vf, vl, vz = (motion.forward_m / duration, motion.lateral_m / duration, motion.vertical_m / duration)
    yaw_rate = math.radians(motion.yaw_deg / duration)
    return FrameMotion(blur_x_px=abs(yaw_rate * t + vl * t / params.scene_depth_m) * focal_px,
                       blur_y_px=abs(vz * t / params.scene_depth_m) * focal_px,
                       zoom=vf * t / params.scene_depth_m)


def _undistort(xd: np.ndarray, yd: np.ndarray, k1: float, k2: float) -> tuple[np.ndarray, np.ndarray]:
    """Invert the Brown radial model x_d = x_u (1 + k1 r_u^2 + k2 r_u^4) by fixed-point iteration."""
    xu, yu = xd.copy(), yd.copy()
    for _ in range(20):
        r2 = xu * xu + yu * yu
        f = 1 + k1 * r2 + k2 * r2 * r2
        xu, yu = xd / f, yd / f
    return xu, yu


@dataclass(frozen=True)
class GLPixels:
    """A render as OpenGL reads it back: HxWx4 uint8 RGBA, bottom row first (`sim/gl_readback.py`). The Tello model
    reads it as is: its lens table flips the rows, and its 4-byte pixels gather and enter Pillow without a copy."""

    rgba: np.ndarray

    @property
    def top_down_rgb(self) -> np.ndarray:
        return np.ascontiguousarray(self.rgba[::-1, :, :3])


def distortion_table(params: TelloCameraParams, src_w: int, src_h: int, bottom_up: bool = False) -> np.ndarray:
    """For each pixel of a `src_w` x `src_h` frame (row-major) with the Tello's lens, the index of the pinhole
    render's pixel it shows (nearest; the JPEG that follows smooths the steps); `bottom_up`: of a render stored
    bottom row first (`GLPixels`). The focal lengths keep the diagonal field of view: the corner ray lands in the
    corner of both."""
    f_out = central_focal_px(params) * src_w / params.width
    half_diag_u = math.tan(math.radians(params.diagonal_fov_deg) / 2)  # normalised pinhole radius of a corner
    f_src = math.hypot(src_w, src_h) / 2 / half_diag_u
    gx, gy = np.meshgrid(np.arange(src_w) + 0.5, np.arange(src_h) + 0.5)
    xu, yu = _undistort((gx - src_w / 2) / f_out, (gy - src_h / 2) / f_out, params.k1, params.k2)
    sx = np.clip(np.floor(xu * f_src + src_w / 2), 0, src_w - 1).astype(np.int32)
    sy = np.clip(np.floor(yu * f_src + src_h / 2), 0, src_h - 1).astype(np.int32)
    if bottom_up:
        sy = src_h - 1 - sy
    return (sy * src_w + sx).reshape(-1).astype(np.intp)  # numpy's own index type: the fastest gather


@functools.lru_cache(maxsize=8)
def _default_table(w: int, h: int) -> np.ndarray:
    return distortion_table(TelloCameraParams(), w, h)


def through_lens(image: np.ndarray, camera: str = "tello") -> np.ndarray:
    """`image` (HxW or HxWxC, any dtype: a segmentation too) as `camera`'s lens shows it, at the same size: the
    geometry of a Tello frame without its exposure, noise or compression (what apparent widths are measured on)."""
    if check_camera(camera) == "ideal":
        return image
    h, w = image.shape[:2]
    flat = image.reshape(h * w, *image.shape[2:])
    return flat[_default_table(w, h)].reshape(image.shape)


def central_focal_px(params: TelloCameraParams) -> float:
    """The output's focal length at the image centre, in pixels (for the blur)."""
    half_diag_u = math.tan(math.radians(params.diagonal_fov_deg) / 2)
    corner_d = half_diag_u * (1 + params.k1 * half_diag_u ** 2 + params.k2 * half_diag_u ** 4)
    return math.hypot(params.width, params.height) / 2 / corner_d


class TelloCamera:
    """The `tello` camera model; `reset` at each episode (its exposure state and noise offsets), then `frame`."""

    name = "tello"
    NOISE_TILE = 256  # the noise is a crop of this seeded square, tiled to the render's size
    NOISE_FRAMES = 16  # crops kept (each frame draws one)
    NOISE_MAX = 8  # the noise is clipped to +-8 grey levels (3.2 sigma); the exposure keeps pixels 8 from the ends,
    # the sensor's black level and its white clip, so that the noise is added modulo 256 without wrapping (in C,
    # `ImageChops.add_modulo`, 7x faster than a clipped add)

    def __init__(self, params: TelloCameraParams | None = None):
        self.params = params or TelloCameraParams()
        if abs(ASPECT - self.params.width / self.params.height) > 1e-6:
            raise ConfigError("the Tello camera's frame must be 4:3")
        self._table: dict[tuple[int, int, bool], np.ndarray] = {}
        self._noise: dict[tuple[int, int], list[Image.Image]] = {}
        self._rng = np.random.default_rng(0)
        self._gain: float | None = None
        self.jpeg_bytes = 0
        self.bias = 1.0  # the exposure bias of a randomised world (sim/randomize.py)

    @property
    def focal_px(self) -> float:
        return central_focal_px(self.params)

    def reset(self, seed: int | None, bias: float = 1.0, world: int | None = None) -> None:
        """A new episode: noise offsets from `seed` (and the randomised `world`), auto-exposure settles on the
        first frame."""
        self._rng = np.random.default_rng([0 if seed is None else seed, 0 if world is None else world + 1, 25])
        self._gain, self.bias = None, bias

    def _noise_image(self, w: int, h: int) -> Image.Image:
        """The noise (modulo 256, RGBX) at the render's size: one of `NOISE_FRAMES` crops of a seeded tile, drawn
        per frame."""
        if (w, h) not in self._noise:
            tile = np.random.default_rng(25).normal(0.0, self.params.noise_sigma, (self.NOISE_TILE, self.NOISE_TILE, 3))
            tile = (np.clip(np.rint(tile), -self.NOISE_MAX, self.NOISE_MAX).astype(np.int16) % 256).astype(np.uint8)
            reps = (math.ceil(h / self.NOISE_TILE) + 1, math.ceil(w / self.NOISE_TILE) + 1, 1)
            big = np.tile(tile, reps)
            offsets = np.random.default_rng(26).integers(0, self.NOISE_TILE, (self.NOISE_FRAMES, 2))
            self._noise[(w, h)] = [Image.fromarray(np.ascontiguousarray(big[y:y + h, x:x + w])).convert("RGBX")
                                   for x, y in offsets]
        return self._noise[(w, h)][int(self._rng.integers(self.NOISE_FRAMES))]

    def _lens_table(self, w: int, h: int, bottom_up: bool) -> np.ndarray:
        key = (w, h, bottom_up)
        if key not in self._table:
            self._table[key] = distortion_table(self.params, w, h, bottom_up)
        return self._table[key]

    def _exposure(self, render: np.ndarray, bottom_up: bool = False) -> float:
        """This frame's gain: auto-exposure moves `ae_rate` of the way from the last gain to what this view wants,
        metered on every 8th pixel of every 8th row from the top (from the bottom row first: the same rows; integers
        summed in float64 are exact in any order)."""
        p = self.params
        rows = render[(render.shape[0] - 1) % 8::8] if bottom_up else render[::8]
        mean = float(rows[:, ::8, :3].mean()) or 1.0
        wanted = min(max(p.ae_target / mean, p.ae_range[0]), p.ae_range[1])
        if self._gain is None:
            self._gain = wanted  # settled at take-off
        else:
            self._gain = math.exp(math.log(self._gain) + p.ae_rate * (math.log(wanted) - math.log(self._gain)))
        return self._gain * self.bias

    def frame(self, render: np.ndarray | GLPixels, motion: FrameMotion = STILL) -> np.ndarray:
        """The frame a Tello sends of `render` (an HxWx3 uint8 pinhole image at the Tello's field of view, or the
        same as `GLPixels`): the lens (at the render's size), the streak, the exposure, the noise, the compression
        and the stream's size."""
        p = self.params
        rgbx, bottom_up = _rgbx(render)
        h, w = rgbx.shape[:2]
        pixels = rgbx.view(np.uint32).reshape(-1)  # a gather moves whole 4-byte pixels
        lens = np.take(pixels, self._lens_table(w, h, bottom_up), mode="clip")  # (all in range)
        img = Image.frombuffer("RGBX", (w, h), lens, "raw", "RGBX", 0, 1)  # shares `lens`, no copy
        if not motion.still:
            img = _motion_blur(img, motion, w / p.width)
        gain, k = self._exposure(rgbx, bottom_up), self.NOISE_MAX
        img = img.point(np.clip(np.rint(np.arange(256) * gain), k, 255 - k).astype(np.uint8).tolist() * 4)
        img = ImageChops.add_modulo(img, self._noise_image(w, h))  # never wraps: the exposure left k levels free
        buf = io.BytesIO()  # compressed at the render's size: the frame's detail is the render's (docs/camera.md)
        img.save(buf, format="JPEG", quality=p.jpeg_quality)
        self.jpeg_bytes = buf.tell()  # what the frame cost the stream (docs/camera.md compares it with the bitrate)
        out = Image.frombytes("RGB", (w, h), buf.getbuffer(), "jpeg", "RGB", "")  # the decoder alone, no file parsing
        if out.size != (p.width, p.height):
            out = out.resize((p.width, p.height), Image.Resampling.NEAREST)
        return _packed_rgb(out)


def _rgbx(render: np.ndarray | GLPixels) -> tuple[np.ndarray, bool]:
    """`render` as HxWx4 uint8 pixels (the fourth byte unused) and whether its bottom row comes first."""
    if isinstance(render, GLPixels):
        return np.ascontiguousarray(render.rgba), True
    h, w = render.shape[:2]
    rgbx = np.empty((h, w, 4), np.uint8)
    rgbx[..., :3] = render
    rgbx[..., 3] = 255
    return rgbx, False


def _packed_rgb(img: Image.Image) -> np.ndarray:
    """`img` as an HxWx3 uint8 array, packed in one pass (`np.asarray` packs it in 64 kB pieces, then joins them)."""
    w, h = img.size
    encoder = Image._getencoder(img.mode, "raw", ("RGB", 0, 1))
    encoder.setimage(img.im, (0, 0, w, h))
    _, status, data = encoder.encode(w * h * 3 + w * 4)  # room for every row at once: one call
    if status != 1:  # the raw encoder ends with 1 when every row is out (RawEncode.c)
        raise RuntimeError(f"packing a {w}x{h} frame ended with status {status}")
    return np.frombuffer(data, np.uint8).reshape(h, w, 3)


def _motion_blur(img: Image.Image, motion: FrameMotion, scale: float) -> Image.Image:
    """A streak along the move: a box blur as long as the streak along each axis (a sideways move or a turn
    streaks along x, a climb along y), and a forward move's zoom blur as a blend with a slightly scaled copy."""
    w, h = img.size
    bx, by = motion.blur_x_px * scale, motion.blur_y_px * scale
    if bx >= 1.5 or by >= 1.5:
        img = img.filter(ImageFilter.BoxBlur((bx / 2, by / 2)))
    if abs(motion.zoom) >= 1e-3:
        z = abs(motion.zoom)
        dx, dy = w * z / 2, h * z / 2
        # the inner crop, for a backward move too: the exposure spans scales 1 to 1 - z instead of 1 to 1 + z, the same
        # streak to the eye (and Pillow refuses a box outside the image)
        img = Image.blend(img, img.resize((w, h), Image.Resampling.NEAREST, box=(dx, dy, w - dx, h - dy)), 0.5)
    return img


class IdealCamera:
    """The render itself; a randomised world's exposure bias scales it (a lookup table)."""

    name = "ideal"

    def __init__(self) -> None:
        self.bias = 1.0

    def reset(self, seed: int | None, bias: float = 1.0, world: int | None = None) -> None:
        self.bias = bias

    def frame(self, render: np.ndarray | GLPixels, motion: FrameMotion = STILL) -> np.ndarray:
        rgb = render.top_down_rgb if isinstance(render, GLPixels) else render
        if abs(self.bias - 1) <= 1e-3:
            return rgb
        lut = [min(255, int(i * self.bias + 0.5)) for i in range(256)] * 3
        return _packed_rgb(Image.fromarray(np.ascontiguousarray(rgb)).point(lut))  # Pillow's table: 4x numpy's


def camera_flown_with(camera: str | None, lag_ms: float | None, randomize: int | None) -> dict[str, object]:
    """What a run with these options records of its frames, as `pilots.replay.camera_flown_with` reads it back. A lag
    asked of the ideal camera is kept, so that `pilots.replay.check_replay_camera` refuses it."""
    key = check_camera(camera or DEFAULT_CAMERA)
    if key == "ideal" and randomize is None and lag_ms is None:
        return {}
    out: dict[str, object] = {"camera": key}
    if key == "tello":
        out["camera_lag_ms"] = TelloCameraParams().lag_ms if lag_ms is None else float(lag_ms)
    elif lag_ms is not None:
        out["camera_lag_ms"] = float(lag_ms)
    if randomize is not None:
        out["randomize"] = int(randomize)
    return out


def make_camera(name: str, lag_ms: float | None = None) -> TelloCamera | IdealCamera:
    """The camera model called `name` (`core.cameras.CAMERAS`); `lag_ms` overrides the Tello's default frame lag."""
    key = check_camera(name)
    if key == "ideal":
        return IdealCamera()
    return TelloCamera(TelloCameraParams() if lag_ms is None else TelloCameraParams(lag_ms=float(lag_ms)))
