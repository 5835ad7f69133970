"""The camera model (`--camera tello`) and domain randomisation (`--randomize SEED`): docs/camera.md."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cli_support import run_main
from vlnpilot.bench.suite import suite_from_dict
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.records import Motion
from vlnpilot.robots.session import check_camera_for
from vlnpilot.sim import SimConfig, Simulator
from vlnpilot.sim.camera_model import (
    FrameMotion,
    GLPixels,
    IdealCamera,
    TelloCamera,
    TelloCameraParams,
    frame_motion,
    lagged_fraction,
)
from vlnpilot.sim.randomize import RANGES

MOVES = ("A1", "B1", "C1", "A2")


def _fly(config: SimConfig, seed: int = 7) -> list[np.ndarray]:
    with Simulator("cabin", config) as sim:
        frames = [sim.reset("living_room", seed=seed).front_rgb]
        frames += [sim.step(c).front_rgb for c in MOVES]
    return frames


def test_the_tello_camera_sends_960x720_frames_that_differ_from_the_render_and_repeat_per_seed() -> None:
    ideal = _fly(SimConfig(rear_camera=False))
    tello = _fly(SimConfig(rear_camera=False, camera="tello", randomize=1))
    again = _fly(SimConfig(rear_camera=False, camera="tello", randomize=1))
    other_world = _fly(SimConfig(rear_camera=False, camera="tello", randomize=2))
    assert ideal[0].shape == (480, 640, 3) and tello[0].shape == (720, 960, 3)
    assert all(np.array_equal(a, b) for a, b in zip(tello, again, strict=True))  # deterministic per seed
    assert not np.array_equal(tello[0], other_world[0])  # another randomisation seed: another world
    # the same view, not another one: the tello frame, brought back to 640x480, is close to the render
    from PIL import Image

    small = np.asarray(Image.fromarray(tello[0]).resize((640, 480)))
    plain = _fly(SimConfig(rear_camera=False, camera="tello"))[0]
    plain_small = np.asarray(Image.fromarray(plain).resize((640, 480))).astype(int)
    assert 1 < np.abs(plain_small - ideal[0].astype(int)).mean() < 40
    assert small.shape == ideal[0].shape


def test_the_frame_shows_the_settled_pose_unless_the_lag_outlasts_the_controllers_wait() -> None:
    p = TelloCameraParams(lag_ms=300)  # the controller waits 1.1 s after a move: a 300 ms stream shows it settled
    assert lagged_fraction(Motion(forward_m=0.5), 1.0, p) == 1.0
    assert lagged_fraction(Motion(forward_m=0.5), 0.6, p) == 0.6  # a move stopped short: where it stopped
    slow = TelloCameraParams(lag_ms=1600)  # 0.5 s longer than the wait
    forward = Motion(forward_m=0.5)  # 1 s at 0.5 m/s: the frame is from half way
    assert lagged_fraction(forward, 1.0, slow) == pytest.approx(0.5)
    assert lagged_fraction(Motion(forward_m=0.1), 1.0, slow) is None  # 0.2 s: the frame is from before the move
    turn = frame_motion(Motion(yaw_deg=30), p, focal_px=600)
    assert turn.blur_x_px > 5 and turn.blur_y_px == 0 and turn.zoom == 0  # a turn streaks along x
    climb = frame_motion(Motion(vertical_m=0.3), p, focal_px=600)
    assert climb.blur_y_px > 0 and climb.blur_x_px == 0
    seen = {}
    for lag in (300, 1700):  # A2 flies 0.5 s: 1.7 s of lag outlasts it and the 1.1 s wait: the hover before it
        with Simulator("cabin", SimConfig(rear_camera=False, camera="tello", camera_lag_ms=lag)) as sim:
            before = sim.reset("living_room", seed=1).front_rgb.astype(int)
            after = sim.step("A2")
            assert after.pose != sim.scene.spawn("living_room").pose  # the drone moved either way
            seen[lag] = np.abs(after.front_rgb.astype(int) - before).mean()
    assert seen[1700] < 2 < seen[300], seen  # a lag within the wait shows the move; a longer one where it began


def _as_read_back(rgb: np.ndarray) -> GLPixels:
    rgba = np.full((*rgb.shape[:2], 4), 255, np.uint8)
    rgba[..., :3] = rgb
    return GLPixels(np.ascontiguousarray(rgba[::-1]))  # bottom row first, as glReadPixels delivers it


@pytest.mark.parametrize("motion", [FrameMotion(), FrameMotion(blur_x_px=20), FrameMotion(blur_y_px=9, zoom=0.01),
                                    FrameMotion(zoom=-0.02)], ids=["still", "turn", "climb-forward", "backward"])
def test_the_gl_read_back_gives_the_frame_the_rgb_render_gives(motion: FrameMotion) -> None:
    """The simulator hands the Tello model OpenGL's rows as they are (no flip, no repack); the frame is the very one
    the top-down RGB render gives, pixel for pixel, and so every recorded frame still replays."""
    with Simulator("cabin", SimConfig(rear_camera=False, width=320, height=240)) as sim:
        rgb = sim.reset("living_room", seed=1).front_rgb
    frames = []
    for render in (rgb, _as_read_back(rgb)):
        camera = TelloCamera()
        camera.reset(3, bias=1.1, world=2)
        frames.append(camera.frame(render, motion))
    assert frames[0].shape == (720, 960, 3) and frames[0].flags.c_contiguous
    assert np.array_equal(frames[0], frames[1])


def test_the_simulator_reads_the_front_camera_back_for_the_tello_model_only(monkeypatch: pytest.MonkeyPatch) -> None:
    import vlnpilot.sim.simulator as simulator

    reads: list[tuple[int, int, int]] = []
    original = simulator.read_rgba

    def counted(renderer, model):  # type: ignore[no-untyped-def]
        pixels = original(renderer, model)
        reads.append(pixels.rgba.shape if pixels is not None else None)
        return pixels

    monkeypatch.setattr(simulator, "read_rgba", counted)
    _fly(SimConfig(rear_camera=False))
    assert reads == []  # the ideal camera: MuJoCo's own RGB render
    _fly(SimConfig(rear_camera=False, camera="tello"))
    assert reads == [(480, 640, 4)] * (1 + len(MOVES))


def test_a_read_back_that_opengl_refuses_falls_back_to_mujocos_and_the_frames_stay(monkeypatch: pytest.MonkeyPatch
                                                                                     ) -> None:
    """PyOpenGL that cannot drive the context (its GLError): the frame comes from MuJoCo's own read-back, the same."""
    from OpenGL import GL
    from OpenGL import error as gl_error

    config = SimConfig(rear_camera=False, camera="tello")
    expected = _fly(config)
    calls = []

    def refused(*args: object) -> None:
        calls.append(args)
        raise gl_error.GLError(err=1282, result=None, cArguments=args, description=b"invalid operation")

    monkeypatch.setattr(GL, "glReadPixels", refused)
    frames = _fly(config)
    assert len(calls) == len(expected)  # every frame tried the read-back, and every one fell back
    assert all(np.array_equal(a, b) for a, b in zip(frames, expected, strict=True))


