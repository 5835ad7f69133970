"""Shields and robots are chosen by name from registries, as pilots, executors and scenes are: a shield or a robot
that a third party registers (a decorator, or an entry point of `vlnpilot.shields` / `vlnpilot.robots`) is accepted
by `--shield` / `--robot`, `EpisodeConfig` and a suite's pin, and an unknown name lists the registered ones."""

from __future__ import annotations

from collections.abc import Iterator
from importlib.metadata import EntryPoint
from pathlib import Path

import pytest

from cli_support import run_main
from vlnpilot.bench.suite import SuiteError, suite_from_dict
from vlnpilot.core import registry as registry_module
from vlnpilot.core.errors import ConfigError, UnknownNameError
from vlnpilot.core.records import Motion, Pose
from vlnpilot.core.rundir import load_run
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.robots.session import ROBOT_REGISTRY, SimRobot, check_robot, get_robot, robot_capabilities
from vlnpilot.safety import SHIELD_REGISTRY, SafetyConfig, Shield, make_shield, register_shield

NO_FORWARD = "no-forward"
TWIN = "sim-twin"


class NoForwardShield(Shield):
    """A third party's shield that refuses every forward move (the drone hovers instead)."""

    name = NO_FORWARD

    def hazard(self, pose: Pose, motion: Motion) -> str | None:
        return "this shield refuses every forward move" if motion.forward_m > 0 else None


class TwinRobot(SimRobot):
    """A third party's robot: the simulator under another name (registered as a class)."""


@pytest.fixture
def no_forward() -> Iterator[str]:
    @register_shield(NO_FORWARD)
    def factory(env: object, config: SafetyConfig) -> Shield:
        return NoForwardShield(config)

    yield NO_FORWARD
    SHIELD_REGISTRY.unregister(NO_FORWARD)


@pytest.fixture
def twin() -> Iterator[str]:
    ROBOT_REGISTRY.register(TWIN)(TwinRobot)
    yield TWIN
    ROBOT_REGISTRY.unregister(TWIN)


# -- shields ------------------------------------------------------------------------------------------------------
def test_the_builtin_shields_are_registered_and_nothing_else_lists_them() -> None:
    import vlnpilot.safety.config as safety_config

    assert SHIELD_REGISTRY.group == "vlnpilot.shields"
    assert SHIELD_REGISTRY.names()[:4] == ["off", "geometry", "depth", "assist"]
    assert not hasattr(safety_config, "SHIELDS")  # one source of truth: the registry


def test_a_registered_shield_flies_from_the_command_line(monkeypatch: pytest.MonkeyPatch,
                                                         capsys: pytest.CaptureFixture[str], tmp_path: Path,
                                                         no_forward: str) -> None:
    """The oracle heads for the bathroom; every forward move it proposes is refused by the shield named."""
    out = tmp_path / "run"
    code, _, err = run_main(monkeypatch, capsys, "run", "Go to the bathroom", "--spawn", "living_room", "--pilot",
                            "oracle", "--shield", no_forward, "--max-steps", "6", "-q", "--no-video", "--out", str(out))
    assert code == 0, err
    summary, steps = load_run(out)
    assert summary["config"]["shield"] == no_forward and summary["result"]["outcome"] == "max_steps"
    forward = [s for s in steps if (s["proposed"] or "").startswith("A")]
    assert forward and all(s["interventions"] for s in forward)  # each refused (a hover, or the door assist's step)
    assert all("this shield refuses every forward move" in i["reason"] for s in forward for i in s["interventions"])
    assert not any((s["executed"] or "").startswith("A") for s in steps)  # it never flew forward


def test_a_registered_shield_is_accepted_by_the_config_and_a_suite_pin(geo_sim, no_forward: str) -> None:
    assert EpisodeConfig(shield=no_forward).shield == no_forward
    assert isinstance(make_shield(no_forward, geo_sim), NoForwardShield)
    rows = [{"spawn": "bedroom", "query": "Go to the bathroom", "goal": "bathroom"}]
    assert suite_from_dict({"shield": no_forward, "rows": rows}).shield == no_forward
    SHIELD_REGISTRY.unregister(no_forward)
    with pytest.raises(SuiteError, match=f"unknown shield '{no_forward}'; valid: off, geometry, depth, assist"):
        suite_from_dict({"shield": no_forward, "rows": rows})


