"""The `vln-pilot` command line: thin wrappers over library functions (no logic a library user would need)."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.console import Console
from rich.markup import escape
from typer._click import Command, Context
from typer._click.exceptions import ClickException, NoSuchOption, UsageError
from typer.core import TyperGroup

from vlnpilot.core.errors import VLNPilotError
from vlnpilot.core.limits import MAX_REPS, MAX_STEPS

if TYPE_CHECKING:
    from vlnpilot.pilots.base import Pilot
    from vlnpilot.scene import Scene


class _ListingGroup(TyperGroup):
    """A command group whose "No such command" line ends with the valid commands (one line, exit code 2)."""

    def resolve_command(self, ctx: Context, args: list[str]) -> tuple[str | None, Command | None, list[str]]:
        try:
            return super().resolve_command(ctx, args)
        except UsageError as exc:
            if args and not args[0].startswith("-") and self.get_command(ctx, args[0]) is None:
                exc.message = f"{exc.message} Valid commands: {', '.join(self.list_commands(ctx))}."
            raise


def _usage_message(exc: ClickException) -> str:
    """The framework's message, with where to find the valid options when it suggests none."""
    message = exc.format_message()
    if isinstance(exc, NoSuchOption) and not exc.possibilities:
        message = f"{message}; the valid options: see {_command_line(exc.ctx)} --help"
    return message


def _command_line(ctx: Context | None) -> str:
    """`vln-pilot` and the subcommands of `ctx` (the program's own name varies: `python -m vlnpilot`...)."""
    names = []
    while ctx is not None and ctx.parent is not None:
        names.append(ctx.info_name or "")
        ctx = ctx.parent
    return " ".join(["vln-pilot", *reversed(names)])


app = typer.Typer(help="VLN-Pilot: a vision-language model pilots an indoor drone.", no_args_is_help=True,
                  add_completion=False, pretty_exceptions_enable=False, cls=_ListingGroup)
scene_app = typer.Typer(help="Inspect and render the built-in scenes.", no_args_is_help=True, cls=_ListingGroup)
app.add_typer(scene_app, name="scene")
console = Console(soft_wrap=True)
err_console = Console(stderr=True, soft_wrap=True)  # one error, one line (no wrapping at 80 columns)

SceneOpt = Annotated[str, typer.Option("--scene", help="Scene name: cabin or house:SEED[?rooms=N&types=a,b].")]
OutOpt = Annotated[Path | None, typer.Option("--out", help="Output directory.")]
PROFILE_HELP = "FSM profile: paper, fast or ranged (fast, and A2 in Reach Object)."
SensorsOpt = Annotated[str, typer.Option("--sensors", help="Range sensors the drone carries: none, tof (a RoboMaster "
                                         "TT's forward ToF) or multiranger (Crazyflie Multi-ranger deck).")]
CameraOpt = Annotated[str | None, typer.Option("--camera", help="What the front camera delivers in simulation: ideal "
                                               "(the render; the default) or tello (what a Tello's stream sends: "
                                               "docs/camera.md). A real Tello's frames are never changed.")]
CameraLagOpt = Annotated[float | None, typer.Option("--camera-lag-ms", min=0, max=2000, help="The tello camera's "
                                                   "frame lag (default 300 ms: docs/camera.md).")]
RandomizeOpt = Annotated[int | None, typer.Option("--randomize", min=0, max=2**31 - 1, help="Domain randomisation "
                                                 "seed: lights, paints, texture scale, camera height, exposure "
                                                 "(docs/camera.md).")]
DetailOpt = Annotated[str | None, typer.Option("--detail", help="Scene detail the cameras render: plain (the "
                                               "scenes every recorded trial saw; the default) or rich (skirting, "
                                               "floorboards, switches, handles, pictures, clutter, mirrors that "
                                               "reflect: docs/scenes.md).")]
PlannerOpt = Annotated[str, typer.Option("--planner", help="Who plans the mission: auto (the pilot, if it plans, "
                                        "unless the instruction is one plain goal), pilot or parser.")]
PilotOptionOpt = Annotated[list[str] | None, typer.Option(
    "--pilot-option", metavar="KEY=VALUE", help="A pilot option, e.g. detail=high or timeout=30 (repeatable).")]


def default_pilot_spec(env: dict[str, str] | None = None) -> tuple[str, str]:
    """The pilot to use when none is given, and why: OpenAI, then Gemini when their keys are set, else the oracle."""
    env = dict(os.environ) if env is None else env
    if env.get("OPENAI_API_KEY"):
        return "openai", "OPENAI_API_KEY is set"
    if env.get("GEMINI_API_KEY") or env.get("GOOGLE_API_KEY"):
        return "gemini", "GEMINI_API_KEY or GOOGLE_API_KEY is set"
    return "oracle", "no OPENAI_API_KEY, GEMINI_API_KEY or GOOGLE_API_KEY is set, so the ground-truth oracle flies"


