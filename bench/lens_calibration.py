"""The Tello camera model's lens, calibrated (issue 25): scripts/calibrate_tello_camera.py on chessboard frames made
with the model's lens equations (the calibration must give them back) and on the model's own frames (a pinhole
render through the lens table, JPEG and the resize), beside the values the model declares.

    .venv/bin/python bench/lens_calibration.py [--smoke]
"""

from __future__ import annotations

import argparse
import runpy
import sys
import time
from pathlib import Path

from machine import describe, publish  # bench/machine.py, beside this script

from vlnpilot.sim.camera_model import TelloCameraParams

ROOT = Path(__file__).resolve().parents[1]
OUT = Path(__file__).parent / "results" / "lens_calibration.md"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--smoke", action="store_true", help="6 views instead of 12 (for the tests)")
    args = parser.parse_args()
    tool = runpy.run_path(str(ROOT / "scripts" / "calibrate_tello_camera.py"))
    poses = tool["SYNTHETIC_POSES"][:6] if args.smoke else tool["SYNTHETIC_POSES"]
    params = TelloCameraParams()
    lines = ["# The Tello camera model's lens, calibrated", "", f"Machine: {describe()}.", ""]
    for through_model, title in ((False, "Frames made with the model's lens equations"),
                                 (True, "The model's own frames (pinhole render, lens table, JPEG, resize)")):
        t0 = time.perf_counter()
        cal = tool["calibrate"](tool["synthetic_views"](params, through_model, poses), (9, 6))
        lines += [f"## {title}", "", tool["report"](cal, params), "",
                  f"({time.perf_counter() - t0:.1f} s)", ""]
    publish("\n".join(lines), OUT, smoke=args.smoke)
    return 0


if __name__ == "__main__":
    sys.exit(main())
