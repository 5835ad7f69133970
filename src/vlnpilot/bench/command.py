"""`vln-pilot bench` as a plain function: the CLI only parses options and calls `bench_command`."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from vlnpilot.bench.executors import BenchError
from vlnpilot.bench.manifest import MANIFEST, read_manifest
from vlnpilot.bench.runner import BenchReport, BenchSettings, run_bench
from vlnpilot.bench.suite import SuitePins, suite_pins
from vlnpilot.core.cameras import DEFAULT_CAMERA, check_camera
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.ranging import range_sensor
from vlnpilot.pilots.ratelimit import parse_rate_limit
from vlnpilot.scene.detail import check_detail


def _checked_sensors(name: str) -> str:
    sensor = range_sensor(name)  # a bad name: one line, before anything runs
    return sensor.name if sensor else "none"


def bench_command(suite: str | Path = "paper", pilots: str | Sequence[str] = "oracle", reps: int | None = None,
                  max_steps: int | None = None, workers: int | None = None, executor: str = "local",
                  ray_address: str | None = None, out: str | Path | None = None, resume: bool = False,
                  seed: int | None = None, profile: str | None = None, base_url: str | None = None,
                  progress: bool = True, shield: str | None = None, *, episode_options: dict[str, Any] | None = None,
                  render: bool = True, pilot_options: Mapping[str, str] | None = None,
                  plugins: Sequence[str] = (), console: Any = None, sensors: str = "none", **more: Any) -> Path:
    """Run (or `resume`) a bench of `suite` x `pilots` and write its tables; returns the bench directory.

    `suite`: 'paper' or a YAML file. `pilots`: 'oracle,openai:gpt-4.1' or a list. reps / max_steps / seed /
    profile override the suite's. `workers`: episodes in flight (default: the number of cores; go above it
    for model pilots). `executor`: local | ray | inline. `shield`: off | geometry | depth (None: off, the
    paper's behaviour). `episode_options`: further EpisodeConfig fields (e.g. {'overlay': 'corridor'}); all of
    them enter the config hash. `pilot_options`: {option: value string} (`--pilot-option`), coerced by each
    pilot's options class and given to every pilot that takes the option; recorded with the pilot (and hashed).
    Raises BenchError (a VLNPilotError) when episodes failed, after recording every finished one: rerun with
    resume=True to fly only the missing ones. `sensors`: the range sensors (none | tof | multiranger) of every
    row's drone that names none itself. A suite may pin its shield and context (the paper suite pins no shield and
    the paper's context): `shield` and `episode_options['context']`, given, win over a pin. `frames`: record each
    step's camera frames, which the report's episode pages show; False writes none and skips the chase camera's
    render, used by nothing else. None: as the resumed bench recorded them, else True. `rate_limit`: 'RPM,TPM',
    the budget of each provider and model until its rate-limit headers say otherwise (pilots/ratelimit.py).
    `camera` (ideal | tello) and `randomize` (a seed for the rows whose suite names none): docs/camera.md. These
    come as keywords of `more` (the signature's ceiling, pyproject's max-args, is not raised for them).
    """
    frames, rate_limit = _more_settings(more)
    check_ray_address(executor, ray_address)
    limit = parse_rate_limit(rate_limit)  # a bad value: one line, before anything runs
    if console is None:
        from rich.console import Console

        console = Console(stderr=True)
    if out is None:
        from vlnpilot.core.rundir import default_run_dir

        if resume:
            raise BenchError("--resume needs --out: the bench directory to resume")
        out = default_run_dir("runs", f"bench-{Path(str(suite)).stem}")
    elif resume and not (Path(out) / MANIFEST).is_file():
        raise BenchError(f"--resume --out {out}: there is no bench there to resume (no {MANIFEST}); give the "
                         "directory of an earlier bench, or drop --resume to start one")
    pins = suite_pins(suite)
    options = _with_pins(pins, shield, dict(episode_options or {}))
    check_detail(options.get("detail", "plain"))  # a bad value: one line, before anything runs
    if frames is None:  # a resumed bench goes on as it started (the choice is in its config hash)
        manifest = read_manifest(out) if resume else None
        frames = bool(manifest["config"].get("save_frames", True)) if manifest else True
    settings = BenchSettings(
        suite=suite, pilots=pilots if isinstance(pilots, str) else tuple(pilots), out=out, reps=reps,
        max_steps=max_steps, seed=seed,
        profile=profile, base_url=base_url, pilot_options=dict(pilot_options or {}), executor=executor,
        episode_options=options,
        workers=workers, ray_address=ray_address, resume=resume, render=render, save_frames=render and frames,
        plugins=tuple(plugins), progress=progress, sensors=_checked_sensors(sensors),
        rate_limit=f"{limit.rpm:g},{limit.tpm or 0:g}" if limit else None, **_imaging(more, pins))
    try:
        report = run_bench(settings, console=console)
    except KeyboardInterrupt:
        console.print(_interrupted(Path(out)), highlight=False)
        raise
    print_report(report, console)
    if report.failed:
        keys = sorted(report.failed)
        shown = "\n  ".join(f"{k}: {report.failed[k].strip().splitlines()[0] if report.failed[k].strip() else '?'}"
                            for k in keys[:5])
        rest = f"\n  ... and {len(keys) - 5} more" if len(keys) > 5 else ""
        raise BenchError(f"{len(keys)} episode(s) did not finish:\n  {shown}{rest}\n"
                         f"every finished episode is recorded; rerun with --resume --out {report.out} to fly the rest")
    return report.out


def check_ray_address(executor: str, ray_address: str | None) -> None:
    """--ray-address with an executor that ignores it (local, inline) is refused: it would silently change nothing."""
    if ray_address is not None and executor in ("local", "inline"):
        raise ConfigError(f"--ray-address applies to --executor ray (here: {executor}); add --executor ray, or drop "
                          "--ray-address")


def check_bench_options(suite: str | Path = "paper", *, executor: str = "local", shield: str | None = None,
                        sensors: str = "none", episode_options: dict[str, Any] | None = None,
                        rate_limit: str | None = None, camera: str | None = None,
                        ray_address: str | None = None) -> None:
    """The checks a bench makes before it flies, but for building its pilots (`--estimate` builds none: it needs no
    provider key): a bad value is one line, as it is for a bench that flies."""
    from vlnpilot.bench.executors import executor_factory
    from vlnpilot.bench.runner import check_episode_options
    from vlnpilot.bench.suite import load_suite

    parse_rate_limit(rate_limit)
    executor_factory(executor)
    check_ray_address(executor, ray_address)
    _checked_sensors(sensors)
    pins = suite_pins(suite)
    check_camera(camera or pins.camera or DEFAULT_CAMERA)
    options = _with_pins(pins, shield, dict(episode_options or {}))
    check_detail(options.get("detail", "plain"))
    check_episode_options(load_suite(suite), options)


def _interrupted(out: Path) -> str:
    """What Ctrl-C leaves: a bench to resume, or (interrupted while it was planned) nothing to resume."""
    if (out / MANIFEST).is_file():
        return f"interrupted: finished episodes are kept in {out}/results.jsonl; continue with --resume --out {out}"
    return "interrupted before the bench started: nothing was recorded, there is nothing to resume"


def print_report(report: BenchReport, console: Any) -> None:
    for s in report.summaries:
        lat = f", latency p50 {s.latency_p50_s:.3f} s p95 {s.latency_p95_s:.3f} s" if s.latency_p50_s is not None \
            else ""
        cached = f" ({s.cached_tokens / s.input_tokens:.0%} cached)" if s.input_tokens else ""
        console.print(
            f"[bold]{s.pilot}[/bold]: {s.successes}/{s.episodes} successes ({100 * s.success_rate:.1f}%, 95% CI "
            f"{100 * s.ci_low:.1f}-{100 * s.ci_high:.1f}%), SPL {s.spl:.3f}, {s.collisions} collisions, "
            f"{s.steps_exceeded} step limits, {s.false_successes} false successes, tokens "
            f"{s.input_tokens}/{s.output_tokens}{cached}, cost ${s.cost_usd:.4f}{lat}", highlight=False)
    state = "complete" if report.complete else f"{report.finished}/{report.episodes} episodes"
    console.print(f"bench {state} in {report.wall_s:.1f} s ({report.ran} run now); tables: "
                  + ", ".join(str(p) for p in report.tables[:3]), highlight=False)


def _more_settings(more: dict[str, Any]) -> tuple[bool | None, str | None]:
    """`frames` and `rate_limit`, the bench's two keyword-only settings beyond the signature."""
    unknown = sorted(set(more) - {"frames", "rate_limit", "camera", "randomize"})
    if unknown:
        raise TypeError(f"bench_command() got unexpected keyword arguments: {', '.join(unknown)}")
    return more.get("frames"), more.get("rate_limit")


def _imaging(more: dict[str, Any], pins: SuitePins) -> dict[str, Any]:
    """`camera` (as given, else as the suite pins it, else ideal) and `randomize` (docs/camera.md), checked: a bad
    camera is one line, before anything runs."""
    randomize = more.get("randomize")
    if randomize is not None and (isinstance(randomize, bool) or not isinstance(randomize, int)
                                  or not 0 <= randomize < 2**31):
        raise ConfigError(f"--randomize must be a seed in 0..{2**31 - 1}, got {randomize!r}")
    return {"camera": check_camera(more.get("camera") or pins.camera or DEFAULT_CAMERA), "randomize": randomize}


def _with_pins(pins: SuitePins, shield: str | None, options: dict[str, Any]) -> dict[str, Any]:
    """The episode options with the shield and context the bench flies: as given, else as the suite pins them (else
    no shield and the paper's context). A paper context is left out, as before pins existed, so that earlier benches
    keep their config hash."""
    context = options.pop("context", None) or pins.context or "paper"
    return {"shield": (shield or pins.shield or "off").lower(), **({"context": context} if context != "paper"
                                                                 else {}), **options}
