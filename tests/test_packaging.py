"""The package's own files (issue 21): one version (pyproject, read back from the metadata), `python -m
vlnpilot`, the licence and the citation."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tarfile
import tomllib
from importlib.metadata import version
from pathlib import Path

import pytest
import yaml

import vlnpilot

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]


def test_the_version_is_written_once_and_read_from_the_metadata() -> None:
    assert vlnpilot.__version__ == version("vln-pilot")
    written = re.compile(rf"['\"]{re.escape(PYPROJECT['version'])}['\"]")
    hits = [p for p in (ROOT / "src").rglob("*.py") if written.search(p.read_text())]
    assert hits == [], f"a version literal outside pyproject.toml: {hits}"


def test_python_m_vlnpilot_is_the_command_line() -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    proc = subprocess.run([sys.executable, "-m", "vlnpilot", "run", "x", "--scene", "nowhere"], env=env,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "unknown scene 'nowhere'" in proc.stderr


def test_the_licence_and_the_citation() -> None:
    assert PYPROJECT["license"] == "MIT" and "MIT License" in (ROOT / "LICENSE").read_text()
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    assert cff["cff-version"] == "1.2.0" and cff["license"] == "MIT" and cff["title"] == "VLN-Pilot"
    paper = cff["preferred-citation"]
    assert paper["title"] == "VLN-Pilot: Large Vision-Language Model as an Autonomous Indoor Drone Operator"
    assert [a["family-names"] for a in paper["authors"]] == ["Dominguez-Dager", "Suescun-Ferrandiz", "Escalona",
                                                           "Gomez-Donoso", "Cazorla"]


def test_the_sdist_ships_the_package_and_no_tests(tmp_path: Path) -> None:
    """setuptools adds tests/test*.py to an sdist by default: they shipped without conftest.py, tests/fakes/ or the
    docs, bench and trials files they read. MANIFEST.in keeps every test out (the sdist built from the files git
    tracks, with the build backend pyproject.toml names)."""
    setuptools = pytest.importorskip("setuptools")
    if int(setuptools.__version__.split(".")[0]) < 77:
        pytest.skip(f"setuptools {setuptools.__version__} predates pyproject's license string (77): make venv")
    tree, out = tmp_path / "tree", tmp_path / "out"
    tracked = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    for name in tracked.decode().split("\0"):
        if name and (ROOT / name).is_file():
            (tree / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, tree / name)
    code = f"from setuptools import build_meta; print(build_meta.build_sdist({str(out)!r}))"
    built = subprocess.run([sys.executable, "-c", code], cwd=tree, capture_output=True, text=True, check=True)
    with tarfile.open(out / built.stdout.strip().splitlines()[-1]) as sdist:
        names = [n.split("/", 1)[1] for n in sdist.getnames() if "/" in n]
    assert "src/vlnpilot/sim/gym_env.py" in names and "pyproject.toml" in names
    assert [n for n in names if n.startswith("tests")] == []
