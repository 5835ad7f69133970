"""`vln-pilot bench ... --estimate`: the calls, tokens, cached share and cost of a bench, counted offline before
anything flies (issue 27; docs/provider-scale.md).

Per row: the steps an episode takes, by a rule measured on the recorded real-model trials (`STEPS_PER_METRE` steps
per metre of the row's shortest path, at most the step limit, per stage for a mission); the prompt of each asked state
of the profile rendered as a model pilot sends it (system prompt, the row's context, the state prompt, a step text
with the context items of a step in the middle of the episode), its text tokens counted with o200k
(`pilots/tokens.py`: exact for OpenAI, an approximation for Gemini and Anthropic, whose tokenizers are not public),
its image at the provider's flat count. The prefix the providers cache (system, context, state prompt) is read from
the cache on every call but an episode's first and those that enter a new state (`STATE_CHANGE_SHARE`). Costs come
from `pilots/pricing.py`.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from vlnpilot.core.decision import Decision, PilotInput
from vlnpilot.core.fsm import ASKED_STATES, State, state_spec

# Measured on the recorded real-model trials (trials/, 165 episodes with a shortest path): the median steps per
# metre of the row's shortest path (14.2), pilot calls per step (1.03: re-asks and confirmations), o200k tokens of an
# answer (68, trials/after-plus and houses-plus), and the calls that enter a new state (110 of 547 in after-plus,
# bench/prompt_prefix.py).
STEPS_PER_METRE = 14.0
CALLS_PER_STEP = 1.03
OUTPUT_TOKENS = 70
STATE_CHANGE_SHARE = 0.2
# The providers' image tokens for one 640x480 front frame: OpenAI at detail low (the pilot's default), Anthropic
# (width x height / 750), Gemini (258 for an image up to 384 px a side, else per 768 px tile: 258 at media_resolution
# low, which the frame is sent near; the default medium is counted the same).
IMAGE_TOKENS = {"openai": 85, "anthropic": 410, "gemini": 258}
MIN_CACHED = 1024  # the shortest prefix any of the three caches
MODEL_PILOTS = tuple(IMAGE_TOKENS)


@dataclass(frozen=True)
class Estimate:
    """What one pilot of the bench would use, summed over its episodes."""

    pilot: str
    model: str | None
    episodes: int
    calls: int
    input_tokens: int
    cached_tokens: int
    output_tokens: int
    cost_usd: float
    priced: bool

    @property
    def cached_share(self) -> float:
        return self.cached_tokens / self.input_tokens if self.input_tokens else 0.0


@dataclass(frozen=True)
class RowCalls:
    """One row's episode: its calls, and a call's text tokens, and those of its cacheable prefix (mean over states)."""

    calls: int
    text_tokens: float
    prefix_tokens: float


def episode_steps(shortest_m: float, max_steps: int) -> int:
    return max(1, min(max_steps, math.ceil(STEPS_PER_METRE * shortest_m)))


def _step_text_inputs(context: str, max_steps: int, step: int, state: State) -> tuple[tuple[str, ...], str]:
    """The context lines and the in-state line of a step in the middle of an episode (memory full)."""
    from vlnpilot.core.commands import get_command
    from vlnpilot.prompting.context import PilotContext, context_preset

    tracker = PilotContext(context_preset(context), max_steps)
    answer = Decision(room="living_room", movement="A1", state=state.value,
                      description="The open door is ahead on the left, about two metres away; the way is clear, "
                                  "so move forward and keep it in view.")
    for k in range(1, step):
        tracker.update(k, state, answer, get_command("A1"), state)
    return tracker.lines(step, state), tracker.in_state()


def row_calls(row: Any, suite: Any, *, max_steps: int, profile: str, context: str) -> RowCalls:
    """The calls of one episode of `row`, and the o200k tokens of a call (text, cacheable prefix)."""
    from vlnpilot.pilots.tokens import encode
    from vlnpilot.prompting.render import build_prompt
    from vlnpilot.scene import load_scene
    from vlnpilot.tasks.mission import Mission, stage_shortest_paths
    from vlnpilot.tasks.task import shortest_path_length

    scene = load_scene(row.scene or suite.scene)
    pose = scene.spawn(row.spawn).pose
    task = row.task
    if isinstance(task, Mission):
        steps = sum(episode_steps(m, max_steps) for m in stage_shortest_paths(scene, pose, task))
    else:
        steps = episode_steps(shortest_path_length(scene, pose, task), max_steps)
    middle = max(1, steps // 2)
    texts, prefixes = [], []
    for state in (s for s in ASKED_STATES if state_spec(s, profile).answer_moves):
        lines, in_state = _step_text_inputs(context, max_steps, min(middle, 8), state)
        asked = PilotInput(image=np.zeros((480, 640, 3), np.uint8), query=row.query,
                           topological_map=scene.topological_map(), state=state, previous_movement="A1", step=middle,
                           profile=profile, context=lines, in_state=in_state, mission=row.mission)
        prompt = build_prompt(asked)
        prefix = sum(len(encode(t)) for t in (prompt.system, prompt.context, prompt.state_prompt))
        prefixes.append(prefix)
        texts.append(prefix + len(encode(prompt.step_text)))
    return RowCalls(math.ceil(steps * CALLS_PER_STEP), statistics.fmean(texts), statistics.fmean(prefixes))


def estimate_pilot(spec: str, rows: Sequence[tuple[RowCalls, int]]) -> Estimate:
    """One pilot over the rows (each with its repetitions)."""
    from vlnpilot.pilots import pricing
    from vlnpilot.pilots.base import parse_spec, pilot_options_class

    name, model = parse_spec(spec)
    episodes = sum(reps for _, reps in rows)
    if name not in MODEL_PILOTS:  # the oracle, a replay, a person: no provider is called
        return Estimate(spec, model, episodes, 0, 0, 0, 0, 0.0, True)
    model = model or pilot_options_class(name).default_model()
    calls = inp = cached = written = 0
    for rc, reps in rows:
        per_call = round(rc.text_tokens) + IMAGE_TOKENS[name]
        prefix = round(rc.prefix_tokens) if rc.prefix_tokens >= MIN_CACHED else 0
        if name == "openai" and prefix:
            prefix = MIN_CACHED + (prefix - MIN_CACHED) // 128 * 128  # reported in steps of 128
        served = round((rc.calls - 1) * (1 - STATE_CHANGE_SHARE))  # not the first, nor a call in a new state
        calls += rc.calls * reps
        inp += per_call * rc.calls * reps
        cached += prefix * served * reps
        if name == "anthropic":  # the breakpoints are written on every call the cache does not serve
            written += prefix * (rc.calls - served) * reps
    out = OUTPUT_TOKENS * calls
    cost = pricing.cost_usd(model, inp, cached, out, cache_write_tokens=written)
    return Estimate(spec, model, episodes, calls, inp, cached, out, cost.usd, cost.known)


def estimate_bench(suite: Any, pilots: Sequence[str], *, reps: int | None = None, max_steps: int | None = None,
                   profile: str | None = None, context: str = "plus") -> list[Estimate]:
    """The estimate of every pilot of a bench of `suite` (a loaded `Suite`), with the bench's overrides."""
    limit = max_steps or suite.max_steps
    per_row = [(row_calls(row, suite, max_steps=limit, profile=profile or suite.profile, context=context),
                reps or suite.repetitions) for row in suite.rows]
    return [estimate_pilot(spec, per_row) for spec in pilots]


