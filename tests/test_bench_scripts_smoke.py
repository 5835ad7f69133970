"""Every script in bench/ still runs: its `--smoke` mode (a few steps or episodes) exits 0 (issue 27).

Nothing else runs the bench scripts, so an API they call can change under them unseen (bench_throughput.py read a
field the fake servers no longer had). Each runs as a user runs it, `python bench/NAME.py --smoke` in a fresh process
of this interpreter with this tree's `src` first on the path. The selected scripts start together, two at a time
(the machine has two cores); each test waits for its own.
"""

from __future__ import annotations

import os
import subprocess
import sys
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "bench"
HELPERS = {"machine"}  # imported by the scripts, not one itself
# Already run in-process, smoke mode included, by their own tests: running them again here adds only time.
ELSEWHERE = {
    "bad_command_lines": "its smoke lines run in tests/chaos/test_chaos_bad_command_lines.py",
    "link_loss": "its --smoke runs in tests/chaos/test_chaos_tello.py",
}
SCRIPTS = sorted(p.stem for p in BENCH.glob("*.py") if p.stem not in HELPERS)


def _run(name: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT / "src"),
                                                                       os.environ.get("PYTHONPATH")]))}
    return subprocess.run([sys.executable, str(BENCH / f"{name}.py"), "--smoke"], cwd=ROOT, env=env,
                          capture_output=True, text=True, check=False)


@pytest.fixture(scope="module")
def smoke_runs(request: pytest.FixtureRequest):
    """The smoke runs of the scripts this session selected, started at once, two at a time."""
    selected = [item.callspec.params["script"] for item in request.session.items
                if item.module is request.module and hasattr(item, "callspec")]
    with ThreadPoolExecutor(max_workers=2) as pool:
        yield {name: pool.submit(_run, name) for name in dict.fromkeys(selected) if name not in ELSEWHERE}


def test_every_script_in_bench_is_covered() -> None:
    assert SCRIPTS, "no bench scripts found"
    assert set(ELSEWHERE) <= set(SCRIPTS)


@pytest.mark.parametrize("script", SCRIPTS)
def test_the_smoke_mode_of_a_bench_script_exits_0(script: str,
                                                  smoke_runs: dict[str, Future[subprocess.CompletedProcess[str]]]
                                                  ) -> None:
    if script in ELSEWHERE:
        pytest.skip(ELSEWHERE[script])
    done = smoke_runs[script].result()
    tail = "\n".join((done.stdout + done.stderr).splitlines()[-25:])
    assert done.returncode == 0, f"bench/{script}.py --smoke exited {done.returncode}:\n{tail}"
    assert "Traceback" not in done.stderr, tail
