"""Recordings: every run writes a directory that can be replayed and reported.

    RUN_DIR/summary.json    task, pilot, outcome, metrics, provenance (written first with status 'running';
                            rewritten at the end as 'finished', or 'interrupted' after Ctrl-C/SIGTERM)
    RUN_DIR/episode.jsonl   one JSON line per step, appended and flushed as the step ends
    RUN_DIR/frames/         front_NNN.jpg and rear_NNN.jpg (NNN = step; 000 is the start)

A run that is interrupted keeps every step written so far. A directory that already holds a run is refused
(never two episodes in one record) unless `overwrite` clears it first. Model replies are capped at
MAX_RECORDED_TEXT characters (with a marker and the original length). Nothing here ever sees an API key: only
decisions, poses and images are written.
"""

from __future__ import annotations

import functools
import io
import json
import platform
import shutil
import subprocess
import tempfile
import tomllib
import weakref
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from vlnpilot.core.dirlock import holds_lock, lock_directory, release_directory
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.exits import shorten, undecodable
from vlnpilot.core.fileio import write_atomic
from vlnpilot.core.steplog import OnDamage, read_steps

SUMMARY, EPISODE, FRAMES = "summary.json", "episode.jsonl", "frames"
ROBOT_EVENTS = "robot_events.jsonl"  # a real robot's link events, appended by its backend
TRIAL = "trial.json"  # beside a trial's summary.json: who flew it, when, how (see trials/README.md)
# Everything a run, its robot and its report write (and a trial's metadata): what `overwrite` removes, and what
# marks a directory as holding a run.
RUN_FILES = (SUMMARY, EPISODE, FRAMES, ROBOT_EVENTS, TRIAL, "report.html", "floorplan.png", "episode.mp4",
             "episode.gif")
# What only a run writes (a bench writes a report.html and a floorplan.png of its own): what marks a run directory.
RUN_MARKS = (SUMMARY, EPISODE, FRAMES, ROBOT_EVENTS, TRIAL, "episode.mp4", "episode.gif")
# What marks a bench directory (vlnpilot.bench.manifest, vlnpilot.bench.results): never a run's to write or clear.
BENCH_FILES = ("bench.json", "results.jsonl", ".bench.lock")
MAX_RECORDED_TEXT = 4_000  # characters of one model reply kept in a record (a decision is ~300)


def cap_text(text: str | None, limit: int = MAX_RECORDED_TEXT) -> str | None:
    """`text` cut to `limit` characters with a marker naming the original length (None stays None)."""
    if text is None or len(text) <= limit:
        return text
    return f"{text[:limit]}... [cut: {len(text)} characters in all]"


def claim_run_dir(out: str | Path, *, overwrite: bool = False) -> Path:
    """A writable run directory that holds no other run: refused if it does, or cleared when `overwrite`.

    The directory's run lock is taken first and held by this process (see vlnpilot.core.dirlock), so two runs
    given one --out never both write it: the second is refused."""
    path = check_writable(out)
    lock_directory(path)
    check_not_a_bench(path, "a run (even with --overwrite)")
    found = [name for name in RUN_FILES if (path / name).exists()]
    if found and not overwrite:
        raise ConfigError(f"--out {path} already holds a run ({', '.join(found)}); choose a new directory "
                          "or pass --overwrite to replace it")
    for name in found:
        target = path / name
        shutil.rmtree(target) if target.is_dir() else target.unlink()
    for stale in path.glob(".*.tmp"):  # a temporary file of an atomic write the old run was killed in
        stale.unlink()
    return path


def check_not_a_bench(path: Path, what: str) -> None:
    """ConfigError if `path` holds a bench: `what` (e.g. "a run") is never written into one."""
    found = [name for name in BENCH_FILES if (path / name).exists()]
    if found:
        raise ConfigError(f"--out {path} holds a bench ({', '.join(found)}); {what} is never written into a bench "
                          "directory: choose another --out")


def check_not_a_run(path: Path, what: str) -> None:
    """ConfigError if `path` holds a run: `what` (e.g. "a bench") is never written into one."""
    found = [name for name in RUN_MARKS if (path / name).exists()]
    if found:
        raise ConfigError(f"--out {path} holds a run ({', '.join(found)}); {what} is never written into a run "
                          "directory: choose another --out")


