"""A bench killed with SIGKILL in the middle, then resumed, ends with every key exactly once.

The bench runs in a subprocess with the local executor (worker processes); a plugin pilot (the oracle,
slowed down a little) keeps it running long enough to be killed after its first results. The kill leaves
worker processes that must die with their parent, maybe a half-written run directory, and we add a torn last
line to results.jsonl as a kill in the middle of a write would.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from vlnpilot.bench import BenchSettings, ResultsLog, run_bench

PLUGIN = '''
import time
from vlnpilot.pilots.base import register_pilot
from vlnpilot.pilots.oracle import OraclePilot

@register_pilot("slow-oracle")
class SlowOracle(OraclePilot):
    name = "slow-oracle"

    def decide(self, pilot_input):
        time.sleep(0.01)
        return super().decide(pilot_input)
'''

SUITE = """\
name: killme
repetitions: 3
max_steps: 30
rows:
  - {id: to-bedroom, spawn: living_room, query: Go to the bedroom}
  - {id: mirror, spawn: bedroom, query: Find the mirror in the bedroom}
"""


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(")")[-1].split()[0] != "Z"  # a zombie has exited
    except FileNotFoundError:
        return False


def _lines(path: Path) -> list[str]:
    return path.read_text().splitlines() if path.exists() else []


@pytest.mark.timeout(120)
def test_resume_after_sigkill_runs_every_key_exactly_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    (tmp_path / "slow_oracle_plugin.py").write_text(PLUGIN)
    (tmp_path / "killme.yaml").write_text(SUITE)
    out = tmp_path / "bench"
    settings = dict(suite=str(tmp_path / "killme.yaml"), pilots=("slow-oracle",), out=str(out), render=False,
                    workers=2, plugins=("slow_oracle_plugin",), progress=False)
    code = textwrap.dedent(f"""
        from vlnpilot.bench import BenchSettings, run_bench
        if __name__ == "__main__":
            run_bench(BenchSettings(**{settings!r}))
    """)
    script = tmp_path / "run.py"
    script.write_text(code)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, str(script)], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    results = out / "results.jsonl"
    deadline = time.monotonic() + 90
    while len(_lines(results)) < 2 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    assert proc.poll() is None, f"the bench ended before it could be killed: {proc.communicate()[1].decode()[-2000:]}"
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=10)
    done_before = [json.loads(x) for x in _lines(results)]
    assert 2 <= len(done_before) < 6

    # Its workers die with it (PR_SET_PDEATHSIG): none keeps writing into the bench directory.
    workers = {int(r["provenance"]["worker"].rsplit(":", 1)[1]) for r in done_before}
    t_end = time.monotonic() + 5
    while any(_alive(pid) for pid in workers) and time.monotonic() < t_end:
        time.sleep(0.05)
    assert not any(_alive(pid) for pid in workers)

    with open(results, "a") as f:  # the parent was killed in the middle of writing a line
        f.write('{"key": "slow-oracle|mirror|3", "pilot": "slow-oracle", "row": "mir')

    monkeypatch.syspath_prepend(str(tmp_path))
    resumed = run_bench(BenchSettings(**{**settings, "executor": "inline", "resume": True}))
    assert resumed.failed == {} and resumed.finished == 6 and resumed.ran == 6 - len(done_before)

    lines = _lines(results)
    keys = [json.loads(x)["key"] for x in lines]  # every line parses: the torn one was cut off
    expected = {f"slow-oracle|{row}|{rep}" for row in ("to-bedroom", "mirror") for rep in (1, 2, 3)}
    assert sorted(keys) == sorted(expected)  # every key, none twice
    assert [r["key"] for r in done_before] == keys[: len(done_before)]  # earlier lines untouched
    for record in ResultsLog(results).read():
        summary = json.loads((out / record["run_dir"] / "summary.json").read_text())
        assert summary["status"] == "finished" and summary["result"] == record["result"]
        assert record["result"]["outcome"] == "success"
    assert "6/6 episodes finished" in (out / "table.md").read_text()