def test_the_ideal_camera_scales_a_randomised_worlds_render_by_its_exposure_bias() -> None:
    rgb = np.arange(256, dtype=np.uint8).repeat(3).reshape(16, 16, 3)
    camera = IdealCamera()
    camera.reset(1, bias=1.25)
    out = camera.frame(rgb)
    assert np.array_equal(out, np.minimum(255, (rgb.astype(int) * 1.25 + 0.5).astype(int)))
    assert np.array_equal(camera.frame(_as_read_back(rgb)), out)
    camera.reset(1, bias=1.0)
    assert camera.frame(rgb) is rgb


def test_randomisation_stays_in_its_ranges_leaves_the_drone_alone_and_repeats_per_seed() -> None:
    with Simulator("cabin", SimConfig(rear_camera=False)) as plain, \
            Simulator("cabin", SimConfig(rear_camera=False, randomize=5)) as rand:
        r = rand.randomization
        for name in ("light_intensity", "light_temperature_k", "camera_height_m", "exposure_ev"):
            lo, hi = RANGES[name]
            assert lo <= getattr(r, name) <= hi
        ratio = rand.model.mat_rgba[:, :3] / np.maximum(plain.model.mat_rgba[:, :3], 1e-9)
        drone = [i for i in range(plain.model.nmat) if plain.model.material(i).name.startswith("drone_")]
        assert drone and np.allclose(rand.model.mat_rgba[drone], plain.model.mat_rgba[drone])
        lit = plain.model.mat_rgba[:, :3] > 0.05
        low = RANGES["material_brightness"][0] * RANGES["material_tint"][0]
        high = RANGES["material_brightness"][1] * RANGES["material_tint"][1]
        clipped = rand.model.mat_rgba[:, :3][lit] >= 1  # a white paint made lighter stays white
        assert ((ratio[lit] >= low - 1e-6) & ((ratio[lit] <= high + 1e-6) | clipped)).all()
        first = rand.model.mat_rgba.copy()
        rand.reset("living_room")
        rand.reset("bedroom")
        assert np.array_equal(rand.model.mat_rgba, first)  # applied from the base values: repeatable
        assert rand.camera_settings()["randomize"]["seed"] == 5
        assert not np.allclose(rand.model.light_diffuse, plain.model.light_diffuse)
        assert np.array_equal(rand.model.geom_size, plain.model.geom_size)  # geometry never changes


