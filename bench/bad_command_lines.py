"""Bad command lines: each must exit 2 with exactly one line on stderr and no traceback (issue 26).

A bare `vln-pilot` or `vln-pilot scene` prints the help (exit 2 too): that is not a bad line, so it is not here.
Every command and every option of `vln-pilot` gets lines with a bad value, a missing value, or a combination that
cannot work; none may start anything (fly, serve, write a run). The lines run in this process, one after the
other, as the entry point runs them (`cli.main()` with its own argv), each under an alarm. Prints each failing line
with what it got, then the count. `--smoke` runs one line in ten (the test suite runs that).

    PYTHONPATH=src .venv/bin/python bench/bad_command_lines.py [--smoke] [--verbose]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import signal
import sys
import tempfile
from pathlib import Path

Q = "Go to the bedroom"


def command_lines(tmp: Path) -> list[list[str]]:
    """The bad lines; `tmp` holds the files some of them name (a file, a corrupt run, a bad suite)."""
    a_file, corrupt, not_run, suite = tmp / "a-file", tmp / "corrupt", tmp / "not-a-run", tmp / "bad.yaml"
    t = str(tmp)
    run = ["run", Q]
    lines = [
        ["nosuchcommand"], ["--nosuchoption"], ["scene", "nosuch"], ["scene", "info", "extra"],
        # scene info / render
        ["scene", "info", "--scene", "nosuch"], ["scene", "info", "--scene"], ["scene", "info", "--json", "x"],
        ["scene", "info", "--scene", "house:abc"], ["scene", "info", "--scene", "house:1?rooms=99"],
        ["scene", "info", "--scene", "house:1?nosuch=1"], ["scene", "info", "--bogus"],
        ["scene", "render", "--spawn", "nosuch", "--out", f"{t}/r1"], ["scene", "render", "--width", "8"],
        ["scene", "render", "--width", "5000"], ["scene", "render", "--height", "0"],
        ["scene", "render", "--height", "x"], ["scene", "render", "--out", str(a_file)],
        ["scene", "render", "--scene", "nosuch"], ["scene", "render", "--spawn"],
        # run: the query
        ["run"], ["run", ""], ["run", "   "], ["run", "Go to the moon"], ["run", "Find the unicorn"],
        ["run", "x" * 10_000], ["run", "Go to the kitchen " * 160], ["run", "Go to the kitchen \udcff"],
        ["run", "Find the fridge in the bathroom"], ["run", Q, "extra"],
        # run: each option
        [*run, "--scene", "nosuch"], [*run, "--scene"], [*run, "--spawn", "nosuch"], [*run, "--spawn"],
        [*run, "--pilot", "nosuch"], [*run, "--pilot", "openai:"], [*run, "--pilot", ":gpt-4.1"],
        [*run, "--pilot", "replay:" + str(not_run)], [*run, "--pilot", "replay:" + str(corrupt)],
        [*run, "--pilot"], [*run, "--max-steps", "0"], [*run, "--max-steps", "-5"], [*run, "--max-steps", "x"],
        [*run, "--max-steps", "1" + "0" * 30], [*run, "--max-steps", "1.5"], [*run, "--seed", "abc"],
        [*run, "--seed", "1.5"], [*run, "--out", str(a_file)], [*run, "--out", f"{t}/o\udcff"],
        [*run, "--out", "/proc/nope/run"], [*run, "--base-url", "not a url"],
        [*run, "--base-url", "ftp://example.org/v1"], [*run, "--base-url", "http://127.0.0.1:99999/v1"],
        [*run, "--base-url", "http://:8000/v1"], [*run, "--base-url", "http://127.0.0.1:0/v1"],
        [*run, "--pilot-option", "nosuch=1"], [*run, "--pilot-option", "novalue"],
        [*run, "--pilot", "oracle", "--pilot-option", "timeout=abc"], [*run, "--profile", "turbo"],
        [*run, "--profile"], [*run, "--quiet", "x"], [*run, "--video", "x"], [*run, "--shield", "nosuch"],
        [*run, "--shield"], [*run, "--overlay", "nosuch"], [*run, "--context", "nosuch"],
        [*run, "--overwrite", "x"], [*run, "--robot", "nosuch"], [*run, "--robot", "tello", "--pilot", "oracle"],
        [*run, "--tello-host", "example.org"], [*run, "--robot", "tello", "--tello-host", "not a host!"],
        [*run, "--judge", "nosuch"], [*run, "--live-port", "70000"], [*run, "--live-port", "-1"],
        [*run, "--live-port", "x"], [*run, "--live", "--live-host", "0.0.0.0"], [*run, "--live-host"],
        [*run, "--live", "--live-host", "203.0.113.1", "--pilot", "oracle"],
        [*run, "--camera", "fisheye"], [*run, "--camera"], [*run, "--camera-lag-ms", "100"],
        [*run, "--camera", "tello", "--camera-lag-ms", "-1"], [*run, "--randomize", "-1"], [*run, "--randomize", "x"],
        [*run, "--robot", "tello", "--camera", "ideal"],
        # watch
        ["watch"], ["watch", str(not_run)], ["watch", str(corrupt)], ["watch", str(a_file)],
        ["watch", f"{t}/missing"], ["watch", str(corrupt), "--port", "70000"],
        ["watch", str(corrupt), "--port", "x"], ["watch", str(corrupt), "--host", "0.0.0.0"],
        # report
        ["report"], ["report", f"{t}/missing"], ["report", str(a_file)], ["report", str(not_run)],
        ["report", str(corrupt)], ["report", str(corrupt), "--video", "x"], ["report", t, "--bogus"],
        # bench
        ["bench", "--suite", "nosuch"], ["bench", "--suite", str(suite)], ["bench", "--suite", "houses:abc"],
        ["bench", "--suite"], ["bench", "--pilots", ""], ["bench", "--pilots", "oracle,,"],
        ["bench", "--pilots", ",oracle"], ["bench", "--pilots", "oracle,oracle"], ["bench", "--pilots", "nosuch"],
        ["bench", "--pilots", "openai:"], ["bench", "--reps", "0"], ["bench", "--reps", "x"],
        ["bench", "--max-steps", "0"], ["bench", "--max-steps", "1" + "0" * 30], ["bench", "--workers", "0"],
        ["bench", "--workers", "x"], ["bench", "--executor", "nosuch"], ["bench", "--executor"],
        ["bench", "--out", str(a_file)], ["bench", "--out", f"{t}/b\udcff"], ["bench", "--resume"],
        ["bench", "--resume", "--out", f"{t}/missing-bench"], ["bench", "--seed", "x"],
        ["bench", "--profile", "turbo"], ["bench", "--base-url", "ftp://example.org/v1"],
        ["bench", "--base-url", "http://127.0.0.1:99999/v1"], ["bench", "--pilot-option", "novalue"],
        ["bench", "--pilot-option", "nosuch=1"], ["bench", "--shield", "nosuch"], ["bench", "--overlay", "nosuch"],
        ["bench", "--context", "nosuch"], ["bench", "--report", "x"], ["bench", "--plugin", "no.such.module"],
        ["bench", "--plugin"], ["bench", "--ray-address"], ["bench", "--camera", "fisheye"],
        ["bench", "--randomize", "-3"],
        # tello-emulator
        ["tello-emulator", "--scene", "nosuch"], ["tello-emulator", "--spawn", "nosuch"],
        ["tello-emulator", "--host", "0.0.0.0"], ["tello-emulator", "--host", "example.org"],
        ["tello-emulator", "--port", "0"], ["tello-emulator", "--port", "70000"],
        ["tello-emulator", "--state-port", "x"], ["tello-emulator", "--video-port", "70000"],
        ["tello-emulator", "--battery", "101"], ["tello-emulator", "--battery", "-1"],
        ["tello-emulator", "--drop-replies", "1"], ["tello-emulator", "--drop-replies", "x"],
        ["tello-emulator", "--video-delay", "11"], ["tello-emulator", "--video-delay", "-1"],
        ["tello-emulator", "--camera", "fisheye"], ["tello-emulator", "--randomize", "x"],
        # serve
        ["serve", "--pilot", "nosuch"], ["serve", "--pilot", "oracle"], ["serve", "--pilot", "openai:"],
        ["serve", "--allow", "nosuch"], ["serve", "--pilot", "openai", "--allow", "oracle"],
        ["serve", "--allow", ":x"], ["serve", "--port", "0"], ["serve", "--port", "70000"],
        ["serve", "--port", "x"], ["serve", "--host", "0.0.0.0", "--pilot", "openai"],
        ["serve", "--host", "999.1.1.1", "--pilot", "openai"], ["serve", "--pilot"],
    ]
    return lines


def make_files(tmp: Path) -> None:
    (tmp / "a-file").write_text("not a directory\n")
    (tmp / "not-a-run").mkdir()
    corrupt = tmp / "corrupt"
    corrupt.mkdir()
    (corrupt / "summary.json").write_text('{"status": "fini')
    (corrupt / "episode.jsonl").write_text("")
    (tmp / "bad.yaml").write_text("name: broken\nrows:\n  - id: a\n    query: [unclosed\n")


class Alarm(Exception):
    pass


def run_line(args: list[str], timeout_s: int = 120) -> tuple[int | str, str]:
    """(exit code, stderr) of `vln-pilot ARGS` run in this process."""
    from vlnpilot import cli

    err = io.StringIO()
    previous = signal.signal(signal.SIGALRM, lambda *_: (_ for _ in ()).throw(Alarm()))
    signal.alarm(timeout_s)
    sys.argv = ["vln-pilot", *args]
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            cli.main()
        code: int | str = 0
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except Alarm:
        code = f"still running after {timeout_s} s"
    except BaseException as exc:  # noqa: BLE001 - an escaped exception is a failure, counted
        import traceback

        code = f"raised {type(exc).__name__}"
        err.write("".join(traceback.format_exception(exc)))
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    return code, err.getvalue()


def verdict(code: int | str, err: str) -> str | None:
    """None when the line was refused properly, else what was wrong."""
    lines = err.strip().splitlines()
    if code != 2:
        return f"exit {code}"
    if len(lines) != 1:
        return f"{len(lines)} lines on stderr"
    if "Traceback" in err:
        return "a traceback"
    return None


def check(smoke: bool = False, verbose: bool = False) -> tuple[int, int, list[str]]:
    """(passed, total, failures) over the bad lines (one in ten with `smoke`)."""
    env_keep = {k: os.environ.pop(k) for k in ("OPENAI_API_KEY", "GEMINI_API_KEY", "GOOGLE_API_KEY",
                                                "VLN_PILOT_TOKEN", "VLN_LIVE_TOKEN") if k in os.environ}
    os.environ["VLN_PILOT_URL"] = "http://127.0.0.1:9"  # never the internet; and no 'pilot server' line
    failures: list[str] = []
    try:
        with tempfile.TemporaryDirectory() as tmp_name:
            tmp = Path(tmp_name)
            make_files(tmp)
            cwd = os.getcwd()
            os.chdir(tmp)  # a line that wrongly starts writes under tmp/runs, not the caller's tree
            try:
                lines = command_lines(tmp)
                chosen = lines[::10] if smoke else lines
                for args in chosen:
                    code, err = run_line(args)
                    wrong = verdict(code, err)
                    shown = " ".join(a if len(a) < 60 else a[:40] + f"...({len(a)} chars)" for a in args)
                    if wrong:
                        failures.append(f"vln-pilot {shown!r}: {wrong}: {err.strip()[-300:]!r}")
                    if verbose:
                        print(f"{'FAIL' if wrong else 'ok  '} vln-pilot {shown}: {err.strip()[:150]}")
            finally:
                os.chdir(cwd)
    finally:
        os.environ.update(env_keep)
        os.environ.pop("VLN_PILOT_URL", None)
    return len(chosen) - len(failures), len(chosen), failures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--smoke", action="store_true", help="one line in ten")
    parser.add_argument("--verbose", action="store_true", help="every line and its stderr")
    args = parser.parse_args()
    passed, total, failures = check(args.smoke, args.verbose)
    for failure in failures:
        print("FAIL", failure)
    print(f"{passed} of {total} bad command lines exit 2 with one line on stderr")
    sys.exit(0 if passed == total else 1)


if __name__ == "__main__":
    main()