@scene_app.command("info")
def scene_info(scene: SceneOpt = "cabin", as_json: Annotated[bool, typer.Option("--json")] = False) -> None:
    """Rooms, doors, targets, spawns and the topological map."""
    from vlnpilot.scene import load_scene

    info = load_scene(scene).info()
    if as_json:
        print(json.dumps(info, indent=2))
        return
    console.print(f"[bold]{info['name']}[/bold]: {info['description']}")
    console.print("[bold]rooms[/bold]: " + ", ".join(f"{r['id']} ({r['name']})" for r in info["rooms"]))
    for d in info["doors"]:
        state = "open" if d["open"] else "closed"
        console.print(f"[bold]door[/bold] {d['id']}: {' - '.join(d['rooms'])}, {d['width_m']:.2f} m wide, {state}")
    for t in info["targets"]:
        console.print(f"[bold]target[/bold] {t['id']} in {t['room']} (aliases: {', '.join(t['aliases'])})")
    for s in info["spawns"]:
        p = s["pose"]
        console.print(f"[bold]spawn[/bold] {s['id']}: ({p['x']:.2f}, {p['y']:.2f}, {p['z']:.2f}) "
                      f"yaw {p['yaw_deg']:.0f}° - {s['description']}")
    console.print("[bold]topological map[/bold]:")
    console.print_json(data=info["topological_map"])


@scene_app.command("render")
def scene_render(scene: SceneOpt = "cabin",
                 spawn: Annotated[str | None, typer.Option("--spawn", help="Spawn point name.")] = None,
                 out: OutOpt = None,
                 width: Annotated[int, typer.Option(min=16, max=960)] = 640,
                 height: Annotated[int, typer.Option(min=16, max=720)] = 480,
                 detail: DetailOpt = None) -> None:
    """Write front.png and rear.png from a spawn point, and map.png, a top-down floor plan.

    Without --spawn, also SPAWN-front.png and SPAWN-rear.png from every spawn point of the scene."""
    from PIL import Image

    from vlnpilot.core.rundir import check_not_a_bench, check_not_a_run, check_writable
    from vlnpilot.report.floorplan import save_floorplan
    from vlnpilot.sim import SimConfig, Simulator

    with Simulator(scene, SimConfig(width=width, height=height, rear_width=width, rear_height=height,
                                    detail=detail or "plain")) as sim:
        spawn_id = spawn or sim.scene.spawns[0].id
        sim.scene.spawn(spawn_id)  # validate before creating the output directory
        out_dir = check_writable(out or Path("runs") / f"scene-{sim.scene.name}-{spawn_id}")
        check_not_a_run(out_dir, "a scene's pictures")
        check_not_a_bench(out_dir, "a scene's pictures")
        obs = sim.reset(spawn_id)
        Image.fromarray(obs.front_rgb).save(out_dir / "front.png")
        Image.fromarray(obs.rear_rgb).save(out_dir / "rear.png")
        for other in [] if spawn else sim.scene.spawns:
            obs = sim.reset(other.id)
            Image.fromarray(obs.front_rgb).save(out_dir / f"{other.id}-front.png")
            Image.fromarray(obs.rear_rgb).save(out_dir / f"{other.id}-rear.png")
        save_floorplan(sim.scene, out_dir / "map.png")
    each = "" if spawn else " (and SPAWN-front.png, SPAWN-rear.png from every spawn)"
    console.print(f"wrote {out_dir}/front.png, rear.png{each} and map.png")


