"""The `replay` pilot: answers with the decisions of a recorded run, step by step.

For regression tests of prompts and controller changes: record a run once (with any pilot), then fly the
same decisions again (`--pilot replay:RUN_DIR`) and compare trajectories and outcomes. Each step replays what
the controller saw that step: the rejected attempts first (re-parsed from their raw text where it was
recorded, else raised again as malformed answers or pilot errors with the recorded reason), then the accepted
decision. When the recording runs out the episode ends with a fatal PilotError.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from vlnpilot.core.cameras import check_camera_lag
from vlnpilot.core.decision import INVALID_ENUM, Decision, DecisionError, PilotInput, parse_decision
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.rundir import load_run, load_summary, load_trial
from vlnpilot.pilots.base import BasePilot, PilotError, register_pilot
from vlnpilot.pilots.options import PilotOptions
from vlnpilot.prompting.context import context_name
from vlnpilot.tasks.mission import PARSER
from vlnpilot.tasks.success import SuccessConfig, recorded_success

_MALFORMED = "malformed answer: "
_INVALID_PREFIXES = ("movement ", "next state ")  # validate_decision's reasons


class ReplayOptions(PilotOptions):
    """The options of the replay pilot; `row` is given by the bench (a set of trials holds one recording per row)."""

    model: str | None = None  # the SPEC's RUN_DIR (replay:RUN_DIR) when `run_dir` is not given
    run_dir: Path | None = None
    strict: bool = False  # end the episode as soon as the controller's state differs from the recorded one
    row: str | None = None  # the suite row whose recording to fly, in a set of trials


@register_pilot("replay", options=ReplayOptions)
class ReplayPilot(BasePilot):
    """Replays `run_dir`'s episode.jsonl (`make_pilot("replay:RUN_DIR")` or `make_pilot("replay", run_dir=...)`).

    `strict=True` also ends the episode (fatal PilotError) as soon as the controller's state differs from the
    recorded one: the replay has diverged from the recording.
    """

    name = "replay"

    def __init__(self, model: str | None = None, **options: Any):
        o = ReplayOptions.build(self.name, model=model, **options)
        source = o.run_dir if o.run_dir is not None else o.model
        if source is None:
            raise ConfigError("the replay pilot needs a recorded run: use --pilot replay:RUN_DIR "
                              "(or make_pilot('replay', run_dir=...))")
        strict, row = o.strict, o.row
        self.run_dir = _recording(Path(source), row)
        self.strict = strict
        steps: list[dict[str, Any]] = []
        self.summary: dict[str, Any] = {}
        self.trial: dict[str, Any] = {}
        self.is_trial_set = self.run_dir is None  # a set of trials without a row: the bench checks the spec this way
        if self.run_dir is None:
            self.run_dir = Path(source)
        else:
            self.summary, steps = load_run(self.run_dir)
            self.trial = load_trial(self.run_dir)
        self.steps: dict[int, dict[str, Any]] = {int(rec["step"]): rec for rec in steps if "step" in rec}
        self.model = f"replay:{self.run_dir}"
        self._step: int | None = None
        self._attempt = 0

    def episode_started(self, scene: Any, config: Any) -> None:
        """Refuse to replay on another scene or with other settings: the outcome could not be reproduced."""
        if self.is_trial_set:
            raise ConfigError(f"{self.run_dir} is a set of trials: replay it with its suite, e.g. vln-pilot bench "
                              f"--suite {self.run_dir}/suite.yaml --pilots replay:{self.run_dir}, or give one trial: "
                              f"replay:{self.run_dir}/ROW")
        flown = self.trial.get("scene") or self.summary.get("scene")
        if not isinstance(flown, str) or not flown:
            status = self.summary.get("status") or "no status"
            raise ConfigError(f"{self.run_dir} holds no episode to replay: its summary.json names no scene ({status}); "
                              "give a run directory that was flown")
        self._check_same_scene(flown, scene)
        # What decides the outcome of the same answers (a longer step limit only runs the recording out).
        now = {"profile": config.profile, "shield": config.shield, "context": context_name(config.context)}
        then = _flown_with(self.summary.get("config", {}))
        differ = [f"--{key.replace('_', '-')} {then[key]}" for key in now
                  if then[key] is not None and str(then[key]) != str(now[key])]
        if differ:
            raise ConfigError(f"{self.run_dir} was flown with other settings; replay it with {' '.join(differ)}")

    def _check_same_scene(self, flown: str, scene: Any) -> None:
        """Refuse another scene (say which to pass), or the same scene changed since (nothing to pass)."""
        mark = self.trial.get("scene_fingerprint") or (self.summary.get("provenance") or {}).get("scene_fingerprint")
        events = (self.summary.get("scenario") or {}).get("name")
        hint = f" --events {events} (its recorded scenario)" if events else ""
        if flown != scene.name:
            raise ConfigError(f"{self.run_dir} was flown in scene {flown!r} ({mark or 'no fingerprint'}); this episode "
                              f"flies {scene.name!r} ({scene.fingerprint()}): replay it with --scene {flown}{hint}")
        if mark is not None and mark != scene.fingerprint():
            fix = (f"replay it with{hint}" if events else
                   "the scene changed since (or the record was edited): it cannot be replayed, fly it again")
            raise ConfigError(f"{self.run_dir} was flown in scene {flown!r} with fingerprint {mark}; today's "
                              f"{scene.name!r} has fingerprint {scene.fingerprint()}: {fix}")

    @property
    def recorded_mover_clearance(self) -> str | None:
        """The mover shield's height rule the recording was flown with (`SafetyConfig.mover_clearance`): the episode
        flies the replay under it (episode/loop.py), so that the same answers meet the same shield. None for a set of
        trials; "column" for a recording made before the setting existed."""
        return recorded_mover_clearance(self.summary.get("config") or {}) if self.summary else None

    @property
    def recorded_success(self) -> SuccessConfig | None:
        """The success monitor the recording was judged by (`config.success`; the point monitor before footprints):
        the episode judges the replay by it too (episode/loop.py), so that the same end is the same outcome. None for
        a set of trials."""
        return recorded_success((self.summary.get("config") or {}).get("success")) if self.summary else None

    @property
    def last_step(self) -> int:
        return max(self.steps, default=0)

    def _attempts(self, rec: dict[str, Any]) -> list[dict[str, Any] | None]:
        """What the pilot answered at a recorded step, in call order: the rejected replies and the answer that was
        sent back for confirmation (each recorded with its call index), then None for the accepted decision."""
        calls: list[dict[str, Any]] = list(rec.get("failures") or [])
        if rec.get("confirmation"):
            calls.append({**rec["confirmation"], "confirm": True})
        out: list[dict[str, Any] | None] = [*sorted(calls, key=lambda c: int(c.get("attempt", 0)))]
        if rec.get("decision") is not None:
            out.append(None)
        return out

    def decide(self, pilot_input: PilotInput) -> Decision:
        step = pilot_input.step
        rec = self.steps.get(step)
        if rec is None:
            raise PilotError(f"recording exhausted at step {step} ({self.run_dir} has {self.last_step} steps)",
                             fatal=True, reason="replay_exhausted")
        if self.strict and rec.get("state") != pilot_input.state.value:
            raise PilotError(f"replay diverged at step {step}: recorded state {rec.get('state')!r}, "
                             f"now {pilot_input.state.value!r}", fatal=True, reason="replay_diverged")
        reask = step == self._step and bool(pilot_input.feedback)  # a re-ask always carries the rejection
        self._attempt = self._attempt + 1 if reask else 0
        self._step = step
        attempts = self._attempts(rec)
        if not attempts:
            raise PilotError(f"recording exhausted at step {step} (no answer recorded)", fatal=True,
                             reason="replay_exhausted")
        index = min(self._attempt, len(attempts) - 1)  # asked more often than recorded: repeat the last answer
        item = attempts[index]
        if item is None:
            return self._decision(rec)
        if item.get("confirm"):  # the final state the pilot declared first, before it was asked to confirm
            return Decision(**item["first"], raw_text=item.get("raw_text"), model=rec.get("model"))
        fatal = rec.get("executed") is None and index == len(attempts) - 1  # the step that ended the episode
        return self._failure(item, fatal)

    def _decision(self, rec: dict[str, Any]) -> Decision:
        return Decision(**rec["decision"], raw_text=rec.get("raw_text"), model=rec.get("model"))

    def _failure(self, failure: dict[str, Any], fatal: bool) -> Decision:
        reason = str(failure.get("reason") or "")
        raw = failure.get("raw_text")
        if raw is not None and not fatal:
            return parse_decision(raw)  # the model's rejected reply: the controller rejects it again
        if fatal:
            kind, _, message = reason.partition(": ")
            raise PilotError(message or reason, fatal=True, reason=kind if message else "pilot_error")
        if reason.startswith(_MALFORMED):
            raise DecisionError(reason[len(_MALFORMED):])
        if reason.startswith(_INVALID_PREFIXES):  # an invalid decision recorded without its raw text
            raise DecisionError(reason, code=INVALID_ENUM)
        kind, _, message = reason.partition(": ")
        raise PilotError(message or reason, fatal=False, reason=kind if message else "pilot_error")


def _recording(source: Path, row: str | None) -> Path | None:
    """A run directory, or for a set of trials (one recording per suite row: SET/ROW/) the row's (None: no row)."""
    trials = sorted(p.name for p in source.iterdir() if (p / "summary.json").is_file()) if source.is_dir() else []
    if (source / "summary.json").is_file() or not trials:
        return source  # load_run explains a missing recording
    if row is None:
        return None
    if row not in trials:
        raise ConfigError(f"{source} has no trial for row {row!r}; its trials: {', '.join(trials)}")
    return source / row


