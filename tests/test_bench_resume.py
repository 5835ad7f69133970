"""A bench killed with SIGKILL in the middle, then resumed, ends with every key exactly once.

The bench runs in a subprocess with the local executor (worker processes). A plugin pilot (the oracle behind a
gate) lets the first two episodes through and holds every later one at its first decision, so the bench is
certainly still running, with episodes half-done, when it is killed after its second results line. The kill
leaves worker processes that must die with their parent and half-written run directories, and we add a torn
last line to results.jsonl as a kill in the middle of a write would. No sleeping: the test waits on inotify
events of the bench directory and on pidfds of the workers, each with a failure bound only.
"""

from __future__ import annotations

import ctypes
import json
import os
import select
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from vlnpilot.bench import BenchSettings, ResultsLog, run_bench

GATE_ENV = "GATED_ORACLE_DIR"
PLUGIN = f'''
import os
import threading
from vlnpilot.pilots.base import register_pilot
from vlnpilot.pilots.oracle import OraclePilot

OPEN = 2  # episodes let through; the later ones wait at their first decision until the bench is killed


def _ticket(gate):
    """This episode's place in the order episodes started across the worker processes (1, 2, ...)."""
    n = 1
    while True:
        try:
            fd = os.open(os.path.join(gate, f"ticket-{{n}}"), os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            n += 1
            continue
        os.write(fd, str(os.getpid()).encode())
        os.close(fd)
        return n


@register_pilot("gated-oracle")
class GatedOracle(OraclePilot):
    name = "gated-oracle"

    _place = None  # taken at the first decision: the bench also builds the pilot once in the parent

    def decide(self, pilot_input):
        gate = os.environ.get("{GATE_ENV}")  # unset in the resumed, in-process bench: no gate
        if self._place is None:
            self._place = _ticket(gate) if gate else 0
        if self._place > OPEN:
            threading.Event().wait()
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

_IN_MODIFY, _IN_CREATE = 0x2, 0x100
_libc = ctypes.CDLL(None, use_errno=True)


def _lines(path: Path) -> list[str]:
    return path.read_text().splitlines() if path.exists() else []


def _complete_lines(path: Path) -> int:
    return path.read_text().count("\n") if path.exists() else 0


def _watch(directory: Path) -> int:
    """An inotify descriptor that becomes readable when a file in `directory` is created or written."""
    fd = _libc.inotify_init1(os.O_NONBLOCK | os.O_CLOEXEC)
    if fd < 0 or _libc.inotify_add_watch(fd, str(directory).encode(), _IN_MODIFY | _IN_CREATE) < 0:
        raise OSError(ctypes.get_errno(), "inotify")
    return fd


def _wait_for_lines(watch: int, path: Path, n: int, proc: subprocess.Popen, stderr: Path, timeout: float) -> None:
    """Wake on each write into the bench directory, or the bench's exit, until `path` holds `n` whole lines.

    The timeout only turns a hang into a failure."""
    end, exited = time.monotonic() + timeout, os.pidfd_open(proc.pid)
    try:
        while _complete_lines(path) < n:
            ready = select.select([watch, exited], [], [], max(0.0, end - time.monotonic()))[0]
            assert exited not in ready, f"the bench ended before it could be killed: {stderr.read_text()[-2000:]}"
            assert ready, f"{path}: fewer than {n} lines after {timeout} s"
            os.read(watch, 65536)  # drain the events: the line count is what we look at
    finally:
        os.close(exited)


def _wait_exited(pid: int, timeout: float) -> bool:
    """Whether process `pid` has exited within `timeout` s, told by its pidfd (readable once it has exited)."""
    try:
        pidfd = os.pidfd_open(pid)
    except ProcessLookupError:
        return True
    try:
        return bool(select.select([pidfd], [], [], timeout)[0])
    finally:
        os.close(pidfd)


@pytest.mark.timeout(120)
def test_resume_after_sigkill_runs_every_key_exactly_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    (tmp_path / "gated_oracle_plugin.py").write_text(PLUGIN)
    (tmp_path / "killme.yaml").write_text(SUITE)
    out, gate = tmp_path / "bench", tmp_path / "gate"
    out.mkdir()
    gate.mkdir()
    settings = dict(suite=str(tmp_path / "killme.yaml"), pilots=("gated-oracle",), out=str(out), render=False,
                    workers=2, plugins=("gated_oracle_plugin",), progress=False)
    code = textwrap.dedent(f"""
        from vlnpilot.bench import BenchSettings, run_bench
        if __name__ == "__main__":
            run_bench(BenchSettings(**{settings!r}))
    """)
    script = tmp_path / "run.py"
    script.write_text(code)
    env = {**os.environ, GATE_ENV: str(gate),
           "PYTHONPATH": os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")])}
    results = out / "results.jsonl"
    watch, stderr = _watch(out), tmp_path / "bench.stderr"
    try:
        with stderr.open("w") as err:
            proc = subprocess.Popen([sys.executable, str(script)], env=env, stdout=subprocess.DEVNULL, stderr=err)
        _wait_for_lines(watch, results, 2, proc, stderr, timeout=90)
    finally:
        os.close(watch)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=10)
    done_before = [json.loads(x) for x in _lines(results)]
    assert len(done_before) == 2  # the gate holds every later episode

    # Its workers die with it (PR_SET_PDEATHSIG), the ones held at the gate included: none keeps writing.
    workers = {int(r["provenance"]["worker"].rsplit(":", 1)[1]) for r in done_before}
    # (a worker killed between creating its ticket and writing its pid into it leaves the ticket empty)
    workers |= {int(text) for t in gate.iterdir() if (text := t.read_text())}
    assert all(_wait_exited(pid, timeout=10) for pid in workers)

    with open(results, "a") as f:  # the parent was killed in the middle of writing a line
        f.write('{"key": "gated-oracle|mirror|3", "pilot": "gated-oracle", "row": "mir')

    monkeypatch.syspath_prepend(str(tmp_path))
    resumed = run_bench(BenchSettings(**{**settings, "executor": "inline", "resume": True}))
    assert resumed.failed == {} and resumed.finished == 6 and resumed.ran == 6 - len(done_before)

    lines = _lines(results)
    keys = [json.loads(x)["key"] for x in lines]  # every line parses: the torn one was cut off
    expected = {f"gated-oracle|{row}|{rep}" for row in ("to-bedroom", "mirror") for rep in (1, 2, 3)}
    assert sorted(keys) == sorted(expected)  # every key, none twice
    assert [r["key"] for r in done_before] == keys[: len(done_before)]  # earlier lines untouched
    for record in ResultsLog(results).read():
        summary = json.loads((out / record["run_dir"] / "summary.json").read_text())
        assert summary["status"] == "finished" and summary["result"] == record["result"]
        assert record["result"]["outcome"] == "success"
    assert "6/6 episodes finished" in (out / "table.md").read_text()
