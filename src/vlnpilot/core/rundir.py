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
import json
import platform
import shutil
import subprocess
import tempfile
import weakref
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from vlnpilot.core.errors import ConfigError
from vlnpilot.core.exits import shorten, undecodable
from vlnpilot.core.fileio import write_atomic

SUMMARY, EPISODE, FRAMES = "summary.json", "episode.jsonl", "frames"
# Everything a run and its report write: what `overwrite` removes, and what marks a directory as holding a run.
RUN_FILES = (SUMMARY, EPISODE, FRAMES, "report.html", "episode.mp4", "episode.gif")
MAX_RECORDED_TEXT = 4_000  # characters of one model reply kept in a record (a decision is ~300)


def cap_text(text: str | None, limit: int = MAX_RECORDED_TEXT) -> str | None:
    """`text` cut to `limit` characters with a marker naming the original length (None stays None)."""
    if text is None or len(text) <= limit:
        return text
    return f"{text[:limit]}... [cut: {len(text)} characters in all]"


def claim_run_dir(out: str | Path, *, overwrite: bool = False) -> Path:
    """A writable run directory that holds no other run: refused if it does, or cleared when `overwrite`."""
    path = check_writable(out)
    found = [name for name in RUN_FILES if (path / name).exists()]
    if found and not overwrite:
        raise ConfigError(f"--out {path} already holds a run ({', '.join(found)}); choose a new directory "
                          "or pass --overwrite to replace it")
    for name in found:
        target = path / name
        shutil.rmtree(target) if target.is_dir() else target.unlink()
    return path


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


@functools.cache
def git_sha() -> str:
    """The git commit of the installed source tree, with '+dirty' when it has local changes."""
    here = Path(__file__).resolve().parent
    try:
        sha = subprocess.run(["git", "rev-parse", "HEAD"], cwd=here, capture_output=True, text=True, timeout=5,
                             check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=here,
                               capture_output=True, text=True, timeout=5).stdout.strip()
        return sha + ("+dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


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
                Image.fromarray(img).save(self.run_dir / path, quality=self.jpeg_quality)
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
        _OPEN.discard(self)


_OPEN: weakref.WeakSet[Recorder] = weakref.WeakSet()  # the records this process has not closed yet


def close_open_records(status: str = "interrupted") -> int:
    """Mark every record still open in this process `status` (a bench worker told to stop, whose episodes run
    in threads that a signal cannot interrupt); returns how many."""
    records = list(_OPEN)
    for recorder in records:
        recorder.close(status)
    return len(records)


def load_run(run_dir: str | Path) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """Read a run directory back: (summary, steps). A truncated last line (killed mid-write) is skipped."""
    run_dir = Path(run_dir)
    summary = load_summary(run_dir)
    steps = []
    if (run_dir / EPISODE).is_file():
        for line in (run_dir / EPISODE).read_text().splitlines():
            try:
                steps.append(json.loads(line))
            except json.JSONDecodeError:
                break
    return summary, steps


TRIAL = "trial.json"  # beside a trial's summary.json: who flew it, when, how (see trials/README.md)


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
    return json.loads(path.read_text()) if path.is_file() else {}
