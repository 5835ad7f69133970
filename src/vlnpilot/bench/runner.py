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
import os
import re
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from vlnpilot.bench.executors import (
    BenchError,
    EpisodeSpec,
    Event,
    default_workers,
    import_plugins,
    make_executor,
)
from vlnpilot.bench.results import RESULTS, PilotSummary, ResultsLog, episode_key, record_key, summarize
from vlnpilot.bench.suite import Suite, episode_seed, load_suite, suite_from_dict
from vlnpilot.bench.tables import render_tables
from vlnpilot.errors import ConfigError, UnknownNameError
from vlnpilot.fileio import write_atomic
from vlnpilot.fsm import PROFILES
from vlnpilot.record import check_writable, default_run_dir, git_sha, package_versions, write_json_atomic

MANIFEST = "bench.json"
LOCK = ".bench.lock"
FORMAT = "vln-pilot-bench/1"
_FAIL_FAST = 3  # abort when this many episodes failed before any finished: something systemic is wrong


@dataclass(frozen=True)
class BenchSettings:
    """One bench invocation. None means: the suite's value (reps, max_steps, seed, profile) or the default."""

    suite: str | Path = "paper"
    pilots: tuple[str, ...] = ("oracle",)
    out: str | Path | None = None
    reps: int | None = None
    max_steps: int | None = None
    seed: int | None = None
    profile: str | None = None
    base_url: str | None = None  # given to every pilot that takes one (OpenAI-compatible servers, ...)
    episode_options: dict[str, Any] = field(default_factory=dict)  # extra EpisodeConfig fields, e.g. a shield
    executor: str = "local"
    workers: int | None = None  # episodes in flight; default: the number of cores
    ray_address: str | None = None
    resume: bool = False
    render: bool = True  # False: no camera images (only for pilots that do not look), no frames recorded
    save_frames: bool = True
    plugins: tuple[str, ...] = ()  # modules to import in every worker (custom pilots registered by name)
    progress: bool = True


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
    specs = [str(p).strip() for p in items if str(p).strip()]
    if not specs:
        raise ConfigError("--pilots needs at least one pilot SPEC (name or name:model)")
    dupes = sorted({p for p in specs if specs.count(p) > 1})
    if dupes:
        raise ConfigError(f"pilot(s) given twice: {', '.join(dupes)}")
    return tuple(specs)


def _pilot_dir(spec: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "-", spec.replace(":", "-")).strip("-.") or "pilot"


def _accepts(spec: str, option: str) -> bool:
    """Whether the pilot's factory takes a keyword option (e.g. base_url); imports only that pilot's module."""
    import inspect

    from vlnpilot.errors import UnknownNameError
    from vlnpilot.pilots.base import parse_spec, pilot_factory

    try:
        factory = pilot_factory(parse_spec(spec)[0])
    except UnknownNameError:
        return False  # make_pilot raises the error that lists the known pilots
    try:
        params = inspect.signature(factory).parameters
    except (TypeError, ValueError):
        return False
    return option in params


def resolve_pilots(specs: Sequence[str], base_url: str | None) -> list[PilotEntry]:
    """Build each pilot once in the parent: unknown names, bad models or missing keys fail before anything runs."""
    from vlnpilot.pilots.base import make_pilot

    out, dirs = [], set()
    for spec in specs:
        options = {"base_url": base_url} if base_url and _accepts(spec, "base_url") else {}
        pilot = make_pilot(spec, **options)
        close = getattr(pilot, "close", None)
        if callable(close):
            with contextlib.suppress(Exception):
                close()
        d = _pilot_dir(spec)
        if d in dirs:
            d += "-" + hashlib.sha256(spec.encode()).hexdigest()[:6]
        dirs.add(d)
        out.append(PilotEntry(spec, getattr(pilot, "model", None), d, options, bool(getattr(pilot, "privileged",
                                                                                             False))))
    return out


def effective_suite(settings: BenchSettings) -> Suite:
    suite = load_suite(settings.suite)
    changes: dict[str, Any] = {}
    for name, attr in (("reps", "repetitions"), ("max_steps", "max_steps")):
        v = getattr(settings, name)
        if v is not None:
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ConfigError(f"--{name.replace('_', '-')} must be a positive integer, got {v!r}")
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
                    render=settings.render, save_frames=settings.save_frames,
                    spawn_jitter_m=suite.spawn_jitter_m, spawn_jitter_deg=suite.spawn_jitter_deg))
    return specs