@app.command("run")
def run(query: Annotated[str, typer.Argument(help='The instruction, e.g. "Go to the bathroom".')],  # noqa: PLR0913 - one parameter per flag (Typer)
        scene: SceneOpt = "cabin",
        spawn: Annotated[str | None, typer.Option("--spawn", help="Spawn point name.")] = None,
        pilot: Annotated[str | None, typer.Option("--pilot", help="Pilot SPEC: name or name:model.")] = None,
        max_steps: Annotated[int, typer.Option("--max-steps", min=1, max=MAX_STEPS, help="Step limit.")] = 50,
        seed: Annotated[int | None, typer.Option("--seed", min=0, help="Seed of the episode (0 or more).")] = None,
        out: OutOpt = None,
        base_url: Annotated[str | None, typer.Option("--base-url", help="OpenAI-compatible server URL.")] = None,
        pilot_option: PilotOptionOpt = None,
        profile: Annotated[str | None, typer.Option("--profile", help=PROFILE_HELP + " Default: ranged with a "
                                                    "forward range sensor, else paper.")] = None,
        quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No per-step lines.")] = False,
        video: Annotated[bool, typer.Option("--video/--no-video", help="Write episode.mp4 and .gif.")] = True,
        shield: Annotated[str | None, typer.Option(
            "--shield", help="off, geometry, depth, assist or a registered one (default: geometry; with a "
            "Tello: assist).")] = None,
        overlay: Annotated[str | None, typer.Option("--overlay", help="Image aid for the model: corridor.")] = None,
        context: Annotated[str | None, typer.Option("--context", help="Pilot context: paper (the paper's five "
                                                    "inputs) or plus (odometry, budget, memory, confirmation; the "
                                                    "default, measured best: docs/pilot-memory.md).")] = None,
        overwrite: Annotated[bool, typer.Option("--overwrite", help="Replace a run already in --out.")] = False,
        sensors: SensorsOpt = "none",
        robot: Annotated[str, typer.Option("--robot", help="sim (the embedded simulator), tello or a "
                                           "registered one.")] = "sim",
        tello_host: Annotated[str | None, typer.Option("--tello-host", help="The Tello's address.")] = None,
        judge: Annotated[str | None, typer.Option("--judge", help="ask (the default) or none: the operator confirms "
                                                  "a Tello's declared outcome (a robot without ground truth).")] = None,
        live: Annotated[bool, typer.Option("--live", help="Serve the live ground station while it flies.")] = False,
        live_port: Annotated[int | None, typer.Option("--live-port", min=0, max=65535, help="With --live (default "
                                                      "8765).")] = None,
        live_host: Annotated[str | None, typer.Option("--live-host", help="With --live (default 127.0.0.1); off "
                                                      "loopback, set VLN_LIVE_TOKEN.")] = None,
        planner: PlannerOpt = "auto",
        camera: CameraOpt = None,
        camera_lag_ms: CameraLagOpt = None,
        randomize: RandomizeOpt = None,
        detail: DetailOpt = None,
        events: Annotated[str | None, typer.Option("--events", help="A scenario of events (people, pets, doors "
                                                   "that close, lights out, signs): a YAML file or a built-in "
                                                   "name (docs/events.md). The simulator only.")] = None,
        ) -> None:
    """Fly one episode on the embedded simulator (or a real Tello), record it and write its report.

    The instruction may be a mission of several stages ("Go to the bathroom, then come back"): it is planned
    before take-off (docs/missions.md), and one that cannot be planned is refused with exit code 2.

    Exit code 0 when the episode was flown to any outcome, 3 when it ended in pilot_error, 4 when the robot's
    link failed (link_lost), 2 for bad input, 130 when interrupted."""
    from vlnpilot.core.environment import check_capabilities
    from vlnpilot.core.exits import check_base_url, exit_code_for
    from vlnpilot.core.fsm import default_profile
    from vlnpilot.core.ranging import forward_range
    from vlnpilot.core.rundir import ROBOT_EVENTS, claim_run_dir, default_run_dir
    from vlnpilot.episode.config import EpisodeConfig
    from vlnpilot.episode.run import run_recorded_episode
    from vlnpilot.pilots.base import make_pilot
    from vlnpilot.pilots.replay import recorded_mission, recorded_scenario, recorded_settings
    from vlnpilot.prompting.context import DEFAULT_CONTEXT
    from vlnpilot.robots.operator import ConsoleOperator, make_judge
    from vlnpilot.robots.session import check_robot, open_robot, robot_capabilities
    from vlnpilot.safety import default_shield
    from vlnpilot.scene import load_scene

    robot = check_robot(robot, tello_host)
    capabilities = robot_capabilities(robot, sensors, tello_host)  # refuses a sensor the drone does not carry
    recorded = recorded_settings(pilot)  # a replay flies as it was flown, unless an option says otherwise
    camera, camera_lag_ms, randomize = _imaging(robot, pilot, recorded, camera, camera_lag_ms, randomize)
    detail = _checked_detail(detail or recorded.get("detail") or "plain", robot)
    shield = shield or recorded.get("shield") or default_shield(capabilities.ground_truth)
    operator = ConsoleOperator()
    judge_outcome = make_judge(judge or "ask", operator)  # validated for every robot, used without ground truth
    _refuse_unused(live, live_port, live_host, judge, capabilities.ground_truth)

    sc = _with_events(load_scene(scene), events, recorded_scenario(pilot), robot)
    spawn_id = spawn or sc.spawns[0].id
    sc.spawn(spawn_id)
    profile = profile or recorded.get("profile") or default_profile(forward_range(sensors))
    config = EpisodeConfig(max_steps=max_steps, seed=seed, profile=profile, shield=shield, overlay=overlay,
                           context=context or recorded.get("context") or DEFAULT_CONTEXT, detail=detail)
    if pilot is None:
        pilot, why = default_pilot_spec()
        console.print(f"pilot: [bold]{pilot}[/bold] ({why})")
    options = _pilot_options(pilot, pilot_option)
    if base_url:
        options["base_url"] = check_base_url(base_url)
    pilot_obj = make_pilot(pilot, **options)  # first: a pilot whose extra is missing says so
    _say_remote_url(pilot)
    check_capabilities(capabilities, robot, shield=shield, pilot=pilot_obj)  # before anything flies
    task = _planned(query, sc, spawn_id, pilot_obj, planner, recorded_mission(pilot, query))  # a refusal flies nothing
    run_dir = claim_run_dir(out or default_run_dir("runs", f"{spawn_id}-{query}"), overwrite=overwrite)

    def show(rec: dict) -> None:
        if quiet:
            return
        d = rec["decision"] or {}  # model text is untrusted: escape it before Rich reads markup in it
        fail = f" [red]({len(rec['failures'])} rejected)[/red]" if rec["failures"] else ""
        hit = f" [bold red]COLLISION with {escape(str(rec['contact']))}[/bold red]" if rec["collided"] else ""
        if rec.get("interventions"):
            hit += f" [yellow](safety: {escape(str(rec['proposed']))} -> {escape(str(rec['executed']))})[/yellow]"
        console.print(f"[dim]{rec['step']:>3}[/dim] {rec['state']:<27} [bold]{rec['executed'] or '-':<2}[/bold] "
                      f"-> {rec['next_state'] or '-':<27} room={escape(str(d.get('room', '?'))):<12}{fail}{hit} "
                      f"[dim]{escape((d.get('description') or '')[:70])}[/dim]", highlight=False)

    station = _live_station(live, run_dir, pilot_obj, sc, live_host or "127.0.0.1", 8765 if live_port is None
                            else live_port)
    with station as control, open_robot(robot, sc, tello_host=tello_host, event_log=run_dir / ROBOT_EVENTS,
                                        operator=operator, sensors=sensors, camera=camera,
                                        camera_lag_ms=camera_lag_ms, randomize=randomize, detail=detail) as env:
        try:
            result = run_recorded_episode(env, pilot_obj, task, config, run_dir=run_dir, spawn=spawn_id,
                                          pilot_spec=pilot, overwrite=True,  # claimed above
                                          on_step=show, judge_outcome=judge_outcome, control=control)
        except KeyboardInterrupt:
            err_console.print(f"interrupted: every step recorded so far is kept in {escape(str(run_dir))}")
            raise typer.Exit(130) from None
    colour = "green" if result.success else "yellow" if result.outcome == "declared" else "red"
    console.print(f"[bold {colour}]{result.outcome}[/bold {colour}] in {result.steps} steps: {result.reason}; "
                  f"path {result.path_length_m:.2f} m, SPL {result.spl:.2f}, tokens "
                  f"{result.input_tokens}+{result.output_tokens}, cost ${result.cost_usd:.4f}")
    console.print(f"run directory: {escape(str(run_dir))}  (report: {_optional_report(run_dir, video=video)})")
    raise typer.Exit(exit_code_for([result.outcome]))


