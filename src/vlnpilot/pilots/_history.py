"""Conversation memory of the model pilots (the `history` option): the earlier turns of an episode as chat messages.

`history=none` (the default) sends one user message per step, as the paper's pilot does. `history=N` sends the last N
earlier turns first, as real messages: the user prompt of each (its text always; its image only for the last
`history_images` of them) and the model's own answer, then the current step's prompt. The messages keep the
providers' prefix caches hitting: the system prompt, then the episode's context (query and map) once, at the start
of the oldest turn, then the turns oldest first, each rendered only from itself and the turns before it. So the
next call's request begins with this call's whole request (as long as no image is dropped and the window is not
full: then it still begins with the system prompt). A turn's state prompt is left out when it is the one just
before it (consecutive steps in one state), as the image of a turn beyond `history_images` is.

The turns come from the pilot's own memory (`Conversation`), or from the caller (`PilotInput.history`: the pilot
server's client holds its conversation, since the server is stateless and shared).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Literal

import numpy as np

from vlnpilot.core.decision import EarlierTurn, PilotInput

if TYPE_CHECKING:
    from vlnpilot.prompting.render import Prompt

Role = Literal["user", "assistant"]


@dataclass(frozen=True)
class Part:
    """One block of a message: a text or a JPEG. `cache` marks the end of a prefix worth caching (Anthropic)."""

    text: str | None = None
    jpeg: bytes | None = None
    cache: bool = False


@dataclass(frozen=True)
class Message:
    role: Role
    parts: tuple[Part, ...]


def memory_label(turns: int, images: int) -> str:
    """'none', 'history=N' or 'history=N,images=K': what summary.json and the trials record."""
    if turns == 0:
        return "none"
    return f"history={turns}" + (f",images={images}" if images else "")


class Conversation:
    """A pilot's own memory of one episode: its accepted answers, one per step, with what it was asked."""

    def __init__(self, history: int | str, images: int):
        """`history`: 'none' or N, as the `history` option takes it; `images`: the `history_images` option."""
        self.turns, self.images = (0 if history == "none" else int(history)), images
        self.label = memory_label(self.turns, images)
        self._said: list[EarlierTurn] = []
        self._query: str | None = None

    def earlier(self, pilot_input: PilotInput) -> tuple[EarlierTurn, ...]:
        """The turns to send before this step's prompt: the caller's, else the last N remembered, images bounded."""
        if pilot_input.history is not None:
            return pilot_input.history
        if not self.turns:
            return ()
        if self._new_episode(pilot_input):
            self._said, self._query = [], pilot_input.query
        return bound_images([t for t in self._said if t.step < pilot_input.step][-self.turns:], self.images)

    def remember(self, pilot_input: PilotInput, answer: str | None) -> None:
        """An accepted answer: it replaces an earlier answer of the same step (a confirmation asks twice)."""
        if not self.turns or pilot_input.history is not None or answer is None:
            return
        if self._new_episode(pilot_input):
            self._said, self._query = [], pilot_input.query
        self._said = [t for t in self._said if t.step < pilot_input.step][-self.turns:]
        self._said.append(turn_of(pilot_input, answer))

    def _new_episode(self, pilot_input: PilotInput) -> bool:
        last = self._said[-1].step if self._said else None
        return pilot_input.query != self._query or pilot_input.step <= 1 or (last is not None
                                                                              and pilot_input.step < last)


def turn_of(pilot_input: PilotInput, answer: str) -> EarlierTurn:
    """What a step was asked and answered, to be sent again as an earlier turn."""
    return EarlierTurn(step=pilot_input.step, state=pilot_input.state, previous_movement=pilot_input.previous_movement,
                       answer=answer, image=pilot_input.image, feedback=pilot_input.feedback,
                       context=pilot_input.context, in_state=pilot_input.in_state)


def bound_images(turns: Sequence[EarlierTurn], images: int) -> tuple[EarlierTurn, ...]:
    """The turns with the image of all but the last `images` of them left out."""
    keep = len(turns) - images
    return tuple(t if i >= keep else replace(t, image=None) for i, t in enumerate(turns))


_NO_IMAGE = np.zeros((1, 1, 3), dtype=np.uint8)


def messages(pilot_input: PilotInput, earlier: Sequence[EarlierTurn], *, jpeg_quality: int,
             max_side: int | None) -> tuple[Prompt, list[Message]]:
    """(this step's Prompt, the messages after the system prompt): the earlier turns oldest first, then this step's."""
    from vlnpilot.prompting.render import build_prompt

    prompt = build_prompt(pilot_input, jpeg_quality=jpeg_quality, max_side=max_side)
    out: list[Message] = []
    previous_state_prompt: str | None = None
    for turn in earlier:
        asked = PilotInput(image=turn.image if turn.image is not None else _NO_IMAGE, query=pilot_input.query,
                           topological_map=pilot_input.topological_map, state=turn.state,
                           previous_movement=turn.previous_movement, step=turn.step, profile=pilot_input.profile,
                           feedback=turn.feedback, context=turn.context, in_state=turn.in_state)
        then = build_prompt(asked, jpeg_quality=jpeg_quality, max_side=max_side)
        jpeg = then.image_jpeg if turn.image is not None else None
        out.append(_user(then.context if not out else None, then.state_prompt, previous_state_prompt, jpeg,
                         then.step_text, turn.step, current=False))
        out.append(Message("assistant", (Part(text=turn.answer, cache=turn is earlier[-1]),)))
        previous_state_prompt = then.state_prompt
    out.append(_user(prompt.context if not out else None, prompt.state_prompt, previous_state_prompt,
                     prompt.image_jpeg, prompt.step_text, pilot_input.step, current=True))
    return prompt, out


def single(prompt: Prompt) -> list[Message]:
    """This step's message alone (no history): the context, the state prompt, the step text and the image."""
    if not prompt.image_jpeg:  # the planning call (pilots/planning.py): no image and no state prompt
        return [Message("user", tuple(Part(text=t) for t in (prompt.context, prompt.state_prompt, prompt.step_text)
                                      if t))]
    return [_user(prompt.context, prompt.state_prompt, None, prompt.image_jpeg, prompt.step_text, 0, current=True)]


def _user(context: str | None, state_prompt: str, previous_state_prompt: str | None, jpeg: bytes | None,
          step_text: str, step: int, *, current: bool) -> Message:
    """A step's user message: stable parts first (the cache marks end the context and the current state prompt), then
    the step's text, then its image."""
    parts: list[Part] = []
    if context is not None:
        parts.append(Part(text=context, cache=True))
    if state_prompt != previous_state_prompt:
        parts.append(Part(text=state_prompt, cache=current))
    parts.append(Part(text=step_text))
    # the image last: everything before it is text that the next call may begin with (issue 27)
    parts.append(Part(jpeg=jpeg) if jpeg is not None else
                 Part(text=f"(The front camera image of step {step} is not sent again.)"))
    return Message("user", tuple(parts))
