"""The bench runner: plan the episodes of a suite x pilots, run the missing ones, record, tabulate.

    OUT/bench.json          manifest: config (suite, pilots, settings) and its hash, sessions, provenance
    OUT/results.jsonl       one line per finished episode, written by this (parent) process only
    OUT/runs/<pilot>/<row>/<rep>/   the episode's recording (summary.json, episode.jsonl, frames/)
    OUT/table.md, table.csv, table.tex, summary.csv

An episode is keyed by (pilot SPEC, row id, repetition 1..N). `resume=True` runs only the keys missing from
results.jsonl and refuses when the config hash differs from the manifest's. A bench killed at any moment and
resumed ends with every key exactly once: lines are fsync'd as episodes end, a torn last line is cut off, a
half-written run directory is wiped before its episode reruns, and reading keeps one line per key.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import re
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from vlnpilot.bench.episode_job import EpisodeSpec, Event, import_plugins
from vlnpilot.bench.executors import BenchError, default_workers, executor_factory, make_executor
from vlnpilot.bench.manifest import FORMAT, MANIFEST, BenchManifest, bench_lock, read_manifest
from vlnpilot.bench.rate_column import RateColumn
from vlnpilot.bench.results import RESULTS, PilotSummary, ResultsLog, episode_key, record_key, summarize
from vlnpilot.bench.suite import Suite, episode_seed, load_suite, suite_from_dict
from vlnpilot.bench.tables import SUMMARY_CSV, TABLE_CSV, TABLE_MD, TABLE_TEX, render_tables
from vlnpilot.core.decision import traits_of
from vlnpilot.core.errors import ConfigError, UnknownNameError
from vlnpilot.core.exits import shorten
from vlnpilot.core.fileio import check_not_directories, write_atomic
from vlnpilot.core.fsm import PROFILES
from vlnpilot.core.limits import MAX_REPS, MAX_STEPS
from vlnpilot.core.rundir import check_not_a_run, check_writable, default_run_dir, git_sha, package_versions
from vlnpilot.pilots.ratelimit import share_budgets

_FAIL_FAST = 3  # abort when this many episodes failed before any finished: something systemic is wrong


@dataclass(frozen=True)
class BenchSettings:
    """One bench invocation. None means: the suite's value (reps, max_steps, seed, profile) or the default."""

    suite: str | Path = "paper"
    pilots: str | tuple[str, ...] = ("oracle",)  # SPECs, or 'oracle, openai:gpt-4.1': parsed once, by run_bench
    out: str | Path | None = None
    reps: int | None = None
    max_steps: int | None = None
    seed: int | None = None
    profile: str | None = None
    base_url: str | None = None  # given to every pilot that takes one (OpenAI-compatible servers, ...)
    pilot_options: dict[str, str] = field(default_factory=dict)  # --pilot-option KEY=VALUE, to the pilots taking KEY
    episode_options: dict[str, Any] = field(default_factory=dict)  # extra EpisodeConfig fields, e.g. a shield
    executor: str = "local"
    workers: int | None = None  # episodes in flight; default: the number of cores
    ray_address: str | None = None
    resume: bool = False
    render: bool = True  # False: no camera images (only for pilots that do not look), no frames recorded
    save_frames: bool = True
    sensors: str = "none"  # range sensors of every row's drone that names none itself (vlnpilot.core.ranging.SENSORS)
    camera: str = "ideal"  # what the front camera delivers (sim.camera_model.CAMERAS; docs/camera.md)
    randomize: int | None = None  # domain randomisation seed of every row whose suite and row name none
    plugins: tuple[str, ...] = ()  # modules to import in every worker (custom pilots registered by name)
    progress: bool = True
    rate_limit: str | None = None  # 'RPM,TPM' of every provider and model until its headers say (pilots/ratelimit.py)


@dataclass
class BenchReport:
    out: Path
    config_hash: str
    episodes: int  # planned
    finished: int  # in results.jsonl after this session
    ran: int  # finished in this session
    failed: dict[str, str]  # key -> error, episodes that did not finish in this session
    summaries: list[PilotSummary]
    tables: list[Path]
    wall_s: float
    executor: str = ""
    notes: list[str] = field(default_factory=list)

    @property
    def complete(self) -> bool:
        return self.finished == self.episodes


@dataclass(frozen=True)
class PilotEntry:
    spec: str
    model: str | None
    dir: str
    options: dict[str, Any]
    privileged: bool = False  # reads ground truth (the oracle): CPU-bound, no network wait