def _imaging(robot: str, pilot: str | None, recorded: dict[str, str], camera: str | None, lag_ms: float | None,
             randomize: int | None) -> tuple[str | None, float | None, int | None]:
    """`--camera`, `--camera-lag-ms`, `--randomize` checked for the robot (docs/camera.md); a replay's frames are
    made as they were recorded, and other frames than those are refused (a real Tello's frames are its own)."""
    from vlnpilot.pilots.replay import check_replay_camera
    from vlnpilot.robots.session import check_camera_for

    if robot == "sim":
        camera = camera or recorded.get("camera")
        lag = recorded.get("camera_lag_ms")
        lag_ms = lag_ms if lag_ms is not None else (float(lag) if lag else None)
        randomize = randomize if randomize is not None else (int(recorded["randomize"]) if "randomize" in recorded
                                                             else None)
    check_camera_for(robot, camera, lag_ms, randomize)
    if robot == "sim":
        from vlnpilot.sim.camera_model import camera_flown_with

        check_replay_camera(pilot, camera_flown_with(camera, lag_ms, randomize))
    return camera, lag_ms, randomize


def _checked_detail(detail: str, robot: str) -> str:
    """`--detail`, refused in one line when it is not a choice or the robot renders no scene (a real camera)."""
    from vlnpilot.core.errors import ConfigError
    from vlnpilot.scene.detail import check_detail

    if check_detail(detail) != "plain" and robot != "sim":
        raise ConfigError(f"--detail {detail} applies to --robot sim (the Tello emulator takes its own --detail)")
    return detail


def _with_events(sc: Scene, events: str | None, recorded: dict | None, robot: str) -> Scene:
    """The scene with `--events` (or, for a replay without it, the recording's scenario): the simulator only."""
    from vlnpilot.core.errors import ConfigError
    from vlnpilot.scene.events import load_scenario, scenario_from_dict, with_scenario

    if events is None and recorded is None:
        return sc
    if robot != "sim":
        raise ConfigError(f"--events needs the simulator (--robot sim); the {robot} flies in a real room")
    scenario = load_scenario(events) if events is not None else scenario_from_dict(recorded, "of the recording")
    return with_scenario(sc, scenario)


def _refuse_unused(live: bool, live_port: int | None, live_host: str | None, judge: str | None,
                   ground_truth: bool) -> None:
    """An option that would change nothing is refused in one line, rather than silently ignored."""
    from vlnpilot.core.errors import ConfigError

    given = [name for name, value in (("--live-port", live_port), ("--live-host", live_host)) if value is not None]
    if given and not live:
        raise ConfigError(f"{' and '.join(given)} without --live would change nothing (they set the live "
                          "station): add --live, or drop them")
    if judge is not None and ground_truth:
        raise ConfigError(f"--judge {judge} applies to a robot without ground truth (--robot tello): the simulator "
                          "judges every declared outcome itself; drop --judge")


