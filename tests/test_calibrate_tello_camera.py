"""scripts/calibrate_tello_camera.py: a chessboard calibration (OpenCV) recovers a known lens, and the `tello` camera
model's own frames calibrate to the lens it declares (docs/camera.md)."""

from __future__ import annotations

import math
import runpy
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from vlnpilot.sim.camera_model import TelloCamera, TelloCameraParams, _undistort, central_focal_px

cv2 = pytest.importorskip("cv2")
ROOT = Path(__file__).resolve().parents[1]
PATTERN = (9, 6)  # inner corners of a 10 x 7 board of 5 cm squares
# (board centre in the camera frame, m: x right, y down, z ahead; yaw, pitch in degrees): the centre, the four
# corners of the frame, tilts, and the edges
POSES = [((0, 0, 0.8), 0, 0), ((-0.25, -0.17, 0.8), 20, -15), ((0.25, -0.17, 0.8), -20, -15),
         ((-0.25, 0.17, 0.8), 20, 15), ((0.25, 0.17, 0.8), -20, 15), ((0, 0, 0.6), 30, 0), ((0, 0, 0.6), -30, 0),
         ((0, 0, 0.6), 0, 30), ((0, 0, 0.6), 0, -30), ((-0.3, 0, 0.85), 10, 5), ((0.3, 0, 0.85), -10, -5),
         ((0, 0.2, 0.85), 5, 10)]


@pytest.fixture(scope="module")
def tool() -> dict:
    return runpy.run_path(str(ROOT / "scripts" / "calibrate_tello_camera.py"))


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


def _through_the_lens(params: TelloCameraParams, pose: tuple) -> np.ndarray:
    """A 960x720 frame made with the model's lens equations directly (no sampling of a render)."""
    f = central_focal_px(params)
    u, v = np.meshgrid(np.arange(params.width) + 0.5, np.arange(params.height) + 0.5)
    xu, yu = _undistort((u - params.width / 2) / f, (v - params.height / 2) / f, params.k1, params.k2)
    return _board(xu, yu, *pose)


def _pinhole_render(params: TelloCameraParams, pose: tuple, w: int = 640, h: int = 480) -> np.ndarray:
    """The chessboard as the simulator's pinhole render shows it at the Tello's diagonal field of view (RGB)."""
    f = math.hypot(2 * w, 2 * h) / 2 / math.tan(math.radians(params.diagonal_fov_deg) / 2)
    u, v = np.meshgrid(np.arange(2 * w) + 0.5, np.arange(2 * h) + 0.5)  # twice as fine, then averaged: smooth edges
    grey = np.asarray(Image.fromarray(_board((u - w) / f, (v - h) / f, *pose)).reduce(2))
    return np.repeat(grey[..., None], 3, axis=2)


def test_the_calibration_recovers_a_known_lens(tool) -> None:
    params = TelloCameraParams()
    cal = tool["calibrate"]([_through_the_lens(params, pose) for pose in POSES], PATTERN)
    assert cal.views == len(POSES) and cal.rms_px < 0.5
    assert cal.k1 == pytest.approx(params.k1, abs=0.004) and abs(cal.k2) < 0.01
    assert cal.fx == pytest.approx(central_focal_px(params), rel=0.005)
    assert cal.diagonal_fov_deg == pytest.approx(params.diagonal_fov_deg, abs=0.3)
    assert "| k1 | -0.05" in tool["report"](cal, params)


def test_the_tello_models_frames_calibrate_to_the_lens_it_declares(tool) -> None:
    """Through the whole model (the lens table's nearest pixels, JPEG, the resize to 960x720) the calibration finds
    the declared field of view and centre; the nearest sampling blurs how k1 and k2 share the distortion."""
    params = TelloCameraParams()
    camera = TelloCamera(params)
    camera.reset(1)
    cal = tool["calibrate"]([camera.frame(_pinhole_render(params, pose)) for pose in POSES], PATTERN)
    assert cal.views == len(POSES) and cal.rms_px < 1.0
    assert cal.diagonal_fov_deg == pytest.approx(params.diagonal_fov_deg, abs=1.0)
    assert (cal.cx, cal.cy) == (pytest.approx(480, abs=3), pytest.approx(360, abs=3))
    assert cal.fx == pytest.approx(central_focal_px(params), rel=0.02)


def test_bad_input_is_one_line_and_exit_2(tool, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    main = tool["main"]
    assert main([str(tmp_path / "none")]) == 2
    assert "is not a directory of frames" in capsys.readouterr().err
    assert main([str(tmp_path)]) == 2
    assert "holds no frame" in capsys.readouterr().err
    Image.new("L", (96, 72), 128).save(tmp_path / "blank.png")
    assert main([str(tmp_path), "--pattern", "nine"]) == 2
    assert "--pattern must be COLSxROWS" in capsys.readouterr().err
    assert main([str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "found in 0 of 1 frames; at least 6 are needed" in err and len(err.strip().splitlines()) == 1


def test_a_directory_of_frames_is_calibrated_and_written(tool, tmp_path: Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    params = TelloCameraParams()
    for i, pose in enumerate(POSES[:8]):
        Image.fromarray(_through_the_lens(params, pose)).save(tmp_path / f"front_{i:03d}.png")
    assert tool["main"]([str(tmp_path), "--json", str(tmp_path / "cal.json")]) == 0
    assert "diagonal field of view" in capsys.readouterr().out
    import json

    saved = json.loads((tmp_path / "cal.json").read_text())
    assert saved["views"] == 8 and saved["width"] == 960
    assert saved["diagonal_fov_deg"] == pytest.approx(params.diagonal_fov_deg, abs=0.5)
