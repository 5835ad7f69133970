"""Calibrate a Tello's camera from chessboard frames (OpenCV) and compare it with the `tello` camera model.

Hold a printed chessboard (9x6 inner corners by default) in front of the drone at a dozen poses that between them
fill the frame's corners, keep the frames (a run's `frames/front_*.jpg`, or any JPEG or PNG), then:

    .venv/bin/python scripts/calibrate_tello_camera.py FRAMES_DIR [--pattern 9x6] [--json calibration.json]

It prints the focal lengths, the principal point, the radial terms k1 and k2 (the model's Brown coefficients: no
tangential term, no k3), the diagonal field of view they give, the RMS reprojection error, and the model's own values
(`TelloCameraParams`, docs/camera.md) beside them. Needs OpenCV (`pip install opencv-python-headless`; the `tello`
extra's djitellopy brings opencv-python). Bad input gets one line and exit code 2.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from PIL import Image

from vlnpilot.sim.camera_model import TelloCamera, TelloCameraParams, _undistort, central_focal_px

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png")
MIN_VIEWS = 6  # fewer views leave the radial terms poorly determined
# Synthetic views of a 10 x 7 board of 5 cm squares (9 x 6 inner corners), to check the tool and the model:
# (board centre in the camera frame, m: x right, y down, z ahead; yaw, pitch in degrees): the centre, the frame's
# four corners, tilts, and the edges
SYNTHETIC_POSES = [((0, 0, 0.8), 0, 0), ((-0.25, -0.17, 0.8), 20, -15), ((0.25, -0.17, 0.8), -20, -15),
                   ((-0.25, 0.17, 0.8), 20, 15), ((0.25, 0.17, 0.8), -20, 15), ((0, 0, 0.6), 30, 0),
                   ((0, 0, 0.6), -30, 0), ((0, 0, 0.6), 0, 30), ((0, 0, 0.6), 0, -30), ((-0.3, 0, 0.85), 10, 5),
                   ((0.3, 0, 0.85), -10, -5), ((0, 0.2, 0.85), 5, 10)]


class CalibrationError(ValueError):
    """Input that cannot be calibrated: one line for the user."""


@dataclass(frozen=True)
class Calibration:
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    k1: float
    k2: float
    rms_px: float
    views: int

    @property
    def diagonal_fov_deg(self) -> float:
        """The angle between the rays of two opposite corners of the frame (the spec sheet's measure)."""
        near = _ray_angle((0.0 - self.cx) / self.fx, (0.0 - self.cy) / self.fy, self.k1, self.k2)
        far = _ray_angle((self.width - self.cx) / self.fx, (self.height - self.cy) / self.fy, self.k1, self.k2)
        return math.degrees(near + far)

    def to_dict(self) -> dict[str, float | int]:
        return {**asdict(self), "diagonal_fov_deg": round(self.diagonal_fov_deg, 2)}


def _ray_angle(xd: float, yd: float, k1: float, k2: float) -> float:
    """The angle off the axis of the ray a distorted normalised point sees (the Brown model inverted)."""
    rd = math.hypot(xd, yd)
    ru = rd
    for _ in range(50):
        ru = rd / (1 + k1 * ru ** 2 + k2 * ru ** 4)
    return math.atan(ru)


def parse_pattern(text: str) -> tuple[int, int]:
    try:
        cols, rows = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise CalibrationError(f"--pattern must be COLSxROWS inner corners, e.g. 9x6; got {text!r}") from None
    if cols < 3 or rows < 3:
        raise CalibrationError(f"--pattern needs at least 3x3 inner corners; got {text!r}")
    return cols, rows


def frames_in(directory: Path) -> list[Path]:
    if not directory.is_dir():
        raise CalibrationError(f"{directory} is not a directory of frames")
    frames = sorted(p for p in directory.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not frames:
        raise CalibrationError(f"{directory} holds no frame ({', '.join(IMAGE_SUFFIXES)})")
    return frames


def _grey(path: Path) -> np.ndarray:
    try:
        with Image.open(path) as img:
            return np.asarray(img.convert("L"))
    except OSError as exc:
        raise CalibrationError(f"{path} is not a readable image ({exc})") from None


def calibrate(images: list[np.ndarray], pattern: tuple[int, int]) -> Calibration:
    """The camera's intrinsics and radial distortion from grey or RGB chessboard images of one size."""
    import cv2  # only this tool needs OpenCV

    sizes = {img.shape[:2] for img in images}
    if len(sizes) != 1:
        raise CalibrationError(f"the frames differ in size: {sorted(sizes)}")
    (height, width), = sizes
    board = np.zeros((pattern[0] * pattern[1], 3), np.float32)
    board[:, :2] = np.mgrid[0:pattern[0], 0:pattern[1]].T.reshape(-1, 2)  # in squares: the scale does not matter
    object_points, image_points = [], []
    for img in images:
        grey = img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
        found, corners = cv2.findChessboardCornersSB(grey, pattern, flags=cv2.CALIB_CB_EXHAUSTIVE)
        if found:
            object_points.append(board)
            image_points.append(corners.astype(np.float32))
    if len(image_points) < MIN_VIEWS:
        raise CalibrationError(f"the {pattern[0]}x{pattern[1]} chessboard was found in {len(image_points)} of "
                               f"{len(images)} frames; at least {MIN_VIEWS} are needed (check --pattern)")
    flags = cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K3  # the model's terms: k1 and k2 only
    rms, matrix, dist, _, _ = cv2.calibrateCamera(object_points, image_points, (width, height), None, None,
                                                  flags=flags)
    return Calibration(width=width, height=height, fx=float(matrix[0, 0]), fy=float(matrix[1, 1]),
                       cx=float(matrix[0, 2]), cy=float(matrix[1, 2]), k1=float(dist.ravel()[0]),
                       k2=float(dist.ravel()[1]), rms_px=float(rms), views=len(image_points))


def synthetic_views(params: TelloCameraParams, through_model: bool, poses: list = SYNTHETIC_POSES) -> list[np.ndarray]:
    """Chessboard frames with a known lens: made with the lens equations directly (`through_model` False: what a
    calibration must give back exactly), or through the `tello` camera model itself (a pinhole render at the Tello's
    field of view, then the lens table, JPEG and the resize: what the model's frames show of the lens it declares)."""
    if not through_model:
        f = central_focal_px(params)
        u, v = np.meshgrid(np.arange(params.width) + 0.5, np.arange(params.height) + 0.5)
        xu, yu = _undistort((u - params.width / 2) / f, (v - params.height / 2) / f, params.k1, params.k2)
        return [_board(xu, yu, *pose) for pose in poses]
    w, h = 640, 480  # the simulator's render, twice as fine then averaged: smooth edges
    f = math.hypot(2 * w, 2 * h) / 2 / math.tan(math.radians(params.diagonal_fov_deg) / 2)
    u, v = np.meshgrid(np.arange(2 * w) + 0.5, np.arange(2 * h) + 0.5)
    camera = TelloCamera(params)
    camera.reset(1)
    views = []
    for pose in poses:
        grey = np.asarray(Image.fromarray(_board((u - w) / f, (v - h) / f, *pose)).reduce(2))
        views.append(camera.frame(np.repeat(grey[..., None], 3, axis=2)))
    return views


def _board(xu: np.ndarray, yu: np.ndarray, center: tuple, yaw: float, pitch: float, square: float = 0.05,
           cols: int = 10, rows: int = 7) -> np.ndarray:
    """What the rays (xu, yu, 1) of a pinhole see of a chessboard: grey levels, with a white margin of one square."""
    cy, sy, cp, sp = (math.cos(math.radians(yaw)), math.sin(math.radians(yaw)), math.cos(math.radians(pitch)),
                      math.sin(math.radians(pitch)))
    rot = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]]) @ np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]])
    e1, e2 = rot[:, 0], rot[:, 1]
    normal = np.cross(e1, e2)
    origin = np.asarray(center, float) - cols / 2 * square * e1 - rows / 2 * square * e2
    t = (normal @ origin) / (normal[0] * xu + normal[1] * yu + normal[2])
    px, py, pz = t * xu - origin[0], t * yu - origin[1], t - origin[2]
    a = (px * e1[0] + py * e1[1] + pz * e1[2]) / square
    b = (px * e2[0] + py * e2[1] + pz * e2[2]) / square
    img = np.full(a.shape, 110, np.uint8)
    img[(a >= -1) & (a < cols + 1) & (b >= -1) & (b < rows + 1)] = 235
    dark = (np.floor(a).astype(int) + np.floor(b).astype(int)) % 2 == 0
    img[(a >= 0) & (a < cols) & (b >= 0) & (b < rows) & dark] = 20
    return img