def recorded_settings(spec: str | None) -> dict[str, str]:
    """What a `replay:RUN_DIR` pilot's run was flown with (context, profile, shield, detail), so that `vln-pilot run`
    flies the replay as it was flown unless an option says otherwise; {} for another pilot or a set of trials."""
    header = _recorded_header(spec)
    if header is None:
        return {}
    config = header.get("config", {})
    settings = {**_flown_with(config), **camera_flown_with(config), "detail": config.get("detail")}  # what it saw
    return {key: str(value) for key, value in settings.items() if value is not None and value != ""}


def camera_flown_with(config: dict[str, Any]) -> dict[str, Any]:
    """How a recorded run's frames were simulated (`config.camera`, docs/camera.md): camera, its lag, the
    randomisation seed; {} for the ideal camera in the world as built (every recording before the camera model)."""
    camera = config.get("camera") or {}
    if not camera:
        return {}
    out: dict[str, Any] = {"camera": camera.get("model", "ideal")}
    if camera.get("lag_ms") is not None:
        out["camera_lag_ms"] = camera["lag_ms"]
    if camera.get("randomize") is not None:
        out["randomize"] = camera["randomize"]["seed"]
    return out


def check_replay_camera(spec: str | None, now: dict[str, Any]) -> None:
    """Refuse (one line) to replay a `replay:RUN_DIR` recording with other frames than it was flown with
    (`now`: `camera_flown_with` of this run's camera): the same answers to other images are not the recording.
    A lag asked of another camera than tello is refused too: in one line of its own, unless the recording was
    flown with a lag (a tello recording replayed with `--camera ideal` carries its recorded lag), where the
    replay's refusal names the settings to replay it with."""
    differs = frames_differ(spec, now)
    if differs is None or "camera_lag_ms" not in differs[1]:
        check_camera_lag(now.get("camera"), now.get("camera_lag_ms"))
    if differs is not None:
        run_dir, then = differs
        flags = " ".join(f"--{key.replace('_', '-')} {value}" for key, value in then.items()) or "--camera ideal"
        raise ConfigError(f"{run_dir} was flown with other frames; replay it with {flags}")