def check_writable(out: str | Path) -> Path:
    """Create `out` if needed and prove it is writable, or raise ConfigError naming the problem."""
    path = Path(out)
    bad = undecodable(str(path))
    if bad:
        raise ConfigError(f"--out {shorten(str(path))!r} is not valid UTF-8 ({bad}); a report could not name it")
    try:  # exists() too raises OSError, for a name longer than the file system takes
        if path.exists() and not path.is_dir():
            raise ConfigError(f"--out {path} exists and is not a directory")
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path, prefix=".write-test-"):
            pass
    except OSError as exc:
        raise ConfigError(f"cannot write to --out {shorten(str(path))}: {exc.strerror or exc}") from None
    return path


def default_run_dir(root: str | Path = "runs", label: str = "run") -> Path:
    stamp = datetime.now(UTC).strftime("%Y%m%d-%H%M%S-%f")[:-3]
    safe = "".join(ch if ch.isalnum() or ch in "-_" else "-" for ch in label.lower()).strip("-")[:40] or "run"
    return Path(root) / f"{stamp}-{safe}"


PACKAGE_DIR = Path(__file__).resolve().parents[1]  # src/vlnpilot in a checkout; site-packages/vlnpilot from a wheel


@functools.cache
def git_sha() -> str:
    """The git commit of the VLN-Pilot checkout this code runs from, with '+dirty' when it has local changes;
    'unknown' without one (a wheel, whatever repository its virtual environment sits in) or without git."""
    return checkout_sha(PACKAGE_DIR)


def checkout_sha(package_dir: Path) -> str:
    """`git_sha` for the package at `package_dir`."""
    try:
        top = Path(_git(package_dir, "rev-parse", "--show-toplevel"))
        if not is_vlnpilot_checkout(top, package_dir):  # a wheel in another repository: its HEAD is not ours
            return "unknown"
        dirty = _git(top, "status", "--porcelain", "--untracked-files=no")
        return _git(top, "rev-parse", "HEAD") + ("+dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def is_vlnpilot_checkout(top: Path, package_dir: Path) -> bool:
    """Whether the repository at `top` is a VLN-Pilot source tree and `package_dir` its own src/vlnpilot."""
    try:
        name = tomllib.loads((top / "pyproject.toml").read_text(encoding="utf-8"))["project"]["name"]
    except (OSError, ValueError, KeyError, TypeError):
        return False
    return name == "vln-pilot" and package_dir.resolve() == (top / "src" / "vlnpilot").resolve()


def _git(cwd: Path, *args: str) -> str:
    return subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True, timeout=5,
                          check=True).stdout.strip()