def render_estimate(estimates: Sequence[Estimate], suite_name: str) -> Any:
    """A Rich table of the estimates."""
    from rich.table import Table

    from vlnpilot.pilots.pricing import PRICES_AS_OF

    table = Table(title=f"Estimate of bench {suite_name} (offline: o200k tokens; prices as of {PRICES_AS_OF}); "
                        "nothing flown", title_justify="left")
    for header in ("Pilot", "Model", "Episodes", "Calls", "Input tokens", "Cached", "Output tokens", "Cost (USD)"):
        table.add_column(header, justify="left" if header in ("Pilot", "Model") else "right", overflow="fold")
    for e in estimates:
        cost = f"{e.cost_usd:.2f}" if e.priced else "unpriced"
        table.add_row(e.pilot, e.model or "--", str(e.episodes), str(e.calls), f"{e.input_tokens:,}",
                      f"{e.cached_share:.1%}" if e.input_tokens else "--", f"{e.output_tokens:,}", cost)
    return table


def estimate_command(suite: str, pilots: str | Sequence[str], *, reps: int | None = None,
                     max_steps: int | None = None, profile: str | None = None, context: str = "plus",
                     console: Any = None) -> list[Estimate]:
    """Check the bench's settings as `bench` does (bad input: one line), then print and return the estimate."""
    from vlnpilot.bench.runner import parse_pilots
    from vlnpilot.bench.suite import load_suite
    from vlnpilot.core.errors import UnknownNameError
    from vlnpilot.core.fsm import PROFILES
    from vlnpilot.pilots.base import parse_spec, pilot_options_class
    from vlnpilot.prompting.context import context_preset

    specs = parse_pilots(pilots)
    for spec in specs:
        pilot_options_class(parse_spec(spec)[0])  # an unknown pilot: one line with the known ones
    if profile is not None and profile not in PROFILES:
        raise UnknownNameError("FSM profile", profile, PROFILES)
    context_preset(context)
    loaded = load_suite(suite)
    estimates = estimate_bench(loaded, specs, reps=reps, max_steps=max_steps, profile=profile, context=context)
    if console is None:
        from rich.console import Console

        console = Console()
    console.print(render_estimate(estimates, loaded.name))
    console.print(f"Steps per episode: {STEPS_PER_METRE:g} per metre of each row's shortest path, at most the step "
                  f"limit; {CALLS_PER_STEP:g} calls a step; {OUTPUT_TOKENS} output tokens a call; the cache serves "
                  f"the system prompt, context and state prompt but on an episode's first call and the "
                  f"{STATE_CHANGE_SHARE:.0%} that enter a new state (docs/provider-scale.md).", highlight=False)
    return estimates
