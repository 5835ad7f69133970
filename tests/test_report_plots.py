"""The report's figures (report/plots.py): the PNG files the bench plots write, read back as pixels, and the
episode floor plan with the pixel positions it promises."""

from __future__ import annotations

import io
import warnings
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from vlnpilot.report import plots

DPI = 150  # the benchmark plots' resolution
HALF_PX = (round(plots.HALF[0] * DPI), round(plots.HALF[1] * DPI))  # 960 x 600
PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(autouse=True)
def _quiet_empty_legends():
    with warnings.catch_warnings():  # an empty plot has no labelled artist for its legend: expected here
        warnings.filterwarnings("ignore", "No artists with labels found", UserWarning)
        yield


def _pixels(path: Path) -> np.ndarray:
    assert path.read_bytes().startswith(PNG)
    return np.asarray(Image.open(path).convert("RGB"))


def _area(image: np.ndarray, color: str) -> int:
    """Pixels of exactly `color` ('#rrggbb'): the inside of bars, not their anti-aliased edges."""
    rgb = [int(color[i:i + 2], 16) for i in (1, 3, 5)]
    return int(np.all(image == rgb, axis=2).sum())


def _height(image: np.ndarray, color: str) -> int:
    rgb = [int(color[i:i + 2], 16) for i in (1, 3, 5)]
    return int(np.all(image == rgb, axis=2).any(axis=1).sum())


def test_success_rates_bars_are_as_tall_as_the_rates(tmp_path: Path):
    path = plots.plot_success_rates(["oracle", "model"], [4, 1], [4, 4], tmp_path / "sub" / "success.png")
    assert path == tmp_path / "sub" / "success.png"  # the folder is made
    image = _pixels(path)
    assert (image.shape[1], image.shape[0]) == HALF_PX
    full, quarter = _height(image, plots.pilot_color(0)), _height(image, plots.pilot_color(1))
    assert full == pytest.approx(4 * quarter, rel=0.05)  # 100% against 25%, on the same axis


def test_outcomes_stack_in_their_colours_and_proportions(tmp_path: Path):
    counts = {"a": {"success": 3, "collision": 1}, "b": {"max_steps": 2}}
    image = _pixels(plots.plot_outcomes(["a", "b"], counts, tmp_path / "outcomes.png"))
    c = plots.OUTCOME_COLORS
    collision = _area(image, c["collision"])
    assert collision > 0
    assert _area(image, c["success"]) == pytest.approx(3 * collision, rel=0.1)
    assert _area(image, c["max_steps"]) == pytest.approx(2 * collision, rel=0.1)
    for absent in ("false_success", "pilot_error", "halted"):
        assert _area(image, c[absent]) == 0, absent


def test_failures_per_query_grows_with_the_queries(tmp_path: Path):
    small = _pixels(plots.plot_failures_per_query(["q1", "q2"], ["a", "b"], {"a": [1, 0], "b": [0, 2]},
                                                  {"a": [0, 0]}, tmp_path / "small.png"))
    assert small.shape[:2] == (round(3.2 * DPI), round(plots.FULL_W * DPI))  # the minimum height
    queries = [f"q{i}" for i in range(10)]
    tall = _pixels(plots.plot_failures_per_query(queries, ["a", "b"], {"a": [1] * 10}, {"b": [2] * 10},
                                                 tmp_path / "tall.png"))
    assert tall.shape[0] == round((0.28 * 10 * 2 + 1.6) * DPI)
    assert _area(tall, plots.pilot_color(0)) > 0 and _area(tall, plots.pilot_color(1)) > 0


def test_cost_bars_follow_the_mean_cost(tmp_path: Path):
    image = _pixels(plots.plot_cost_latency(["cheap", "dear"], {"cheap": [0.01, 0.01], "dear": [0.03, 0.05]},
                                            {"cheap": [1.0, 2.0], "dear": [3.0]}, tmp_path / "cost.png"))
    assert image.shape[:2] == (round(4.0 * DPI), round(plots.FULL_W * DPI))

    def bar_height(i: int) -> int:  # bars are drawn at alpha 0.85 over white
        rgb = np.array([int(plots.pilot_color(i)[k:k + 2], 16) for k in (1, 3, 5)])
        blended = np.round(0.85 * rgb + 0.15 * 255)
        left = image[:, : image.shape[1] // 2].astype(int)  # the cost panel
        return int((np.abs(left - blended).max(axis=2) <= 1).any(axis=1).sum())

    assert bar_height(1) == pytest.approx(4 * bar_height(0), rel=0.05)  # mean 0.04 against 0.01


@pytest.mark.parametrize("plot", ["success", "outcomes", "failures", "cost"])
def test_empty_data_still_makes_a_figure(tmp_path: Path, plot: str):
    path = tmp_path / f"{plot}.png"
    {"success": lambda: plots.plot_success_rates(["idle"], [0], [0], path),
     "outcomes": lambda: plots.plot_outcomes(["idle"], {}, path),
     "failures": lambda: plots.plot_failures_per_query([], ["idle"], {}, {}, path),
     "cost": lambda: plots.plot_cost_latency(["idle"], {}, {}, path)}[plot]()
    assert path.read_bytes().startswith(PNG) and Image.open(path).size[0] > 0


def test_floor_plan_maps_metres_to_the_pixels_it_reports(scene):
    (xmin, ymin), (xmax, ymax) = scene.bounds
    plan = plots.render_plan(scene, trajectory=[{"x": 1.0, "y": 1.0}, {"x": 2.0, "y": 1.5}],
                             states=["Recognize Room", "Search Object"],
                             positions_of=[{"x": xmin, "y": ymin}, None, {"x": xmax, "y": ymax}], width_px=600)
    margin = 0.3  # around the walls' outer faces
    scale = 600 / (xmax - xmin + 2 * margin)
    width, height = plan.size
    assert width == 600 and height == pytest.approx(600 * (ymax - ymin + 2 * margin) / (xmax - xmin + 2 * margin),
                                                    abs=1)
    assert plan.meters_to_px == pytest.approx(scale)
    low, missing, high = plan.positions
    assert missing is None
    assert low == pytest.approx((margin * scale, height - margin * scale), abs=0.5)  # y grows downwards
    assert high == pytest.approx((width - margin * scale, margin * scale), abs=0.5)
    assert set(plan.state_colors) == {"Recognize Room", "Search Object"}
    assert len(set(plan.state_colors.values())) == 2
    png = plan.png()
    assert png.startswith(PNG) and Image.open(io.BytesIO(png)).size == plan.size


def test_floor_plan_without_a_trajectory(scene):
    plan = plots.render_plan(scene, width_px=300)
    assert plan.size[0] == 300 and plan.positions == [] and plan.state_colors == {}
    assert plan.rgb.std() > 0  # the plan is drawn, not a blank canvas