# ------------------------------------------------------------------------------------------ manifest, lock
def read_manifest(out: str | Path) -> dict[str, Any] | None:
    path = Path(out) / MANIFEST
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text())
    except ValueError as exc:
        raise BenchError(f"{path} is not valid JSON ({exc}); not a bench directory") from None


def _differences(old: dict[str, Any], new: dict[str, Any]) -> list[str]:
    out = []
    for k in sorted(set(old) | set(new)):
        if old.get(k) == new.get(k):
            continue
        if k == "suite" and isinstance(old.get(k), dict) and isinstance(new.get(k), dict):
            out += [f"suite {sub}" for sub in sorted(set(old[k]) | set(new[k])) if old[k].get(sub) != new[k].get(sub)]
        else:
            out.append(f"{k}: recorded {json.dumps(old.get(k))}, now {json.dumps(new.get(k))}")
    return out


@contextlib.contextmanager
def _bench_lock(out: Path) -> Iterator[None]:
    """Exclusive lock on the bench directory: two benches never append to one results file."""
    try:
        import fcntl
    except ImportError:  # not POSIX: no lock
        yield
        return
    fh = open(out / LOCK, "a+")  # noqa: SIM115 - closed below
    try:
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            fh.seek(0)
            holder = fh.read().strip() or "another process"
            raise BenchError(f"another bench is running in {out} ({holder}); wait for it or use another --out") \
                from None
        fh.truncate(0)
        fh.write(f"pid {os.getpid()}\n")
        fh.flush()
        yield
    finally:
        fh.close()


def write_tables(out: str | Path) -> list[Path]:
    """(Re)write table.md, table.csv, table.tex and summary.csv of a bench directory from its results."""
    out = Path(out)
    manifest = read_manifest(out)
    if manifest is None:
        raise BenchError(f"{out} is not a bench directory: {MANIFEST} is missing")
    suite = suite_from_dict(manifest["suite"], source=str(out / MANIFEST))
    pilots = [p["spec"] for p in manifest["pilots"]]
    records = [r for r in ResultsLog(out / RESULTS).read() if r["pilot"] in pilots]
    paths = []
    for name, text in render_tables(suite, pilots, records, manifest.get("config_hash")).items():
        paths.append(write_atomic(out / name, text))
    return paths


# ------------------------------------------------------------------------------------------------- running
Printer = Callable[[str], None]