def _live_station(live: bool, run_dir: Path, pilot: Pilot, scene: Scene, host: str, port: int):
    """The live ground station's control for `run --live` (vlnpilot.live), else no control."""
    if not live:
        return contextlib.nullcontext(None)
    from vlnpilot.core.extras import require

    require("server", "report", what="the live station (--live)")
    from vlnpilot.live.station import live_control

    return live_control(run_dir, pilot, scene, host=host, port=port, say=lambda line: console.print(escape(line)))


def _planned(query: str, scene: Any, spawn_id: str, pilot: Any, planner: str, recorded: dict | None = None) -> Any:
    """The instruction's mission (pilots/planning.py), said in a line when it is more than one goal; a replay's
    `recorded` mission (a pilot's plan for this query) as recorded, checked against the map."""
    from vlnpilot.pilots.planning import plan_instruction
    from vlnpilot.tasks.mission import Mission, validate_mission

    if recorded is not None:
        mission = validate_mission(Mission.from_dict(recorded), scene, scene.spawn(spawn_id).room)
    else:
        mission, _ = plan_instruction(query, scene, scene.spawn(spawn_id).room, pilot, planner=planner,
                                      say=lambda line: err_console.print(escape(line)))
    if mission.recorded:
        console.print(f"plan ({escape(mission.source)}): {escape(mission.describe().replace(chr(10), '; '))}")
    return mission


@app.command("plan")
def plan(query: Annotated[str, typer.Argument(help='The instruction, e.g. "Go to the bathroom, then come back".')],
         scene: SceneOpt = "cabin",
         spawn: Annotated[str | None, typer.Option("--spawn", help="Spawn point name (where a return goes).")] = None,
         pilot: Annotated[str | None, typer.Option("--pilot", help="Pilot SPEC that plans (default, or a pilot "
                                                   "that does not plan: the deterministic parser).")] = None,
         base_url: Annotated[str | None, typer.Option("--base-url", help="OpenAI-compatible server URL.")] = None,
         pilot_option: PilotOptionOpt = None,
         planner: PlannerOpt = "pilot",
         as_json: Annotated[bool, typer.Option("--json", help="Print the mission as JSON.")] = False) -> None:
    """Print the plan of an instruction against a scene's map, and fly nothing. Exit code 2 if it is refused."""
    from vlnpilot.pilots.planning import can_plan, check_planner, plan_instruction
    from vlnpilot.scene import load_scene

    check_planner(planner)  # checked even when the parser plans, as `run` checks it
    sc = load_scene(scene)
    spawn_id = spawn or sc.spawns[0].id
    sc.spawn(spawn_id)
    pilot_obj = _planning_pilot(pilot, base_url, pilot_option)
    mission, _ = plan_instruction(query, sc, sc.spawn(spawn_id).room, pilot_obj,
                                  planner=planner if can_plan(pilot_obj) else "parser",
                                  say=lambda line: err_console.print(escape(line)))
    if as_json:
        console.print_json(json.dumps({**mission.to_dict(), "plan": mission.plan()}))
        return
    console.print(f"plan of {escape(repr(query))} in {escape(sc.name)} from {escape(spawn_id)} "
                  f"(by {escape(mission.source)}):")
    console.print(escape(mission.describe()))


def _planning_pilot(spec: str | None, base_url: str | None, pairs: list[str] | None) -> Pilot | None:
    """`plan`'s pilot from its options; without --pilot the parser plans, and an option for a pilot is refused
    (it would configure nothing)."""
    from vlnpilot.core.errors import ConfigError
    from vlnpilot.core.exits import check_base_url
    from vlnpilot.pilots.base import make_pilot

    if spec is None:
        given = [name for name, value in (("--base-url", base_url), ("--pilot-option", pairs)) if value]
        if given:
            raise ConfigError(f"{' and '.join(given)} given without --pilot: give the pilot that plans too, e.g. "
                              "--pilot openai:gpt-4.1 (without one the parser plans, and it takes no options)")
        return None
    options = _pilot_options(spec, pairs)
    if base_url:
        options["base_url"] = check_base_url(base_url)
    return make_pilot(spec, **options)


def _pilot_options(spec: str, pairs: list[str] | None) -> dict:
    """`--pilot-option KEY=VALUE`s, checked and coerced by the pilot's options class (one line for a bad one)."""
    from vlnpilot.pilots.base import parse_spec, pilot_options_class
    from vlnpilot.pilots.options import parse_option_pairs

    name = parse_spec(spec)[0]
    return pilot_options_class(name).from_command_line(name, parse_option_pairs(pairs or ()))


@app.command("watch")
def watch(run_dir: Annotated[Path, typer.Argument(help="A run directory, finished or still running.")],
          port: Annotated[int, typer.Option("--port", min=0, max=65535)] = 8765,
          host: Annotated[str, typer.Option("--host", help="Off loopback, set VLN_LIVE_TOKEN.")] = "127.0.0.1",
          ) -> None:
    """Open a run in the live ground station's page, read-only, from its files (until Ctrl-C)."""
    from vlnpilot.core.extras import require

    require("server", "report", what="vln-pilot watch")
    from vlnpilot.live.station import watch_run

    watch_run(run_dir, host=host, port=port, say=lambda line: console.print(escape(line)))


