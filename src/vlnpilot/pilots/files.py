"""The `files` pilot: a program, a person or an agent that cannot hold a pipe open flies through a directory.

    vln-pilot run "Go to the bedroom" --pilot files:/tmp/ep1

Each pilot call gets the next sequence number NNN (001, 002, ...; a re-ask is a new call with a new number, so an
answerer only ever answers the newest prompt). For call NNN the pilot writes, each file atomically:

    DIR/NNN.png          the front image
    DIR/NNN.prompt.md    the step's user text exactly as `build_prompt` renders it, then the answer instructions
                         (written after the image: its appearance means the call is complete)
    DIR/latest.txt       NNN, so that an answerer finds the newest prompt cheaply
    DIR/system.md        the system prompt, once per episode (the episode's first prompt says to read it first,
                         and every later prompt names it, so that a fresh pilot can answer any one call)

and then waits for DIR/NNN.answer.json: one JSON object with the five fields of the paper's output format.
The controller validates the answer like any model's and re-asks with the reason (the next prompt's
"Controller feedback" shows it). When the episode ends the pilot writes DIR/done.txt with the outcome line.

No answer within `timeout_s` ends the episode (a fatal PilotError, reason `timeout`): the answerer is gone,
and re-asking would only wait again. Everything recorded so far is kept. The pilot is not under the episode's
step deadline (it waits for people, not a network).

One directory holds one run: a DIR that already holds another run's files is refused (`overwrite=True` deletes
them). `bench` builds a pilot per episode, so with `files` its second episode is refused: fly rows with `run`.
"""

from __future__ import annotations

import contextlib
import io
import json
import re
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, ClassVar

from PIL import Image
from pydantic import Field

from vlnpilot.core.decision import FIELDS, Decision, PilotInput, Usage, parse_decision
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.fileio import write_atomic
from vlnpilot.pilots.base import BasePilot, PilotError, register_pilot
from vlnpilot.pilots.options import PilotOptions
from vlnpilot.prompting.render import build_prompt

# The files a run writes (NNN.png, NNN.prompt.md, NNN.answer.json, their temp files, and the fixed names):
# they decide whether DIR already holds another run, and they are the only files `overwrite` deletes.
_CALL_FILE_RE = re.compile(r"^\.?\d{3,}\.(png|prompt\.md|answer\.json)(\.tmp)?$")
_FIXED_FILES = ("latest.txt", "done.txt", "system.md")


def run_files(directory: Path) -> list[Path]:
    """The files of a file-pilot run in `directory` (sorted)."""
    return sorted(p for p in directory.iterdir() if _CALL_FILE_RE.match(p.name) or p.name in _FIXED_FILES)


def prepare_directory(directory: Path, overwrite: bool) -> None:
    """Create `directory`, check that it is writable and holds no other run's files (deleted with `overwrite`)."""
    try:
        directory.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=directory, prefix=".write-check-"):
            pass
        old = run_files(directory)
    except OSError as exc:
        raise ConfigError(f"the files pilot cannot write in {directory}: {exc.strerror or exc}; "
                          "give a writable directory (--pilot files:DIR)") from None
    if old and not overwrite:
        raise ConfigError(f"{directory} already holds the files of another file-pilot run ({old[0].name}, ...); "
                          "give a fresh directory (--pilot files:NEW_DIR) or delete them (overwrite=True in Python)")
    for path in old:
        path.unlink(missing_ok=True)


def _answer_instructions(call: str, first_of_episode: bool) -> str:
    lines = ["## Your answer", f"The front camera image of this step is `{call}.png` in this directory."]
    if first_of_episode:
        lines.append("This is the first prompt of the episode: read the system prompt in `system.md` first.")
    else:  # so that a fresh pilot per step (a stateless trial, docs/pilot-memory.md) finds it from any prompt
        lines.append("The system prompt, the same for the whole episode, is `system.md` in this directory.")
    lines.append(f"Write ONE JSON object with the fields {', '.join(FIELDS)} to `{call}.answer.json` in this "
                 "directory, atomically (write a temporary file, then rename it).")
    return "\n".join(lines) + "\n"


class FilesOptions(PilotOptions):
    """The options of the files pilot. `clock` and `sleep` are programmatic (injected by tests)."""

    programmatic: ClassVar[frozenset[str]] = frozenset({"clock", "sleep"})

    model: str | None = None  # the SPEC's DIR (files:DIR) when `directory` is not given
    directory: Path | None = None
    timeout_s: float = Field(600.0, gt=0)  # wait per call, then a fatal PilotError
    overwrite: bool = False  # delete another run's files in DIR instead of refusing
    poll_s: float = Field(0.2, gt=0)  # how often it looks for the answer
    grace_s: float = Field(2.0, gt=0)  # how long a present but unparsable answer may still be being written
    clock: Callable[[], float] = Field(time.monotonic, repr=False)
    sleep: Callable[[float], None] = Field(time.sleep, repr=False)