# -------------------------------------------------------------------------------------------------- planning
def parse_pilots(pilots: str | Sequence[str]) -> tuple[str, ...]:
    """'oracle, openai:gpt-4.1' or a list -> ('oracle', 'openai:gpt-4.1'); duplicates and blanks refused."""
    items = pilots.split(",") if isinstance(pilots, str) else list(pilots)
    specs = [str(p).strip() for p in items]
    if not any(specs):
        raise ConfigError("--pilots needs at least one pilot SPEC (name or name:model)")
    if not all(specs):
        raise ConfigError(f"--pilots {shorten(str(pilots))!r} has an empty SPEC; write SPECs separated by single "
                          "commas, e.g. oracle,openai:gpt-4.1")
    from vlnpilot.pilots.base import check_spec_syntax, parse_spec

    for spec in specs:
        check_spec_syntax(spec)
    keys = [parse_spec(p) for p in specs]  # a pilot's name in any case is the same pilot (the model's case counts)
    dupes = [p for i, p in enumerate(specs) if keys.index(keys[i]) != i]
    if dupes:
        raise ConfigError(f"pilot(s) given twice: {', '.join(dupes)} (names are not case-sensitive); give each "
                          "pilot once")
    return tuple(specs)


def _pilot_dir(spec: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "-", spec.replace(":", "-")).strip("-.") or "pilot"


def _accepts(spec: str, option: str) -> bool:
    """Whether the pilot's options class has an option (e.g. base_url); imports only that pilot's module."""
    from vlnpilot.pilots.base import parse_spec, pilot_options_class

    try:
        return pilot_options_class(parse_spec(spec)[0]).accepts(option)
    except UnknownNameError:
        return False  # make_pilot raises the error that lists the known pilots


def _command_line_options(specs: Sequence[str], pairs: Mapping[str, str]) -> dict[str, dict[str, Any]]:
    """Each pilot's share of the `--pilot-option` pairs (those its options class takes), coerced by that class.

    Like base_url, an option goes to every pilot that takes it; one that no pilot takes is refused.
    """
    from vlnpilot.pilots.base import parse_spec, pilot_options_class

    classes = {spec: pilot_options_class(parse_spec(spec)[0]) for spec in specs}
    valid = sorted({key for cls in classes.values() for key in cls.settable()})
    for key in pairs:
        if key not in valid:
            raise ConfigError(f"--pilot-option {key!r} is taken by none of the pilots {', '.join(specs)}; "
                              f"valid keys: {', '.join(valid) or '(none)'}")
    return {spec: cls.from_command_line(parse_spec(spec)[0], {k: v for k, v in pairs.items() if k in cls.settable()})
            for spec, cls in classes.items()}


def resolve_pilots(specs: Sequence[str], base_url: str | None,
                   pilot_options: Mapping[str, str] | None = None) -> list[PilotEntry]:
    """Build each pilot once in the parent: unknown names, bad models or missing keys fail before anything runs."""
    from vlnpilot.pilots.base import close_pilot, make_pilot

    given = _command_line_options(specs, pilot_options) if pilot_options else {}
    out, dirs = [], set()
    for spec in specs:
        options = dict(given.get(spec, {}))
        if base_url and _accepts(spec, "base_url"):
            options["base_url"] = base_url
        pilot = make_pilot(spec, **options)
        with contextlib.suppress(Exception):  # built only to check it; the workers build their own
            close_pilot(pilot)
        d = _pilot_dir(spec)
        if d in dirs:
            d += "-" + hashlib.sha256(spec.encode()).hexdigest()[:6]
        dirs.add(d)
        out.append(PilotEntry(spec, getattr(pilot, "model", None), d, options, traits_of(pilot).privileged))
    return out


def effective_suite(settings: BenchSettings) -> Suite:
    suite = load_suite(settings.suite)
    changes: dict[str, Any] = {}
    for name, attr, cap in (("reps", "repetitions", MAX_REPS), ("max_steps", "max_steps", MAX_STEPS)):
        v = getattr(settings, name)
        if v is not None:
            if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= cap:
                raise ConfigError(f"--{name.replace('_', '-')} must be an integer in 1..{cap}, got {v!r}")
            changes[attr] = v
    if settings.seed is not None:
        changes["seed"] = int(settings.seed)
    if settings.profile is not None:
        if settings.profile not in PROFILES:
            raise UnknownNameError("FSM profile", settings.profile, PROFILES)
        changes["profile"] = settings.profile
    return replace(suite, **changes)