def _say_remote_url(spec: str) -> None:
    """The remote pilot falls back to a local server: say so, rather than silently."""
    from vlnpilot.pilots.base import parse_spec

    if parse_spec(spec)[0] != "remote":
        return
    from vlnpilot.pilots.remote import DEFAULT_URL, URL_ENV  # only now: it needs the [server] extra

    if not os.environ.get(URL_ENV):
        err_console.print(f"pilot server: {DEFAULT_URL} ({URL_ENV} is not set)", highlight=False)


@contextlib.contextmanager
def _sigterm_interrupts():
    """SIGTERM, and SIGHUP (the terminal closed, the ssh link dropped), are handled as Ctrl-C (a
    KeyboardInterrupt): a run's record is closed as 'interrupted', a Tello is landed as the block around it
    closes, a bench stops its workers (which record their episodes in flight as 'interrupted'), and the exit code
    is 130."""
    def interrupt(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    signums = [signal.SIGTERM] + ([signal.SIGHUP] if hasattr(signal, "SIGHUP") else [])
    try:
        previous = {signum: signal.signal(signum, interrupt) for signum in signums}
    except ValueError:  # not the main thread (an embedding): leave the signals alone
        yield
        return
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def _optional_report(run_dir: Path, *, video: bool = True, bench: bool = False) -> str:
    """Write the report after a run or a bench if the [report] extra is installed; else say how to get one."""
    from vlnpilot.core.extras import MissingExtraError

    try:
        path = _write_bench_report(run_dir) if bench else _write_episode_report(run_dir, video=video)
    except MissingExtraError as exc:
        return escape(f"not written: {exc}; then `vln-pilot report {run_dir}`")
    return escape(str(path))


def _write_bench_report(bench_dir: Path) -> Path:
    from vlnpilot.core.extras import require

    require("report", what="the report")
    from vlnpilot.report.html import write_bench_report

    return write_bench_report(bench_dir)


def _write_episode_report(run_dir: Path, *, video: bool = True) -> Path:
    from vlnpilot.core.extras import require

    require("report", what="the report")
    from vlnpilot.report.html import write_episode_report
    from vlnpilot.report.video import write_episode_video

    if video:  # first, so that the page links the video
        write_episode_video(run_dir)
    return write_episode_report(run_dir, warn=lambda line: err_console.print(f"warning: {escape(line)}",
                                                                             highlight=False))


@app.command("report")
def report(run_dir: Annotated[Path, typer.Argument(help="A run directory (or a bench directory).")],
           video: Annotated[bool, typer.Option("--video/--no-video", help="Also write episode.mp4 and .gif.")] = True,
           ) -> None:
    """Write report.html (and the episode video) for a recorded run, or the report of a bench directory."""
    from vlnpilot.core.errors import ConfigError
    from vlnpilot.core.fileio import check_not_directories

    if not run_dir.is_dir():
        raise ConfigError(f"{run_dir} is not a directory; give a run directory (with summary.json) or a bench "
                          "directory (with results.jsonl)")
    if (run_dir / "results.jsonl").is_file() and not (run_dir / "summary.json").is_file():
        check_not_directories(run_dir, ("report.html",))
        path = _write_bench_report(run_dir)
    else:
        if not (run_dir / "summary.json").is_file():
            raise ConfigError(f"{run_dir} is not a run directory: summary.json is missing")
        check_not_directories(run_dir, ("report.html", "floorplan.png", "episode.mp4", "episode.gif"))
        path = _write_episode_report(run_dir, video=video)
    console.print(f"wrote {escape(str(path))}")


@app.command("bench")
def bench(suite: Annotated[str, typer.Option("--suite", help="paper, houses[:SEEDS] or a YAML file.")] = "paper",  # noqa: PLR0913, E501 - one parameter per flag (Typer)
          pilots: Annotated[str, typer.Option("--pilots", help="Pilot SPECs, comma-separated.")] = "oracle",
          reps: Annotated[int | None, typer.Option("--reps", min=1, max=MAX_REPS, help="Repetitions per row.")] = None,
          max_steps: Annotated[int | None, typer.Option("--max-steps", min=1, max=MAX_STEPS)] = None,
          workers: Annotated[int | None, typer.Option("--workers", min=1, help="Episodes in flight.")] = None,
          executor: Annotated[str, typer.Option("--executor", help="local, ray, inline or one a --plugin "
                                                "registers.")] = "local",
          ray_address: Annotated[str | None, typer.Option("--ray-address")] = None,
          out: OutOpt = None,
          resume: Annotated[bool, typer.Option("--resume", help="Run only the episodes missing in --out.")] = False,
          seed: Annotated[int | None, typer.Option("--seed", min=0, help="Base seed of the repetitions "
                                                                    "(0 or more).")] = None,
          profile: Annotated[str | None, typer.Option("--profile", help=PROFILE_HELP)] = None,
          base_url: Annotated[str | None, typer.Option("--base-url")] = None,
          pilot_option: PilotOptionOpt = None,
          shield: Annotated[str | None, typer.Option("--shield", help="off, geometry, depth, assist or a registered "
                                                     "one (default: the suite's pin, else geometry).")] = None,
          overlay: Annotated[str | None, typer.Option("--overlay", help="corridor")] = None,
          context: Annotated[str | None, typer.Option("--context", help="Pilot context: paper or plus (default: the "
                                                      "suite's pin, else plus).")] = None,
          report: Annotated[bool, typer.Option("--report/--no-report", help="Write report.html.")] = True,
          frames: Annotated[bool | None, typer.Option(
              "--frames/--no-frames", help="Record each step's camera frames (front and chase view) for the report's "
              "episode pages (default: with --report; a resumed bench as it started).")] = None,
          sensors: SensorsOpt = "none",
          detail: DetailOpt = None,
          rate_limit: Annotated[str | None, typer.Option(
              "--rate-limit", help="RPM,TPM: the requests and tokens per minute each provider and model may "
              "take, shared by every worker, until the provider's rate-limit headers say otherwise.")] = None,
          plugin: Annotated[list[str] | None, typer.Option(
              "--plugin", help="A module to import first, in every worker too: it may register pilots, "
              "executors and shields. Repeatable.")] = None,
          camera: CameraOpt = None,
          randomize: Annotated[int | None, typer.Option(
              "--randomize", min=0, max=2**31 - 1, help="Domain randomisation seed of the rows whose suite names "
              "none (a suite's `randomize:`, per suite or row, wins; docs/camera.md).")] = None,
          estimate: Annotated[bool, typer.Option(
              "--estimate", help="Print the estimated calls, tokens, cached share and cost of each pilot, counted "
              "offline, and exit without flying.")] = False) -> None:
    """Run a benchmark suite (default: the paper's Table 4) for one or more pilots; write tables and a report.

    Exit code 0 when every episode was flown to an outcome, 3 when any ended in pilot_error, 2 for bad input."""
    from vlnpilot.bench.command import bench_command
    from vlnpilot.bench.episode_job import import_plugins
    from vlnpilot.bench.results import RESULTS, ResultsLog
    from vlnpilot.bench.suite import suite_pins
    from vlnpilot.core.exits import check_base_url, exit_code_for
    from vlnpilot.pilots.options import parse_option_pairs
    from vlnpilot.prompting.context import DEFAULT_CONTEXT
    from vlnpilot.safety import DEFAULT_SHIELD

    import_plugins(tuple(plugin or ()))  # first: a plugin's shield may be what the suite pins
    pins = suite_pins(suite)  # the paper suite pins the paper's; a set of trials what it was flown with
    options: dict[str, str] = {"overlay": overlay} if overlay else {}
    options["context"] = context or pins.context or DEFAULT_CONTEXT
    if detail is not None and _checked_detail(detail, "sim") != "plain":  # plain: benches before it hash alike
        options["detail"] = detail
    if estimate:  # checked as a bench that flies checks them, but for its pilots' keys (it counts offline)
        from vlnpilot.bench.command import check_bench_options
        from vlnpilot.bench.estimate import estimate_command

        check_base_url(base_url)
        parse_option_pairs(pilot_option or ())
        check_bench_options(suite, executor=executor, shield=shield, sensors=sensors, episode_options=options,
                            rate_limit=rate_limit, camera=camera, ray_address=ray_address)
        estimate_command(suite, pilots, reps=reps, max_steps=max_steps, profile=profile, context=options["context"],
                         console=console)
        raise typer.Exit(0)
    bench_dir = bench_command(suite=suite, pilots=pilots, reps=reps, max_steps=max_steps, workers=workers,
                              executor=executor, ray_address=ray_address, out=out, resume=resume, seed=seed,
                              profile=profile, base_url=check_base_url(base_url),
                              shield=shield or pins.shield or DEFAULT_SHIELD,
                              episode_options=options, pilot_options=parse_option_pairs(pilot_option or ()),
                              plugins=tuple(plugin or ()), sensors=sensors, rate_limit=rate_limit,
                              frames=frames if frames is not None or resume else report, camera=camera,
                              randomize=randomize)
    if report:
        console.print(f"report: {_optional_report(bench_dir, bench=True)}")
    raise typer.Exit(exit_code_for(r["result"]["outcome"] for r in ResultsLog(bench_dir / RESULTS).read()))


@app.command("tello-emulator")
def tello_emulator(scene: SceneOpt = "cabin",
                   spawn: Annotated[str | None, typer.Option("--spawn", help="Spawn point name.")] = None,
                   host: Annotated[str, typer.Option("--host", help="A loopback address.")] = "127.0.0.1",
                   port: Annotated[int, typer.Option("--port", min=1, max=65535)] = 8889,
                   state_port: Annotated[int, typer.Option("--state-port", min=1, max=65535)] = 8890,
                   video_port: Annotated[int, typer.Option("--video-port", min=1, max=65535)] = 11111,
                   battery: Annotated[float, typer.Option("--battery", min=0, max=100, help="Start %.")] = 100.0,
                   drop_replies: Annotated[float, typer.Option("--drop-replies", min=0, max=0.99)] = 0.0,
                   drop_seed: Annotated[int, typer.Option("--drop-seed", min=0, help="Seed of which replies are "
                                                          "dropped (the same seed drops the same ones).")] = 0,
                   video_delay: Annotated[float, typer.Option("--video-delay", min=0, max=10, help="s")] = 0.0,
                   camera: Annotated[str, typer.Option("--camera", help="What its video shows: tello (what a Tello "
                                                       "sends; its lag is --video-delay) or ideal (the renders); "
                                                       "docs/camera.md.")] = "tello",
                   randomize: RandomizeOpt = None,
                   detail: DetailOpt = None,
                   ) -> None:
    """A Tello SDK 2.0 peer on loopback (commands 8889, state to 8890, H.264 to 11111) flying the simulated drone."""
    from vlnpilot.core.extras import require

    require("tello", what="the Tello emulator")
    from vlnpilot.robots.emulator import EmulatorConfig
    from vlnpilot.robots.session import serve_emulator
    from vlnpilot.scene import load_scene

    sc = load_scene(scene)
    if spawn is not None:
        sc.spawn(spawn)  # validate: one line listing the spawns
    config = EmulatorConfig(host=host, port=port, state_port=state_port, video_port=video_port, battery_pct=battery,
                            drop_replies=drop_replies, video_delay_s=video_delay, seed=drop_seed, camera=camera,
                            randomize=randomize, detail=detail or "plain")
    serve_emulator(scene, spawn, config, say=lambda text: console.print(escape(text), highlight=False))


@app.command("serve")
def serve(host: Annotated[str, typer.Option("--host")] = "127.0.0.1",
          port: Annotated[int, typer.Option("--port", min=1, max=65535)] = 8000,
          pilot: Annotated[str | None, typer.Option("--pilot", help="Default pilot SPEC.")] = None,
          allow: Annotated[list[str] | None, typer.Option("--allow", help="Another pilot SPEC clients may ask for "
                                                          "(repeatable); nothing else is served.")] = None) -> None:
    """Serve pilots over HTTP (POST /v1/decide, GET /healthz, OpenAPI at /docs); VLN_PILOT_TOKEN sets a bearer token.

    Only --pilot and the --allow SPECs are served; off loopback a token is required."""
    from vlnpilot.core.extras import require

    require("server", what="vln-pilot serve")
    from vlnpilot.server.app import serve as run_server

    if pilot is None:
        pilot, why = default_pilot_spec()
        if pilot == "oracle":  # the oracle needs the simulator's ground truth, which a server does not have
            pilot, why = "openai", "the default model pilot; set OPENAI_API_KEY"
        console.print(f"default pilot: [bold]{pilot}[/bold] ({why})")
    run_server(host=host, port=port, pilot_spec=pilot, allowed_pilots=allow or [])


def main() -> None:
    """Entry point: bad input becomes one clear line on stderr and exit code 2, never a traceback.

    Exit codes (vlnpilot.core.exits): 0 flown, 2 bad input, 3 pilot or provider failure, 4 robot link fault,
    130 interrupted.
    """
    # Typer >= 0.29 (pinned in pyproject.toml) vendors click as typer._click; Abort lives in typer itself.
    from typer._click.exceptions import NoArgsIsHelpError

    try:
        with _sigterm_interrupts():  # every command, from start-up on: SIGTERM is Ctrl-C
            code = app(standalone_mode=False)  # usage errors come back here, to be printed in one line
    except VLNPilotError as exc:
        from vlnpilot.core.exits import error_exit_code

        _one_line_error(str(exc))
        sys.exit(error_exit_code(exc))
    except ModuleNotFoundError as exc:  # an optional module that no `extras.needs` block named: still one line
        from vlnpilot.core.extras import missing_extra_message

        message = missing_extra_message(exc)
        if message is None:
            raise
        _one_line_error(message)
        sys.exit(2)
    except OSError as exc:  # a path argument too long for the file system: one line; any other is a fault
        from vlnpilot.core.exits import path_error_message

        message = path_error_message(exc)
        if message is None:
            raise
        _one_line_error(message)
        sys.exit(2)
    except NoArgsIsHelpError as exc:  # a bare `vln-pilot`: the help, as before
        exc.show()
        sys.exit(exc.exit_code)
    except ClickException as exc:
        _one_line_error(_usage_message(exc))
        sys.exit(exc.exit_code)
    except (KeyboardInterrupt, typer.Abort):
        err_console.print("interrupted: every step recorded so far is kept")
        sys.exit(130)
    sys.exit(code if isinstance(code, int) else 0)


def _one_line_error(message: str) -> None:
    line = " ".join(message.split())  # a framework message may span lines
    err_console.print(f"[bold red]error:[/bold red] {escape(line)}", highlight=False)


if __name__ == "__main__":
    main()
