"""The one atomic write: the target appears whole, through a hidden temporary file that does not stay."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from vlnpilot.core.fileio import write_atomic


def test_write_atomic_publishes_through_a_hidden_temp_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[tuple[str, str, bytes]] = []
    real_replace = os.replace

    def spy(src: str, dst: str) -> None:
        seen.append((Path(src).name, Path(dst).name, Path(src).read_bytes()))
        assert not Path(dst).exists() or Path(dst).read_text(encoding="utf-8") == "old"  # never half-written
        real_replace(src, dst)

    monkeypatch.setattr("vlnpilot.core.fileio.os.replace", spy)
    (tmp_path / "a.json").write_text("old", encoding="utf-8")
    assert write_atomic(tmp_path / "a.json", "é\n") == tmp_path / "a.json"
    write_atomic(tmp_path / "b.bin", b"\x00\x01")
    assert seen == [(".a.json.tmp", "a.json", "é\n".encode()), (".b.bin.tmp", "b.bin", b"\x00\x01")]
    assert (tmp_path / "a.json").read_text(encoding="utf-8") == "é\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json", "b.bin"]
