"""A bench directory's own files: `bench.json` (the manifest) and the lock that makes one bench its writer.

The manifest holds what the results depend on (the config and its hash, which guards --resume), the
pilots and their run directories, the number of planned episodes, and one entry per session (when, git SHA,
prompt hash, executor, versions). It is written before any episode runs.
"""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vlnpilot.bench.executors import BenchError
from vlnpilot.bench.results import ResultsLog
from vlnpilot.core.rundir import write_json_atomic

MANIFEST = "bench.json"
LOCK = ".bench.lock"
FORMAT = "vln-pilot-bench/1"


def read_manifest(out: str | Path) -> dict[str, Any] | None:
    """A bench directory's manifest, None if it has none; an unreadable one is refused in one line."""
    path = Path(out) / MANIFEST
    if path.is_dir():
        raise BenchError(f"{path} is a directory, not a bench manifest; remove it or choose another --out")
    if not path.is_file():
        return None
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except (ValueError, UnicodeDecodeError) as exc:
        raise BenchError(f"{path} is not valid JSON ({exc}); not a bench directory") from None
    problem = _shape_problem(manifest)
    if problem:
        raise BenchError(f"{path} is not a bench manifest: {problem}; restore it or choose another --out")
    return manifest


def _shape_problem(manifest: Any) -> str | None:
    """What makes `manifest` unreadable as one `vln-pilot bench` writes (the fields its readers rely on)."""
    if not isinstance(manifest, dict):
        return f"it holds a JSON {type(manifest).__name__}, not an object"
    if not isinstance(manifest.get("suite"), dict):
        return "its 'suite' is missing or not an object"
    pilots = manifest.get("pilots")
    if not isinstance(pilots, list) or not all(isinstance(p, dict) and isinstance(p.get("spec"), str) for p in pilots):
        return "its 'pilots' is missing or not a list of objects with a 'spec'"
    if "config" in manifest and not isinstance(manifest["config"], dict):
        return "its 'config' is not an object"
    return None


@dataclass
class BenchManifest:
    out: Path
    data: dict[str, Any]
    resumed: bool  # the directory held this bench already (a --resume session)

    @classmethod
    def open(cls, out: Path, fresh: dict[str, Any], *, resume: bool, log: ResultsLog) -> BenchManifest:
        """The manifest this session continues (`resume`) or starts from `fresh`; refuses a directory that
        holds another bench, results without a manifest, or (on resume) a different config hash."""
        old = read_manifest(out)
        if old is not None and not resume:
            raise BenchError(f"{out} already holds a bench ({len(log.read())} of {old.get('episodes', '?')} episodes "
                             f"finished): pass --resume to continue it, or choose another --out")
        if old is None and (log.path.exists() or (out / "runs").exists()):
            raise BenchError(f"{out} holds results but no {MANIFEST}: it cannot be resumed; choose another --out")
        if old is not None and old.get("config_hash") != fresh["config_hash"]:
            raise BenchError(_hash_mismatch(out, old, fresh))
        return cls(out, old if old is not None else fresh, resumed=old is not None)

    def start_session(self, session: dict[str, Any]) -> list[str]:
        """Append this session and write the manifest; notes on what changed since the last session."""
        last = (self.data.get("sessions") or [{}])[-1]
        notes = []
        if self.resumed:
            for what, key in (("git SHA", "git_sha"), ("prompt hash", "prompt_hash")):
                old, new = last.get(key), session.get(key)
                if old and old != new:
                    notes.append(f"note: the {what} changed since the last session ({old} -> {new}); "
                                 "every results line records its own")
        session = {**session, "resume": self.resumed}  # whether a recorded bench was continued
        self.data["sessions"] = [*self.data.get("sessions", []), session]
        write_json_atomic(self.out / MANIFEST, self.data)
        return notes


def _hash_mismatch(out: Path, old: dict[str, Any], fresh: dict[str, Any]) -> str:
    diffs = _differences(old.get("config", {}), fresh["config"])
    return (f"cannot resume {out}: its config hash is {old.get('config_hash')}, this bench's is "
            f"{fresh['config_hash']}. The suite, the pilots or the settings differ from the recorded ones:\n  - "
            + "\n  - ".join(diffs or ["(unreadable recorded config)"])
            + "\nResume with the recorded settings, or start a new bench with another --out.")


def _differences(old: dict[str, Any], new: dict[str, Any]) -> list[str]:
    out = []
    for k in sorted(set(old) | set(new)):
        if old.get(k) == new.get(k):
            continue
        if k == "suite" and isinstance(old.get(k), dict) and isinstance(new.get(k), dict):
            out += [f"suite {sub}" for sub in sorted(set(old[k]) | set(new[k])) if old[k].get(sub) != new[k].get(sub)]
        else:
            out.append(f"{k}: recorded {json.dumps(old.get(k))}, now {json.dumps(new.get(k))}")
    return out


@contextlib.contextmanager
def bench_lock(out: Path) -> Iterator[None]:
    """Exclusive lock on the bench directory: two benches never append to one results file."""
    try:
        import fcntl
    except ImportError:  # not POSIX: no lock
        yield
        return
    fh = open(out / LOCK, "a+")  # noqa: SIM115 - closed below
    try:
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            fh.seek(0)
            holder = fh.read().strip() or "another process"
            raise BenchError(f"another bench is running in {out} ({holder}); wait for it or use another --out") \
                from None
        fh.truncate(0)
        fh.write(f"pid {os.getpid()}\n")
        fh.flush()
        yield
    finally:
        fh.close()
