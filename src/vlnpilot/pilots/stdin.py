"""The `stdin` pilot: a person (the human baseline) or any external program flies the drone over text streams.

Each step it prints the rendered prompt (the system prompt once per episode, then the user text), writes the
front image to a JPEG file and prints its path, then reads one Decision as a JSON line from standard input.
The controller validates the answer exactly as it validates a model's, and re-asks with the reason.

    vln-pilot run "Go to the bedroom" --pilot stdin
    {"room": "living_room", "movement": "C2", "state": "Search Open Door", "description": "...",
     "door_position": "left"}          <- typed as ONE line
"""

from __future__ import annotations

import json
import shutil
import sys
import tempfile
import time
import weakref
from pathlib import Path
from typing import IO, Any, ClassVar

from pydantic import Field

from vlnpilot.core.decision import Decision, PilotInput, Usage, parse_decision
from vlnpilot.core.errors import ConfigError
from vlnpilot.pilots.base import BasePilot, PilotError, register_pilot
from vlnpilot.pilots.options import PilotOptions
from vlnpilot.prompting.render import build_prompt

RULE = "=" * 100


class StdinOptions(PilotOptions):
    """The options of the stdin pilot. `input` and `output` (text streams) are programmatic."""

    programmatic: ClassVar[frozenset[str]] = frozenset({"input", "output"})
    takes_model: ClassVar[bool] = False  # a person answers: no model to name

    model: str = "stdin"
    image_dir: Path | None = None  # where front images go; None: a fresh temporary directory
    input: Any = Field(None, repr=False)  # None: sys.stdin at call time
    output: Any = Field(None, repr=False)  # None: sys.stderr at call time
    jpeg_quality: int = Field(85, ge=1, le=100)
    show_system: bool = True  # print the system prompt at the start of each episode


@register_pilot("stdin", options=StdinOptions)
class StdinPilot(BasePilot):
    """Prompts on `output` (default standard error), reads one JSON line per answer from `input` (default stdin).

    Options (`StdinOptions`): `image_dir` (where front images go; default a fresh temporary directory),
    `input`/`output` streams (for tests and embedding), `jpeg_quality`, `show_system` (print the system prompt
    at the start of each episode; default True).
    """

    name = "stdin"

    def __init__(self, model: str | None = None, **options: Any):
        o = StdinOptions.build(self.name, model=model, **options)
        self.model = o.model
        self._input, self._output = o.input, o.output
        self.jpeg_quality = o.jpeg_quality
        self.show_system = o.show_system
        image_dir: str | Path | None = o.image_dir
        self._remove_images: weakref.finalize | None = None
        if image_dir is None:  # ours: removed when the pilot is closed, collected, or the process exits
            image_dir = tempfile.mkdtemp(prefix="vlnpilot-stdin-")
            self._remove_images = weakref.finalize(self, shutil.rmtree, image_dir, ignore_errors=True)
        self.image_dir = Path(image_dir)
        try:
            self.image_dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ConfigError(f"cannot create image_dir {self.image_dir}: {exc.strerror or exc}") from None
        self._last_step: int | None = None
        self._episode = 0
        self._attempt = 0

    def close(self) -> None:
        if self._remove_images is not None:
            self._remove_images()

    # Streams are looked up at call time, so that a redirected sys.stdin/sys.stderr (pytest, CliRunner) is used.
    @property
    def input(self) -> IO[str]:
        return self._input if self._input is not None else sys.stdin

    @property
    def output(self) -> IO[str]:
        return self._output if self._output is not None else sys.stderr

    def _reask(self, pilot_input: PilotInput) -> bool:
        """The controller asks again within the same step, with the rejection as feedback."""
        return pilot_input.step == self._last_step and bool(pilot_input.feedback)

    def _new_episode(self, pilot_input: PilotInput) -> bool:
        return self._last_step is None or (pilot_input.step <= self._last_step and not self._reask(pilot_input))

    def decide(self, pilot_input: PilotInput) -> Decision:
        prompt = build_prompt(pilot_input, jpeg_quality=self.jpeg_quality)
        if self._new_episode(pilot_input):
            self._episode += 1
            self._attempt = 0
            if self.show_system:
                self._print(f"{RULE}\nSYSTEM PROMPT\n{RULE}\n{prompt.system.rstrip()}\n")
        self._attempt = self._attempt + 1 if self._reask(pilot_input) else 0
        self._last_step = pilot_input.step

        suffix = f"_{self._attempt}" if self._attempt else ""
        image_path = self.image_dir / f"ep{self._episode:03d}_front_{pilot_input.step:03d}{suffix}.jpg"
        image_path.write_bytes(prompt.image_jpeg)
        reask = f" (re-ask {self._attempt})" if self._attempt else ""
        self._print(f"{RULE}\nSTEP {pilot_input.step} - {pilot_input.state.value}{reask}\n{RULE}\n"
                    f"{prompt.user_text().rstrip()}\n\n"
                    f"image: {image_path}\n"
                    "answer with ONE line of JSON: room, movement, state, description, door_position\n> ")

        t0 = time.perf_counter()
        line = self._read_line()
        latency = time.perf_counter() - t0
        decision = parse_decision(line)  # DecisionError: the controller re-asks with the reason
        return decision.model_copy(update={"model": self.model, "usage": Usage(latency_s=round(latency, 4))})

    def plan(self, prompt: Any) -> tuple[str, Usage]:
        """The planning call before take-off (pilots/planning.py): the planning rules, the instruction and the
        map, the answer's JSON schema; one JSON line back: {"stages": [...], "avoid": [...], "refusal": null}."""
        self._print(f"{RULE}\nPLAN (before take-off)\n{RULE}\n{prompt.system.rstrip()}\n\n{prompt.context.rstrip()}\n\n"
                    f"{prompt.step_text.rstrip()}\n\nJSON schema of the answer:\n{json.dumps(prompt.schema)}\n\n"
                    "answer with ONE line of JSON: stages, avoid, refusal\n> ")
        t0 = time.perf_counter()
        return self._read_line(), Usage(latency_s=round(time.perf_counter() - t0, 4))

    def _read_line(self) -> str:
        line = ""
        while not line.strip():  # blank lines (an Enter pressed twice) are not answers
            line = self.input.readline()
            if line == "":
                raise PilotError("stdin closed", fatal=True, reason="stdin_closed")
        return line.strip()

    def _print(self, text: str) -> None:
        out = self.output
        out.write(text if text.endswith(("\n", "> ")) else text + "\n")
        out.flush()