def test_an_unknown_shield_is_one_line_naming_the_registered_ones(monkeypatch: pytest.MonkeyPatch,
                                                                 capsys: pytest.CaptureFixture[str], tmp_path: Path,
                                                                 geo_sim, no_forward: str) -> None:
    with pytest.raises(UnknownNameError, match="unknown shield 'lidar'; valid shields: assist, depth, geometry, "
                                               "no-forward, off$"):
        make_shield("lidar", geo_sim)
    with pytest.raises(ConfigError, match="unknown shield 'lidar'; valid shields: .*assist, no-forward$"):
        EpisodeConfig(shield="lidar")
    code, _, err = run_main(monkeypatch, capsys, "run", "Go to the bedroom", "--shield", "lidar", "--out",
                            str(tmp_path / "never"))
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "unknown shield 'lidar'" in err and no_forward in err and not (tmp_path / "never").exists()


def test_a_shield_from_an_entry_point_is_accepted(monkeypatch: pytest.MonkeyPatch, geo_sim) -> None:
    point = EntryPoint("entry-shield", f"{__name__}:_entry_shield", "vlnpilot.shields")
    monkeypatch.setattr(registry_module, "entry_points", lambda group: [point] if group == point.group else [])
    monkeypatch.setattr(SHIELD_REGISTRY, "_points", None)  # read the (patched) installed entry points again
    try:
        assert "entry-shield" in SHIELD_REGISTRY.names() and EpisodeConfig(shield="entry-shield")
        assert isinstance(make_shield("entry-shield", geo_sim), NoForwardShield)
    finally:
        SHIELD_REGISTRY.unregister("entry-shield")


def _entry_shield(env: object, config: SafetyConfig) -> Shield:
    return NoForwardShield(config)


# -- robots -------------------------------------------------------------------------------------------------------
def test_a_registered_robot_flies_from_the_command_line(monkeypatch: pytest.MonkeyPatch,
                                                        capsys: pytest.CaptureFixture[str], tmp_path: Path,
                                                        twin: str) -> None:
    out = tmp_path / "run"
    code, stdout, err = run_main(monkeypatch, capsys, "run", "Go to the bedroom", "--spawn", "bedroom", "--robot",
                                 twin, "--pilot", "oracle", "--sensors", "tof", "-q", "--no-video", "--out", str(out))
    assert code == 0, err
    assert stdout.startswith("success in 1 steps") and load_run(out)[0]["result"]["outcome"] == "success"
    assert robot_capabilities(twin, "tof").range_sensor == "tof" and isinstance(get_robot(twin), TwinRobot)


def test_tello_host_applies_only_to_a_robot_that_takes_it(twin: str) -> None:
    with pytest.raises(ConfigError, match="^--tello-host applies to --robot tello only$"):
        check_robot(twin, "127.0.0.1")
    assert check_robot(f" {twin.upper()} ", None) == twin


def test_an_unknown_robot_is_one_line_naming_the_registered_ones(monkeypatch: pytest.MonkeyPatch,
                                                                capsys: pytest.CaptureFixture[str], tmp_path: Path,
                                                                twin: str) -> None:
    code, _, err = run_main(monkeypatch, capsys, "run", "Go to the bedroom", "--robot", "drone", "--out",
                            str(tmp_path / "never"))
    assert code == 2 and err.strip() == f"error: unknown robot 'drone'; valid robots: sim, {twin}, tello"


def test_a_robot_from_an_entry_point_is_accepted(monkeypatch: pytest.MonkeyPatch) -> None:
    assert ROBOT_REGISTRY.group == "vlnpilot.robots"
    point = EntryPoint("entry-robot", f"{__name__}:TwinRobot", "vlnpilot.robots")
    monkeypatch.setattr(registry_module, "entry_points", lambda group: [point] if group == point.group else [])
    monkeypatch.setattr(ROBOT_REGISTRY, "_points", None)
    try:
        assert check_robot("entry-robot", None) == "entry-robot" and isinstance(get_robot("entry-robot"), TwinRobot)
    finally:
        ROBOT_REGISTRY.unregister("entry-robot")


def test_the_tello_stays_lazy() -> None:
    """Listing or checking robots imports none of the djitellopy-dependent modules (the `[tello]` extra)."""
    import subprocess
    import sys

    code = ("import sys; from vlnpilot.robots.session import ROBOT_REGISTRY, check_robot; check_robot('sim', None); "
            "ROBOT_REGISTRY.names(); "
            "print(sorted(m for m in sys.modules if m.startswith(('djitellopy', 'vlnpilot.robots.tello'))))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert proc.stdout.strip() == "[]"
