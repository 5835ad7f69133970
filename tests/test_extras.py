"""The plain install and its extras (issue 21): without an extra the oracle still flies from the command line,
and a command that needs a missing extra says which one in one line, with exit code 2.

A missing package is simulated: `sys.modules[name] = None` makes `import name` raise ModuleNotFoundError, as
it does where the package is not installed; the plain-install flight runs in a child process whose import
system refuses every optional package at once.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import tomllib
from pathlib import Path

import pytest

from cli_support import run_main
from vlnpilot.core import extras
from vlnpilot.pilots import base as pilots_base

ROOT = Path(__file__).resolve().parents[1]
OPTIONAL = sorted({module for modules in extras.EXTRA_MODULES.values() for module in modules})


def _without(monkeypatch: pytest.MonkeyPatch, *modules: str) -> None:
    """Make `modules` (and whatever vlnpilot already imported from them) look uninstalled for this test."""
    for name in list(sys.modules):
        top = name.partition(".")[0]
        if top in modules or name.startswith("vlnpilot.pilots.") and name.rpartition(".")[2] in modules:
            monkeypatch.delitem(sys.modules, name)
    for module in modules:
        monkeypatch.setitem(sys.modules, module, None)


def _one_line_exit_2(code: int, err: str, extra: str) -> None:
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1, err
    assert f"pip install 'vln-pilot[{extra}]'" in err
    assert "Traceback" not in err


@pytest.mark.parametrize(("pilot", "module", "extra"), [
    ("openai", "openai", "openai"), ("gemini", "google", "gemini"), ("anthropic", "anthropic", "anthropic"),
    ("remote", "httpx", "server"),
])
def test_a_model_pilot_without_its_extra_is_one_line_and_exit_2(monkeypatch: pytest.MonkeyPatch, capsys,
                                                                  tmp_path: Path, pilot: str, module: str,
                                                                  extra: str) -> None:
    _without(monkeypatch, module)
    monkeypatch.delitem(pilots_base.PILOT_REGISTRY._entries, pilot, raising=False)  # imported afresh
    code, _, err = run_main(monkeypatch, capsys, "run", "Go to the bedroom", "--pilot", pilot,
                            "--out", str(tmp_path / "run"))
    _one_line_exit_2(code, err, extra)
    assert f"the {pilot} pilot needs {module}" in err
    assert not (tmp_path / "run").exists()  # refused before anything flew


def test_the_list_of_pilots_names_the_ones_whose_extra_is_missing(monkeypatch: pytest.MonkeyPatch) -> None:
    _without(monkeypatch, "openai", "anthropic")
    monkeypatch.delitem(pilots_base.PILOT_REGISTRY._entries, "openai", raising=False)
    assert {"openai", "anthropic", "oracle"} <= set(pilots_base.known_pilots())


@pytest.mark.parametrize(("args", "module", "extra"), [
    (("serve",), "fastapi", "server"),
    (("watch", "RUN"), "uvicorn", "server,report"),
    (("report", "RUN"), "matplotlib", "report"),
    (("report", "RUN"), "av", "report"),
    (("tello-emulator",), "av", "tello"),
    (("run", "Go to the bedroom", "--robot", "tello", "--out", "RUN/new"), "djitellopy", "tello"),
])
def test_a_command_without_its_extra_is_one_line_and_exit_2(monkeypatch: pytest.MonkeyPatch, capsys,
                                                             tmp_path: Path, args: tuple[str, ...], module: str,
                                                             extra: str) -> None:
    (tmp_path / "summary.json").write_text("{}")
    _without(monkeypatch, module)
    code, _, err = run_main(monkeypatch, capsys, *(a.replace("RUN", str(tmp_path)) for a in args))
    _one_line_exit_2(code, err, extra)
    assert module in err


def test_an_optional_module_no_block_names_still_gives_one_line(monkeypatch: pytest.MonkeyPatch, capsys) -> None:
    """The command line's last resort: a ModuleNotFoundError of any optional package names its extras."""
    from vlnpilot import cli

    def boom(*_a, **_k):
        import ray  # noqa: F401

    _without(monkeypatch, "ray")
    monkeypatch.setattr(cli, "app", boom)
    code, _, err = run_main(monkeypatch, capsys, "bench")
    _one_line_exit_2(code, err, "ray")


def test_every_extra_module_comes_from_its_extra_in_pyproject() -> None:
    """extras.EXTRA_MODULES and pyproject's optional dependencies name the same extras; [all] has them all."""
    optional = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    assert set(extras.EXTRA_MODULES) <= set(optional)
    assert optional["all"] == [f"vln-pilot[{','.join(extras.EXTRA_MODULES)}]"]
    assert "vln-pilot[all]" in optional["test"]


def test_the_install_page_lists_every_extra() -> None:
    """docs/install.md's extras table has one row per extra of pyproject.toml, `all` and `test` included."""
    import re

    optional = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    page = (ROOT / "docs" / "install.md").read_text()
    listed = re.findall(r"^\| `([a-z]+)` \|", page, flags=re.MULTILINE)
    assert sorted(listed) == sorted(optional)


_PLAIN_INSTALL = textwrap.dedent("""
    import importlib.abc, sys
    BLOCKED = set(sys.argv[1].split(","))

    class NotInstalled(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name.partition(".")[0] in BLOCKED:
                raise ModuleNotFoundError(f"No module named {name!r}", name=name)
            return None

    sys.meta_path.insert(0, NotInstalled())
    sys.argv = ["vln-pilot", *sys.argv[2:]]
    from vlnpilot.cli import main
    main()
""")


def test_the_plain_install_flies_the_oracle_and_says_how_to_get_the_report(tmp_path: Path) -> None:
    """`vln-pilot run "Go to the bedroom"` with no optional package importable: flown, recorded, exit 0."""
    env = {k: v for k, v in os.environ.items() if k not in ("OPENAI_API_KEY", "GEMINI_API_KEY", "GOOGLE_API_KEY")}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "src"), env.get("PYTHONPATH", "")])
    run_dir = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-c", _PLAIN_INSTALL, ",".join(OPTIONAL), "run", "Go to the bedroom",
                           "--max-steps", "3", "--out", str(run_dir), "--quiet"],
                          env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert json.loads((run_dir / "summary.json").read_text())["pilot"].startswith("oracle")
    assert "not written: the report needs" in proc.stdout and "pip install 'vln-pilot[report]'" in proc.stdout
    assert not (run_dir / "report.html").exists()