def test_a_tello_run_is_recorded_and_its_replay_reproduces_every_frame(tmp_path: Path,
                                                                       monkeypatch: pytest.MonkeyPatch,
                                                                       capsys: pytest.CaptureFixture[str]) -> None:
    flown, replayed = tmp_path / "flown", tmp_path / "replayed"
    code, _, err = run_main(monkeypatch, capsys, "run", "Go to the kitchen", "--pilot", "oracle", "--camera", "tello",
                            "--randomize", "3", "--out", str(flown), "--no-video", "-q")
    assert code == 0, err
    camera = json.loads((flown / "summary.json").read_text())["config"]["camera"]
    assert camera["model"] == "tello" and camera["lag_ms"] == 300 and camera["randomize"]["seed"] == 3
    code, _, err = run_main(monkeypatch, capsys, "run", "Go to the kitchen", "--pilot", f"replay:{flown}",
                            "--out", str(replayed), "--no-video", "-q")
    assert code == 0, err
    again = json.loads((replayed / "summary.json").read_text())
    assert again["config"]["camera"] == camera
    steps = sorted(p.name for p in (flown / "frames").glob("front_*.jpg"))
    assert steps and steps == sorted(p.name for p in (replayed / "frames").glob("front_*.jpg"))
    assert all((flown / "frames" / n).read_bytes() == (replayed / "frames" / n).read_bytes() for n in steps)
    code, _, err = run_main(monkeypatch, capsys, "run", "Go to the kitchen", "--pilot", f"replay:{flown}",
                            "--camera", "ideal", "--out", str(tmp_path / "other"), "--no-video", "-q")
    assert code == 2 and len(err.strip().splitlines()) == 1, err  # the replay's refusal, not the recorded lag's
    assert "was flown with other frames; replay it with --camera tello --camera-lag-ms 300.0 --randomize 3" in err
    assert not (tmp_path / "other").exists()  # refused before anything is written
    # as a trial: its set's suite replays the row in the same world (tests/test_trials.py reads it too)
    import runpy

    import yaml

    script = runpy.run_path(str(Path(__file__).resolve().parents[1] / "scripts" / "import_trial.py"))
    dest = script["import_trial"](flown, tmp_path / "set", "living-kitchen-1", flown_by="a test", interface="files",
                                  scene=None, account=None, memory="none")
    assert json.loads((dest / "trial.json").read_text())["camera"] == camera
    assert yaml.safe_load((tmp_path / "set" / "suite.yaml").read_text())["rows"][0]["randomize"] == 3