def run_bench(settings: BenchSettings, *, console: Any = None) -> BenchReport:
    """Run (or resume) a bench; returns its report. Raises BenchError/ConfigError before anything runs if the
    suite, the pilots or the output directory are not usable."""
    t0 = time.perf_counter()
    import_plugins(settings.plugins)
    suite = effective_suite(settings)
    pilots = resolve_pilots(parse_pilots(settings.pilots), settings.base_url)
    if settings.executor not in ("local", "ray", "inline"):
        make_executor(settings.executor)  # raises the error that lists the executors
    _check_episode_options(suite, settings.episode_options)
    config = config_of(suite, pilots, settings)
    chash = config_hash(config)
    if settings.out is None and settings.resume:
        raise ConfigError("--resume needs --out: the bench directory to resume")
    out = check_writable(settings.out or default_run_dir("runs", f"bench-{suite.name}"))
    say: Printer = (lambda msg: console.print(msg, highlight=False)) if console is not None else (lambda msg: None)

    with _bench_lock(out):
        manifest = read_manifest(out)
        log = ResultsLog(out / RESULTS)
        notes: list[str] = []
        if manifest is not None and not settings.resume:
            done = len(log.read())
            raise BenchError(f"{out} already holds a bench ({done} of {manifest.get('episodes', '?')} episodes "
                             f"finished): pass --resume to continue it, or choose another --out")
        if manifest is None and (log.path.exists() or (out / "runs").exists()):
            raise BenchError(f"{out} holds results but no {MANIFEST}: it cannot be resumed; choose another --out")
        if manifest is not None:
            if manifest.get("config_hash") != chash:
                diffs = _differences(manifest.get("config", {}), config)
                raise BenchError(
                    f"cannot resume {out}: its config hash is {manifest.get('config_hash')}, this bench's is {chash}. "
                    "The suite, the pilots or the settings differ from the recorded ones:\n  - "
                    + "\n  - ".join(diffs or ["(unreadable recorded config)"])
                    + "\nResume with the recorded settings, or start a new bench with another --out.")
        sha, phash = git_sha(), _prompt_hash(suite.profile)
        session = {"started_at": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "git_sha": sha, "prompt_hash": phash,
                   "executor": settings.executor, "workers": settings.workers or default_workers(),
                   "resume": manifest is not None,
                   "versions": package_versions()}
        if manifest is None:
            manifest = {"format": FORMAT, "config_hash": chash, "config": config, "suite": suite.to_dict(),
                        "suite_source": suite.source,
                        "pilots": [{"spec": p.spec, "model": p.model, "dir": p.dir} for p in pilots],
                        "episodes": len(suite.rows) * suite.repetitions * len(pilots),
                        "created_at": session["started_at"], "sessions": []}
        else:
            last = (manifest.get("sessions") or [{}])[-1]
            for what, old, new in (("git SHA", last.get("git_sha"), sha), ("prompt hash", last.get("prompt_hash"),
                                                                           phash)):
                if old and old != new:
                    notes.append(f"note: the {what} changed since the last session ({old} -> {new}); "
                                 "every results line records its own")
        manifest["sessions"] = [*manifest.get("sessions", []), session]
        write_json_atomic(out / MANIFEST, manifest)

        specs = plan(suite, pilots, settings, out)
        planned = {s.key for s in specs}
        log.repair()
        done_keys = {episode_key(*record_key(r)) for r in log.read()} & planned
        todo = [s for s in specs if s.key not in done_keys]
        for n in notes:
            say(n)
        failed: dict[str, str] = {}
        ran = 0
        executor = None
        try:
            if todo:
                executor = make_executor(settings.executor, workers=settings.workers,
                                         ray_address=settings.ray_address, plugins=settings.plugins)
                say(f"bench [bold]{suite.name}[/bold]: {len(specs)} episodes ({len(suite.rows)} rows x "
                    f"{suite.repetitions} reps x {len(pilots)} pilot(s)), {len(done_keys)} already done; "
                    f"{executor.describe}; out {out}")
                if settings.workers is None and settings.executor == "local" and not all(p.privileged
                                                                                        for p in pilots):
                    say("hint: model pilots spend most of a step waiting for the model; --workers 16 keeps more "
                        "episodes in flight than there are cores")
                ran, failed = _drive(executor, todo, log, chash, len(specs), len(done_keys), settings.progress,
                                     console)
            else:
                say(f"bench {suite.name}: all {len(specs)} episodes are already in {out / RESULTS}")
        finally:
            log.close()
            close = getattr(executor, "close", None)
            if callable(close):
                close()
            tables = write_tables(out)
        records = [r for r in log.read() if episode_key(*record_key(r)) in planned]
        summaries = [summarize(p.spec, [r for r in records if r["pilot"] == p.spec]) for p in pilots]
        return BenchReport(out=out, config_hash=chash, episodes=len(specs), finished=len(records), ran=ran,
                           failed=failed, summaries=summaries, tables=tables, wall_s=time.perf_counter() - t0,
                           executor=getattr(executor, "describe", ""), notes=notes)


def _check_episode_options(suite: Suite, options: dict[str, Any]) -> None:
    """Build one EpisodeConfig now, so that a bad shield or option is refused before anything runs."""
    from vlnpilot.episode import EpisodeConfig

    reserved = sorted({"max_steps", "profile", "seed"} & set(options))
    if reserved:
        raise ConfigError(f"episode option(s) {', '.join(reserved)} are set by the suite and the bench, not by "
                          "episode_options")
    try:
        EpisodeConfig(max_steps=suite.max_steps, profile=suite.profile, **options)
    except TypeError as exc:
        raise ConfigError(f"bad episode option: {exc}") from None


def _prompt_hash(profile: str) -> str:
    from vlnpilot.prompting import prompt_hash

    return prompt_hash(profile)


def _drive(executor: Any, todo: Sequence[EpisodeSpec], log: ResultsLog, chash: str, total: int, done: int,
           show_progress: bool, console: Any) -> tuple[int, dict[str, str]]:
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
                        TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(), console=console,
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
    record = dict(ev.record)
    record["provenance"] = {**record.get("provenance", {}), "config_hash": chash,
                            "finished_at": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    log.append(record)


def _first_line(text: str | None) -> str:
    return (text or "").strip().splitlines()[0] if (text or "").strip() else "unknown error"
