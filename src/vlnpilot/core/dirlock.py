"""One writer per directory: an exclusive lock file held while a run writes its directory.

The lock is `fcntl.flock` on a dot-file inside the directory, so the system releases it when the process dies
(a killed run never leaves a stale lock). Locks are per open file, so a process remembers the directories it
holds: a second claim of the same directory by the same process is not a second writer.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TextIO

from vlnpilot.core.errors import ConfigError

RUN_LOCK = ".run.lock"
_HELD: dict[Path, TextIO] = {}  # directory (resolved) -> its open lock file, held by this process


def holds_lock(directory: Path) -> bool:
    return directory.resolve() in _HELD


def lock_directory(directory: Path) -> None:
    """Hold `directory`'s run lock until `release_directory` (or the process ends); ConfigError if another
    process holds it. Not POSIX (no fcntl): no lock."""
    key = directory.resolve()
    if key in _HELD:
        return
    try:
        import fcntl
    except ImportError:
        return
    fh = open(directory / RUN_LOCK, "a+", encoding="utf-8")  # noqa: SIM115 - held until released
    try:
        fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        fh.seek(0)
        holder = fh.read().strip() or "another process"
        fh.close()
        raise ConfigError(f"--out {directory} is being written by another run ({holder}); wait for it to end "
                          "or choose another --out") from None
    fh.truncate(0)
    fh.write(f"pid {os.getpid()}\n")
    fh.flush()
    _HELD[key] = fh


def release_directory(directory: Path) -> None:
    fh = _HELD.pop(directory.resolve(), None)
    if fh is not None:
        fh.close()