def config_of(suite: Suite, pilots: Sequence[PilotEntry], settings: BenchSettings) -> dict[str, Any]:
    """What the results depend on; its hash guards --resume. (Workers and executor do not belong here.)"""
    return {
        "suite": suite.canonical(), "repetitions": suite.repetitions, "max_steps": suite.max_steps,
        "seed": suite.seed, "pilots": [{"spec": p.spec, "options": p.options} for p in pilots],
        "episode_options": dict(settings.episode_options), "render": settings.render,
        "save_frames": settings.save_frames and settings.render,
        **({"sensors": settings.sensors} if settings.sensors != "none" else {}),  # benches before it hash alike
        **({"camera": settings.camera} if settings.camera != "ideal" else {}),
        **({"randomize": settings.randomize} if settings.randomize is not None else {}),
    }


def config_hash(config: dict[str, Any]) -> str:
    blob = json.dumps(config, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def plan(suite: Suite, pilots: Sequence[PilotEntry], settings: BenchSettings, out: Path) -> list[EpisodeSpec]:
    """Every episode, repetition-major (all rows of repetition 1 first): partial results cover every row."""
    specs = []
    for rep in range(1, suite.repetitions + 1):
        for p in pilots:
            for row in suite.rows:
                rel = Path("runs") / p.dir / row.id / str(rep)
                specs.append(EpisodeSpec(
                    key=episode_key(p.spec, row.id, rep), pilot=p.spec, row=row.id, rep=rep,
                    seed=episode_seed(suite.seed, row.id, rep), scene=row.scene or suite.scene, spawn=row.spawn,
                    query=row.query, goal_room=row.goal_room, goal_target=row.goal_target, max_steps=suite.max_steps,
                    profile=suite.profile, run_dir=str((out / rel).resolve()), run_dir_rel=rel.as_posix(),
                    pilot_options=dict(p.options), episode_options=dict(settings.episode_options),
                    render=settings.render, save_frames=settings.save_frames, mission=row.mission, events=row.events,
                    spawn_jitter_m=suite.spawn_jitter_m, spawn_jitter_deg=suite.spawn_jitter_deg,
                    sensors=row.sensors or settings.sensors, camera=settings.camera,
                    randomize=next((r for r in (row.randomize, suite.randomize, settings.randomize) if r is not None),
                                   None),
                    rate_dir=str((out / RATE_DIR).resolve()), rate_limit=settings.rate_limit))
    return specs


# ------------------------------------------------------------------------------------------------- tables
def write_tables(out: str | Path) -> list[Path]:
    """(Re)write table.md, table.csv, table.tex and summary.csv of a bench directory from its results."""
    out = Path(out)
    manifest = read_manifest(out)
    if manifest is None:
        raise BenchError(f"{out} is not a bench directory: {MANIFEST} is missing")
    suite = suite_from_dict(manifest["suite"], source=str(out / MANIFEST))
    pilots = [p["spec"] for p in manifest["pilots"]]
    records = _in_key_order(r for r in ResultsLog(out / RESULTS).read() if r["pilot"] in pilots)
    paths = []
    for name, text in render_tables(suite, pilots, records, manifest.get("config_hash")).items():
        paths.append(write_atomic(out / name, text))
    return paths


def _in_key_order(records: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """Records by (pilot, row, repetition), not in the order episodes happened to finish: the sums behind the
    tables and summaries (floating point) then depend only on which episodes ran, not on the executor."""
    return sorted(records, key=record_key)


# ------------------------------------------------------------------------------------------------- running
Printer = Callable[[str], None]
RATE_DIR = "rate"  # the shared rate budgets of the bench's workers (pilots/ratelimit.py)
# The files a bench writes in its directory (the report's page too: report.html)
BENCH_OUTPUTS = (MANIFEST, RESULTS, TABLE_MD, TABLE_CSV, TABLE_TEX, SUMMARY_CSV, "report.html")


def run_bench(settings: BenchSettings, *, console: Any = None) -> BenchReport:
    """Run (or resume) a bench; returns its report. Raises BenchError/ConfigError before anything runs if the
    suite, the pilots or the output directory are not usable."""
    t0 = time.perf_counter()
    import_plugins(settings.plugins)
    suite = effective_suite(settings)
    pilots = resolve_pilots(parse_pilots(settings.pilots), settings.base_url, settings.pilot_options)
    executor_factory(settings.executor)  # a bad name is refused before anything runs
    check_episode_options(suite, settings.episode_options)
    _check_replayed_frames(plan(suite, pilots, settings, Path(".")))
    config = config_of(suite, pilots, settings)
    chash = config_hash(config)
    out = _bench_dir(settings, suite)
    check_not_a_run(out, "a bench")
    check_not_directories(out, BENCH_OUTPUTS)  # before anything flies: the tables are written after the episodes
    say: Printer = (lambda msg: console.print(msg, highlight=False)) if console is not None else (lambda msg: None)
    started = time.strftime("%Y-%m-%dT%H:%M:%S%z")
    with bench_lock(out):
        log = ResultsLog(out / RESULTS)
        manifest = BenchManifest.open(out, _fresh_manifest(suite, pilots, config, chash, started),
                                      resume=settings.resume, log=log)
        notes = manifest.start_session(_session(settings, suite, started))
        for n in notes:
            say(n)
        specs = plan(suite, pilots, settings, out)
        log.repair()
        done_keys = {episode_key(*record_key(r)) for r in log.read()} & {s.key for s in specs}
        todo = [s for s in specs if s.key not in done_keys]
        flight = _Flight(suite, pilots, len(specs), len(done_keys), out, chash, say)
        try:
            ran, failed, describe = _fly(settings, flight, todo, log, console)
        finally:
            log.close()
            share_budgets(None)  # an inline bench shared this process's budgets: the pilots after it have none
            tables = write_tables(out)
        records = _in_key_order(r for r in log.read() if episode_key(*record_key(r)) in {s.key for s in specs})
        summaries = [summarize(p.spec, [r for r in records if r["pilot"] == p.spec]) for p in pilots]
        return BenchReport(out=out, config_hash=chash, episodes=len(specs), finished=len(records), ran=ran,
                           failed=failed, summaries=summaries, tables=tables, wall_s=time.perf_counter() - t0,
                           executor=describe, notes=notes)


def _bench_dir(settings: BenchSettings, suite: Suite) -> Path:
    if settings.out is None and settings.resume:
        raise ConfigError("--resume needs --out: the bench directory to resume")
    return check_writable(settings.out or default_run_dir("runs", f"bench-{suite.name}"))


def _fresh_manifest(suite: Suite, pilots: Sequence[PilotEntry], config: dict[str, Any], chash: str,
                    created_at: str) -> dict[str, Any]:
    """The manifest of a new bench (its sessions are appended by `BenchManifest.start_session`)."""
    return {"format": FORMAT, "config_hash": chash, "config": config, "suite": suite.to_dict(),
            "suite_source": suite.source, "pilots": [{"spec": p.spec, "model": p.model, "dir": p.dir} for p in pilots],
            "episodes": len(suite.rows) * suite.repetitions * len(pilots),
            "created_at": created_at, "sessions": []}


def _session(settings: BenchSettings, suite: Suite, started_at: str) -> dict[str, Any]:
    """This session's provenance: when, which code and prompts, where it runs (`resume`: set by the manifest)."""
    return {"started_at": started_at, "git_sha": git_sha(),
            "prompt_hash": _prompt_hash(suite.profile), "executor": settings.executor,
            "workers": settings.workers or default_workers(), "resume": settings.resume,
            "versions": package_versions()}


@dataclass(frozen=True)
class _Flight:
    """What the console lines and the progress bar of one session say."""

    suite: Suite
    pilots: Sequence[PilotEntry]
    planned: int
    done: int
    out: Path
    chash: str
    say: Printer


def _fly(settings: BenchSettings, flight: _Flight, todo: Sequence[EpisodeSpec], log: ResultsLog,
         console: Any) -> tuple[int, dict[str, str], str]:
    """The executor's life: made only if something is left to fly, closed whatever happens."""
    suite = flight.suite
    if not todo:
        flight.say(f"bench {suite.name}: all {flight.planned} episodes are already in {flight.out / RESULTS}")
        return 0, {}, ""
    executor = make_executor(settings.executor, workers=settings.workers, ray_address=settings.ray_address,
                             plugins=settings.plugins)
    try:
        flight.say(f"bench [bold]{suite.name}[/bold]: {flight.planned} episodes ({len(suite.rows)} rows x "
                   f"{suite.repetitions} reps x {len(flight.pilots)} pilot(s)), {flight.done} already done; "
                   f"{executor.describe}; out {flight.out}")
        if suite.refused:  # a mission suite's instructions that must not fly (docs/missions.md)
            flight.say(f"{len(suite.refused)} instruction(s) refused before take-off, as the suite expects: "
                       + "; ".join(f"{r.id} ({r.refusal.split(';')[0]})" for r in suite.refused))
        if settings.workers is None and settings.executor == "local" and not all(p.privileged for p in flight.pilots):
            flight.say("hint: model pilots spend most of a step waiting for the model; --workers 16 keeps more "
                       "episodes in flight than there are cores")
        ran, failed = _drive(executor, todo, log, flight.chash, flight.planned, flight.done, settings.progress,
                             console, flight.out / RATE_DIR)
        return ran, failed, executor.describe
    finally:
        executor.close()


def check_episode_options(suite: Suite, options: dict[str, Any]) -> None:
    """Build one EpisodeConfig now, so that a bad shield or option is refused before anything runs."""
    from vlnpilot.episode.config import EpisodeConfig

    reserved = sorted({"max_steps", "profile", "seed"} & set(options))
    if reserved:
        raise ConfigError(f"episode option(s) {', '.join(reserved)} are set by the suite and the bench, not by "
                          "episode_options")
    try:
        EpisodeConfig(max_steps=suite.max_steps, profile=suite.profile, **options)
    except TypeError as exc:
        raise ConfigError(f"bad episode option: {exc}") from None


def _check_replayed_frames(specs: Sequence[EpisodeSpec]) -> None:
    """A replay flies the frames its recording saw (the same answers to other images are not the recording, as
    `vln-pilot run` says too): a recording flown with another camera or world is refused before anything runs."""
    from vlnpilot.pilots.replay import frames_differ
    from vlnpilot.sim.camera_model import camera_flown_with

    for spec in {(s.pilot, s.row): s for s in specs if s.pilot.startswith("replay:")}.values():
        differs = frames_differ(spec.pilot, camera_flown_with(spec.camera, None, spec.randomize), spec.row)
        if differs is not None:
            run_dir, then = differs
            saw = ", ".join(f"{key} {value}" for key, value in then.items()) or "the ideal camera"
            raise ConfigError(f"{run_dir} was flown with other frames ({saw}); bench it with --camera "
                              f"{then.get('camera', 'ideal')}, or pin `camera:` in the suite (a set of trials pins "
                              "what it was flown with)")


def _prompt_hash(profile: str) -> str:
    from vlnpilot.prompting.render import prompt_hash

    return prompt_hash(profile)


def _drive(executor: Any, todo: Sequence[EpisodeSpec], log: ResultsLog, chash: str, total: int, done: int,
           show_progress: bool, console: Any, rate_dir: Path | None = None) -> tuple[int, dict[str, str]]:
    """Consume the executor's events: append finished episodes to the log, show progress, collect failures."""
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    pending = {s.key for s in todo}
    failed: dict[str, str] = {}
    ran = ok = 0
    progress = Progress(TextColumn("[bold]bench"), BarColumn(), MofNCompleteColumn(),
                        TextColumn("ok {task.fields[ok]}  failed {task.fields[failed]}  in flight {task.fields[run]}"),
                        TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(), RateColumn(rate_dir),
                        console=console,
                        disable=not show_progress or console is None)
    in_flight = 0
    with progress:
        task = progress.add_task("bench", total=total, completed=done, ok=0, failed=0, run=0)
        events = executor.run(todo)
        try:
            for ev in events:
                if ev.key not in pending:  # an event for a key already settled: ignore (defensive)
                    continue
                if ev.kind == "started":
                    in_flight += 1
                    progress.update(task, run=in_flight)
                    continue
                in_flight = max(0, in_flight - 1)
                pending.discard(ev.key)
                if ev.kind == "finished":
                    _append(log, ev, chash)
                    ran += 1
                    ok += ev.record["result"]["outcome"] == "success"
                    progress.update(task, advance=1, ok=ok, run=in_flight)
                else:
                    failed[ev.key] = ev.error or "unknown error"
                    progress.update(task, failed=len(failed), run=in_flight)
                    if console is not None:
                        progress.console.print(f"[red]episode {ev.key} failed:[/red] {_first_line(ev.error)}",
                                               highlight=False)
                    if ran == 0 and len(failed) >= _FAIL_FAST:
                        raise BenchError(f"the first {len(failed)} episodes failed, stopping; the first error:\n"
                                         f"{next(iter(failed.values()))}")
        finally:
            close = getattr(events, "close", None)
            if callable(close):
                close()
    for key in sorted(pending):  # the executor stopped before reporting them
        failed.setdefault(key, "not run")
    return ran, failed


def _append(log: ResultsLog, ev: Event, chash: str) -> None:
    record = dict(ev.record or {})
    record["provenance"] = {**record.get("provenance", {}), "config_hash": chash,
                            "finished_at": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    log.append(record)


def _first_line(text: str | None) -> str:
    return (text or "").strip().splitlines()[0] if (text or "").strip() else "unknown error"