def report(cal: Calibration, params: TelloCameraParams) -> str:
    """The calibration beside the model's values, scaled to the calibrated frame's width."""
    model_f = central_focal_px(params) * cal.width / params.width
    rows = [("focal length, px (fx / fy)", f"{cal.fx:.1f} / {cal.fy:.1f}", f"{model_f:.1f}"),
            ("principal point, px", f"{cal.cx:.1f}, {cal.cy:.1f}", f"{cal.width / 2:.1f}, {cal.height / 2:.1f}"),
            ("k1", f"{cal.k1:+.4f}", f"{params.k1:+.4f}"),
            ("k2", f"{cal.k2:+.4f}", f"{params.k2:+.4f}"),
            ("diagonal field of view, deg", f"{cal.diagonal_fov_deg:.1f}", f"{params.diagonal_fov_deg:.1f}")]
    lines = [f"{cal.views} views of {cal.width}x{cal.height}, RMS reprojection error {cal.rms_px:.2f} px", "",
             "| | this camera | the `tello` model |", "|---|---|---|"]
    lines += [f"| {name} | {measured} | {model} |" for name, measured, model in rows]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("frames", type=Path, help="a directory of chessboard frames (JPEG or PNG)")
    parser.add_argument("--pattern", default="9x6", help="inner corners of the chessboard, COLSxROWS (9x6)")
    parser.add_argument("--json", type=Path, help="also write the calibration here")
    args = parser.parse_args(argv)
    try:
        pattern = parse_pattern(args.pattern)
        images = [_grey(p) for p in frames_in(args.frames)]
        cal = calibrate(images, pattern)
    except ImportError:
        print("error: this tool needs OpenCV: pip install opencv-python-headless", file=sys.stderr)
        return 2
    except CalibrationError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(report(cal, TelloCameraParams()))
    if args.json is not None:
        try:
            args.json.write_text(json.dumps(cal.to_dict(), indent=2) + "\n")
        except OSError as exc:
            print(f"error: cannot write {args.json} ({exc.strerror}); the calibration is printed above",
                  file=sys.stderr)
            return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
