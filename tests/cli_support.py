"""`vln-pilot ARGS` run in-process as the entry point runs it: the helper every command-line test shares."""

from __future__ import annotations

import sys

import pytest

from vlnpilot import cli

# Unset for every in-process run, so that a key or a pilot server in the developer's shell never changes a test.
PROVIDER_ENV = ("OPENAI_API_KEY", "GEMINI_API_KEY", "GOOGLE_API_KEY", "VLN_PILOT_URL")


def run_main(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    """Call `cli.main()` with `args` as its argv: (exit code, stdout, stderr)."""
    monkeypatch.setattr(sys, "argv", ["vln-pilot", *args])
    for key in PROVIDER_ENV:
        monkeypatch.delenv(key, raising=False)
    with pytest.raises(SystemExit) as info:
        cli.main()
    out, err = capsys.readouterr()
    return int(info.value.code or 0), out, err