def test_a_run_with_the_ideal_camera_records_no_camera(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_main(monkeypatch, capsys, "run", "Go to the kitchen", "--pilot", "oracle", "--out",
                            str(tmp_path / "r"), "--no-video", "-q", "--max-steps", "2")
    assert code == 0, err
    assert "camera" not in json.loads((tmp_path / "r" / "summary.json").read_text())["config"]


@pytest.mark.parametrize("args, says", [
    (("--camera", "fisheye"), "unknown camera 'fisheye'; valid cameras: ideal, tello"),
    (("--camera-lag-ms", "100"), "a camera lag applies to --camera tello only"),
    (("--robot", "tello", "--camera", "ideal"), "--camera ideal applies to --robot sim only"),
    (("--robot", "tello", "--camera-lag-ms", "500"), "vln-pilot tello-emulator --video-delay 0.5"),
])
def test_bad_camera_options_get_one_line_and_exit_2(args: tuple[str, ...], says: str, tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_main(monkeypatch, capsys, "run", "Go to the kitchen", "--pilot", "oracle", *args,
                            "--out", str(tmp_path / "r"), "--no-video", "-q")
    assert code == 2 and len(err.strip().splitlines()) == 1 and says in err, err
    assert not (tmp_path / "r").exists()  # refused before the run directory is claimed


def test_a_real_tello_frames_are_never_post_processed() -> None:
    check_camera_for("tello", "tello", None, None)  # what it is: accepted, and nothing is applied
    with pytest.raises(ConfigError, match=r"--randomize applies to --robot sim only .*tello-emulator --randomize 4\)"):
        check_camera_for("tello", None, None, 4)
    # the emulator has no --camera-lag-ms: its frame lag is --video-delay, in seconds
    with pytest.raises(ConfigError, match=r"--camera-lag-ms applies to --robot sim only .*its --video-delay, in "
                                          r"seconds: vln-pilot tello-emulator --video-delay 0.5\)"):
        check_camera_for("tello", None, 500.0, None)


def _suite(**extra: object) -> dict:
    return {"scene": "cabin", "rows": [{"id": "a", "spawn": "living_room", "query": "Go to the kitchen",
                                        "randomize": 9},
                                       {"id": "b", "spawn": "living_room", "query": "Go to the bedroom"}], **extra}


def test_a_suite_takes_a_randomisation_seed_per_row_and_per_suite(tmp_path: Path) -> None:
    from vlnpilot.bench.runner import BenchSettings, plan

    suite = suite_from_dict(_suite(randomize=4), source="t")
    assert [r.randomize for r in suite.rows] == [9, None] and suite.randomize == 4
    assert suite_from_dict(suite.to_dict(), source="again").canonical() == suite.canonical()
    specs = plan(suite, [_entry()], BenchSettings(camera="tello", randomize=1), tmp_path)
    assert {s.row: s.randomize for s in specs} == {"a": 9, "b": 4}  # the row's, else the suite's
    assert {s.camera for s in specs} == {"tello"}
    plain = suite_from_dict(_suite(), source="t")
    assert {s.row: s.randomize for s in plan(plain, [_entry()], BenchSettings(randomize=1), tmp_path)} == \
        {"a": 9, "b": 1}  # else the bench's
    with pytest.raises(ConfigError, match="'randomize' must be a seed"):
        suite_from_dict(_suite(randomize="x"), source="t")


def _entry():
    from vlnpilot.bench.runner import PilotEntry

    return PilotEntry(spec="oracle", model=None, dir="oracle", options={})


def test_the_emulator_streams_the_tello_camera_frames(monkeypatch: pytest.MonkeyPatch) -> None:
    """Over H.264 on 127.0.0.1, djitellopy decodes the Tello camera's 960x720 frames."""
    from tello_support import rig

    with rig(emulator={"camera": "tello", "randomize": 2}) as (emu, env):
        obs = env.reset("living_room")
        assert obs.front_rgb.shape == (720, 960, 3)
        sent = emu._grab()
        assert np.abs(obs.front_rgb.astype(int) - sent.astype(int)).mean() < 15


def test_the_gym_environments_take_the_camera_and_a_randomised_world() -> None:
    from vlnpilot.sim.gym_env import CabinEnv

    env = CabinEnv(camera="tello", randomize=2)
    try:
        obs, _ = env.reset(seed=1)
        assert obs["front"].shape == env.observation_space["front"].shape == (720, 960, 3)
        assert env.observation_space.contains(env.step(0)[0])
        assert env.sim.camera_settings()["randomize"]["seed"] == 2
    finally:
        env.close()


def test_a_suite_pins_its_camera_and_an_unknown_one_is_refused_naming_the_valid() -> None:
    from vlnpilot.bench.suite import SuiteError, suite_pins

    rows = [{"spawn": "living_room", "query": "Go to the bathroom", "goal": "bathroom"}]
    assert suite_from_dict({"name": "t", "camera": "tello", "rows": rows}).pins().camera == "tello"
    assert suite_from_dict({"name": "t", "rows": rows}).camera is None
    assert suite_pins(Path(__file__).resolve().parents[1] / "trials" / "tello-cabin" / "suite.yaml").camera == "tello"
    with pytest.raises(SuiteError, match="unknown camera 'fisheye'; valid: ideal, tello"):
        suite_from_dict({"name": "t", "camera": "fisheye", "rows": rows})
