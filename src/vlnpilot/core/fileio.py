"""The one atomic write: a hidden temporary file beside the target, then `os.replace`.

Readers (a files-pilot answerer, a report loader, a resumed bench) never see half a file, and a listing that
skips dot-files never sees the temporary one.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from vlnpilot.core.errors import ConfigError


def write_atomic(path: str | os.PathLike[str], data: bytes | str) -> Path:
    """Write `data` (text is UTF-8) to `path` through `.NAME.tmp` and os.replace; returns the path."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_bytes(data.encode("utf-8") if isinstance(data, str) else data)
    os.replace(tmp, path)
    return path


def check_not_directories(directory: Path, names: Iterable[str]) -> None:
    """ConfigError naming a file of `names` that is a directory in `directory`: checked before the work that
    would end by writing it (a rename cannot replace a directory)."""
    for name in names:
        if (directory / name).is_dir():
            raise ConfigError(f"{directory / name} is a directory where a file is written; remove or rename it")