@functools.cache
def package_versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for pkg in ("vln-pilot", "mujoco", "numpy", "openai", "google-genai", "anthropic"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            pass
    return out


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    if hasattr(value, "model_dump"):
        return value.model_dump(mode="json")
    if hasattr(value, "value") and hasattr(value, "name"):  # enums
        return value.value
    return value


def write_json_atomic(path: Path, data: Any) -> None:
    """Write JSON through a temporary file and rename, so a reader never sees half a file."""
    write_atomic(path, json.dumps(_jsonable(data), indent=2, sort_keys=False) + "\n")


class Recorder:
    """Writes one run directory. Used by the controller as a collaborator, never from inside `env.step()`."""

    def __init__(self, run_dir: str | Path, *, jpeg_quality: int = 85, save_frames: bool = True,
                 overwrite: bool = False):
        self._owns_lock = not holds_lock(Path(run_dir))  # a caller that claimed the directory holds it on
        self.run_dir = claim_run_dir(run_dir, overwrite=overwrite)
        self._summary: dict[str, Any] = {"status": "running"}
        write_json_atomic(self.run_dir / SUMMARY, self._summary)  # first: never frames without a summary
        self.frames_dir = self.run_dir / FRAMES
        self.jpeg_quality = jpeg_quality
        self.save_frames = save_frames
        if save_frames:
            self.frames_dir.mkdir(exist_ok=True)
        self._episode = open(self.run_dir / EPISODE, "w", encoding="utf-8")  # noqa: SIM115 (closed in close())
        _OPEN.add(self)

    def frame_paths(self, step: int) -> dict[str, str]:
        return {"front": f"{FRAMES}/front_{step:03d}.jpg", "rear": f"{FRAMES}/rear_{step:03d}.jpg"}

    def save_observation(self, step: int, front: np.ndarray, rear: np.ndarray) -> dict[str, str]:
        """Save both frames of a step as JPEG; returns their paths relative to the run directory."""
        if not self.save_frames:
            return {}
        written = {}
        for key, img in (("front", front), ("rear", rear)):
            if img.size > 3:  # observations of a render-less simulator carry 1x1 placeholders
                path = self.frame_paths(step)[key]
                jpeg = io.BytesIO()
                Image.fromarray(img).save(jpeg, format="JPEG", quality=self.jpeg_quality)
                write_atomic(self.run_dir / path, jpeg.getvalue())  # a kill mid-write never leaves a torn frame
                written[key] = path
        return written

    def start(self, summary: dict[str, Any]) -> None:
        self._summary = {"status": "running", **summary}
        write_json_atomic(self.run_dir / SUMMARY, self._summary)

    def step(self, record: dict[str, Any]) -> None:
        decision = record.get("decision")
        if isinstance(decision, dict) and isinstance(decision.get("description"), str):
            decision = {**decision, "description": cap_text(decision["description"])}
        record = {**record, "decision": decision, "raw_text": cap_text(record.get("raw_text")),
                  "failures": [{**f, "raw_text": cap_text(f.get("raw_text"))} for f in record.get("failures") or []]}
        self._episode.write(json.dumps(_jsonable(record)) + "\n")
        self._episode.flush()

    def finish(self, summary: dict[str, Any]) -> None:
        self._summary = {**self._summary, **summary, "status": "finished"}
        write_json_atomic(self.run_dir / SUMMARY, self._summary)
        self.close()

    def close(self, status: str = "interrupted") -> None:
        """Close the record; an episode that did not finish is marked `status` in summary.json."""
        if self._summary.get("status") == "running":
            self._summary = {**self._summary, "status": status}
            write_json_atomic(self.run_dir / SUMMARY, self._summary)
        if not self._episode.closed:
            self._episode.close()
        if self._owns_lock:
            release_directory(self.run_dir)
        _OPEN.discard(self)


_OPEN: weakref.WeakSet[Recorder] = weakref.WeakSet()  # the records this process has not closed yet


def close_open_records(status: str = "interrupted") -> int:
    """Mark every record still open in this process `status` (a bench worker told to stop, whose episodes run
    in threads that a signal cannot interrupt); returns how many."""
    records = list(_OPEN)
    for recorder in records:
        recorder.close(status)
    return len(records)


def load_run(run_dir: str | Path, on_damage: OnDamage | None = None) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """Read a run directory back: (summary, steps). A truncated last line (killed mid-write) is skipped; another
    damaged line is a ConfigError naming it, or skipped and told to `on_damage` (see core/steplog.py)."""
    run_dir = Path(run_dir)
    summary = load_summary(run_dir)
    path = run_dir / EPISODE
    if path.is_dir():
        raise ConfigError(f"{path} is a directory, not a run's steps; restore the file or fly the run again")
    return summary, read_steps(path, on_damage) if path.is_file() else []


def load_summary(run_dir: str | Path) -> dict[str, Any]:
    """A run directory's summary alone (what it was flown with and how it ended), without its steps."""
    run_dir = Path(run_dir)
    if not (run_dir / SUMMARY).is_file():
        raise ConfigError(f"{run_dir} is not a run directory: {SUMMARY} is missing")
    try:
        summary = json.loads((run_dir / SUMMARY).read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{run_dir / SUMMARY} is not valid JSON ({exc}); restore it or fly the run again") from None
    if not isinstance(summary, dict):
        raise ConfigError(f"{run_dir / SUMMARY} holds a {type(summary).__name__}, not a run summary (a JSON object)")
    return summary


def load_trial(run_dir: str | Path) -> dict[str, Any]:
    """A trial's metadata (trial.json), or {} for a plain run."""
    path = Path(run_dir) / TRIAL
    if path.is_dir():
        raise ConfigError(f"{path} is a directory, not a trial's metadata; remove it or restore the file")
    if not path.is_file():
        return {}
    try:
        trial = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path} is not valid JSON ({exc}); restore it (trials/README.md)") from None
    if not isinstance(trial, dict):
        raise ConfigError(f"{path} holds a {type(trial).__name__}, not a trial's metadata (a JSON object)")
    return trial
