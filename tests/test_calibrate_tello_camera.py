"""scripts/calibrate_tello_camera.py: a chessboard calibration (OpenCV) recovers a known lens, and the `tello` camera
model's own frames calibrate to the lens it declares (docs/camera.md)."""

from __future__ import annotations

import runpy
from pathlib import Path

import pytest
from PIL import Image

from vlnpilot.sim.camera_model import TelloCameraParams, central_focal_px

cv2 = pytest.importorskip("cv2")
ROOT = Path(__file__).resolve().parents[1]
PATTERN = (9, 6)  # inner corners of the synthetic views' 10 x 7 board


@pytest.fixture(scope="module")
def tool() -> dict:
    return runpy.run_path(str(ROOT / "scripts" / "calibrate_tello_camera.py"))


def test_the_calibration_recovers_a_known_lens(tool) -> None:
    params = TelloCameraParams()
    cal = tool["calibrate"](tool["synthetic_views"](params, through_model=False), PATTERN)
    assert cal.views == len(tool["SYNTHETIC_POSES"]) and cal.rms_px < 0.5
    assert cal.k1 == pytest.approx(params.k1, abs=0.004) and abs(cal.k2) < 0.01
    assert cal.fx == pytest.approx(central_focal_px(params), rel=0.005)
    assert cal.diagonal_fov_deg == pytest.approx(params.diagonal_fov_deg, abs=0.3)
    assert "| k1 | -0.05" in tool["report"](cal, params)


def test_the_tello_models_frames_calibrate_to_the_lens_it_declares(tool) -> None:
    """Through the whole model (the lens table's nearest pixels, JPEG, the resize to 960x720) the calibration finds
    the declared field of view and centre; the nearest sampling blurs how k1 and k2 share the distortion."""
    params = TelloCameraParams()
    cal = tool["calibrate"](tool["synthetic_views"](params, through_model=True), PATTERN)
    assert cal.views == len(tool["SYNTHETIC_POSES"]) and cal.rms_px < 1.0
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
    (tmp_path / "torn.jpg").write_bytes(b"\xff\xd8\xff\xe0 not a whole JPEG")
    assert main([str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "torn.jpg" in err and len(err.strip().splitlines()) == 1


def test_a_directory_of_frames_is_calibrated_and_written(tool, tmp_path: Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    params = TelloCameraParams()
    views = tool["synthetic_views"](params, through_model=False, poses=tool["SYNTHETIC_POSES"][:8])
    for i, view in enumerate(views):
        Image.fromarray(view).save(tmp_path / f"front_{i:03d}.png")
    assert tool["main"]([str(tmp_path), "--json", str(tmp_path / "cal.json")]) == 0
    assert "diagonal field of view" in capsys.readouterr().out
    import json

    saved = json.loads((tmp_path / "cal.json").read_text())
    assert saved["views"] == 8 and saved["width"] == 960
    assert saved["diagonal_fov_deg"] == pytest.approx(params.diagonal_fov_deg, abs=0.5)
    assert tool["main"]([str(tmp_path), "--json", str(tmp_path / "no-such-dir" / "cal.json")]) == 2
    captured = capsys.readouterr()
    assert "diagonal field of view" in captured.out and "cannot write" in captured.err