@register_pilot("files", options=FilesOptions)
class FilesPilot(BasePilot):
    """Writes each call's prompt and image into a directory and waits for the answer file.

    Options (`FilesOptions`): `directory` (or the SPEC `files:DIR`), `timeout_s` (wait per call, default 600 s;
    then a fatal PilotError), `overwrite` (delete another run's files in DIR instead of refusing), `poll_s` (how
    often it looks for the answer), `grace_s` (how long a present but unparsable answer file may still be being
    written), `clock` and `sleep` (injectable for tests).
    """

    name = "files"

    def __init__(self, model: str | None = None, **options: Any):
        o = FilesOptions.build(self.name, model=model, **options)
        source = o.directory if o.directory is not None else o.model
        if source is None or not str(source).strip():
            raise ConfigError("the files pilot needs a directory: use --pilot files:DIR (e.g. files:/tmp/ep1)")
        self.directory = Path(source).expanduser()
        self.model = "files"
        self.timeout_s, self.poll_s, self.grace_s = o.timeout_s, o.poll_s, o.grace_s
        self.clock, self.sleep = o.clock, o.sleep
        prepare_directory(self.directory, o.overwrite)
        self.calls = 0
        self._last_step: int | None = None
        self._finished = False

    def _new_episode(self, pilot_input: PilotInput) -> bool:
        """The first call, the first after `episode_finished`, or steps counting from the start again.

        A second call within one step (a re-ask, a confirmation) stays in the episode, with or without feedback.
        """
        return self._last_step is None or self._finished or pilot_input.step < self._last_step

    def decide(self, pilot_input: PilotInput) -> Decision:
        prompt = build_prompt(pilot_input)
        first = self._new_episode(pilot_input)
        self._last_step, self._finished = pilot_input.step, False
        self.calls += 1
        call = f"{self.calls:03d}"
        try:
            if first:
                (self.directory / "done.txt").unlink(missing_ok=True)
                write_atomic(self.directory / "system.md", prompt.system.encode("utf-8"))
            self._write_call(call, pilot_input, prompt.user_text(), first)
        except OSError as exc:  # DIR deleted or full mid-episode: nobody can answer, so end the episode
            raise PilotError(f"the files pilot cannot write call {call} in {self.directory}: {exc.strerror or exc}",
                             fatal=True, reason="files_unwritable") from None
        t0 = self.clock()
        text = self._wait_for_answer(self.directory / f"{call}.answer.json")
        latency = self.clock() - t0
        decision = parse_decision(text)  # DecisionError: the controller re-asks with the reason
        return decision.model_copy(update={"model": self.model, "usage": Usage(latency_s=round(latency, 4))})

    def plan(self, prompt: Any) -> tuple[str, Usage]:
        """The planning call before take-off (pilots/planning.py), as call NNN: DIR/NNN.prompt.md holds the
        planning rules, the instruction, the map and the answer's JSON schema (no image); the answer is
        DIR/NNN.answer.json: {"stages": [...], "avoid": [...], "refusal": null}."""
        self.calls += 1
        call = f"{self.calls:03d}"
        text = (f"# Plan before take-off\n\n{prompt.system.rstrip()}\n\n---\n\n{prompt.context.rstrip()}\n\n"
                f"{prompt.step_text.rstrip()}\n\n---\n\nWrite your answer to `{call}.answer.json`: one JSON object "
                f"with this schema:\n\n```json\n{json.dumps(prompt.schema, indent=2)}\n```\n")
        try:
            (self.directory / "done.txt").unlink(missing_ok=True)
            write_atomic(self.directory / f"{call}.prompt.md", text.encode("utf-8"))
            write_atomic(self.directory / "latest.txt", f"{call}\n".encode())
        except OSError as exc:
            raise PilotError(f"the files pilot cannot write call {call} in {self.directory}: {exc.strerror or exc}",
                             fatal=True, reason="files_unwritable") from None
        t0 = self.clock()
        answer = self._wait_for_answer(self.directory / f"{call}.answer.json")
        return answer, Usage(latency_s=round(self.clock() - t0, 4))

    def episode_finished(self, result: Any) -> None:
        """Called by run_episode at the end: done.txt tells the answerer that no prompt will follow."""
        line = f"{result.outcome} in {result.steps} steps: {result.reason}\n"
        self._finished = True
        with contextlib.suppress(OSError):  # DIR gone: the recording still holds the outcome
            write_atomic(self.directory / "done.txt", line.encode("utf-8"))

    def _write_call(self, call: str, pilot_input: PilotInput, user_text: str, first: bool) -> None:
        image = self.directory / f"{call}.png"
        png = io.BytesIO()
        Image.fromarray(pilot_input.image).save(png, format="PNG")
        write_atomic(image, png.getvalue())
        text = user_text.rstrip() + "\n\n---\n\n" + _answer_instructions(call, first)
        write_atomic(self.directory / f"{call}.prompt.md", text.encode("utf-8"))  # last: the call is complete
        write_atomic(self.directory / "latest.txt", f"{call}\n".encode())

    def _wait_for_answer(self, path: Path) -> str:
        """The answer file's text once it parses as JSON, or once `grace_s` has passed since it appeared."""
        start, seen = self.clock(), None
        while True:
            now = self.clock()
            text = _read(path)
            if text is not None:
                if _is_json(text):
                    return text
                seen = now if seen is None else seen
                if now - seen >= self.grace_s:  # not a write in progress: parse_decision says what is wrong
                    return text
            if now - start >= self.timeout_s:
                raise PilotError(f"no answer in {path} within {self.timeout_s:g} s (the files pilot's timeout_s)",
                                 fatal=True, reason="timeout")
            self.sleep(self.poll_s)


def _read(path: Path) -> str | None:
    try:
        return path.read_bytes().decode("utf-8", errors="replace")
    except FileNotFoundError:
        return None


def _is_json(text: str) -> bool:
    try:
        json.loads(text)
    except ValueError:
        return False
    return True