def frames_differ(spec: str | None, now: dict[str, Any], row: str | None = None) -> tuple[Path, dict[str, Any]] | None:
    """The recording a `replay:` spec flies (in a set of trials, `row`'s) and how its frames were simulated
    (`camera_flown_with`), where that differs from `now`; None where they agree or there is no recording."""
    source = Path(spec.removeprefix("replay:")) if spec and spec.startswith("replay:") else None
    run_dir = _recording(source, row) if source is not None and source.is_dir() else None
    if run_dir is None or not (run_dir / "summary.json").is_file():
        return None
    then = camera_flown_with(load_summary(run_dir).get("config", {}))
    if {k: str(v) for k, v in then.items()} == {k: str(v) for k, v in now.items()}:
        return None
    return run_dir, then


def recorded_scenario(spec: str | None) -> dict[str, Any] | None:
    """The scenario of events a `replay:RUN_DIR` pilot's run was flown with (its header's `scenario`), else None:
    `vln-pilot run` flies the replay in it, so that the same events fire at the same steps."""
    header = _recorded_header(spec)
    return header.get("scenario") if header is not None else None


def recorded_mission(spec: str | None, query: str) -> dict[str, Any] | None:
    """The mission a `replay:RUN_DIR` pilot's run flew, where a pilot planned it for this same `query` (its header's
    `mission`), else None: `vln-pilot run` flies the replay on that plan, as the parser may read the instruction
    otherwise (a replay answers no planning call)."""
    mission = (_recorded_header(spec) or {}).get("mission")
    if not mission or mission.get("query") != query or mission.get("source", PARSER) == PARSER:
        return None
    return {key: value for key, value in mission.items() if key != "planning"}  # the replay makes no planning call


def _recorded_header(spec: str | None) -> dict[str, Any] | None:
    """The summary of the one run a `replay:RUN_DIR` spec flies; None for another pilot or a set of trials."""
    if not spec or not spec.startswith("replay:"):
        return None
    run_dir = Path(spec.removeprefix("replay:"))
    return load_summary(run_dir) if (run_dir / "summary.json").is_file() else None


def recorded_mover_clearance(config: dict[str, Any]) -> str:
    """A recorded config's `safety.mover_clearance`; "column" if absent (every run before the 3-D rule)."""
    return str((config.get("safety") or {}).get("mover_clearance", "column"))


def _flown_with(config: dict[str, Any]) -> dict[str, Any]:
    """The settings of a recorded run's config that decide its outcome: profile, shield, context (None if unknown)."""
    context = (config.get("context") or {}).get("preset", "paper")  # recordings before contexts: paper
    return {"profile": config.get("profile"), "shield": config.get("shield"), "context": context}
