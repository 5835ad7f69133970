"""Time from a Tello link's death to the `land` command: the emulator's link cut at random steps of an episode.

Each run starts the emulator on free loopback ports (127.0.0.1 only), connects the Tello backend with the
default settings of tello.yaml (link_silence_s 1.0, video_silence_s 2.0, land_confirm_s 5.0), and flies an
episode whose pilot, at a random step, has the link cut after a random delay (0-1.5 s: during the move, the
frame wait or the next ask). Both are drawn from --seed. Three cuts: `link` (the emulator killed: every channel
dies), `state` (its state packets stop, commands and video go on), `video` (its stream stops). A run passes when
the episode ends `link_lost`, the watchdog's first `land` left within the cut's limit of the death (2 s; the video
3 s, its silence limit being 2), and no more moves are recorded as executed than the emulator had received when
the link was cut (every step asked after it: nothing executed). Prints each run, the median and the maximum time
to `land`, and the machine; writes the tables to bench/results/link_loss.md. The exit code is 1 if any run failed.

    .venv/bin/python bench/link_loss.py [--runs 10] [--seed 0] [--cuts link,state,video]
    .venv/bin/python bench/link_loss.py --smoke      # 2 runs (tests/chaos/test_chaos_tello.py calls it)
"""

from __future__ import annotations

import argparse
import io
import random
import socket
import statistics
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))  # bench/machine.py, beside this script
from machine import describe, publish  # noqa: E402

from vlnpilot.core.decision import Decision, PilotInput  # noqa: E402
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode  # noqa: E402
from vlnpilot.robots.emulator import EmulatorConfig, TelloEmulator  # noqa: E402
from vlnpilot.robots.operator import ConsoleOperator  # noqa: E402
from vlnpilot.robots.tello import TelloEnv  # noqa: E402
from vlnpilot.robots.tello_config import load_tello_config  # noqa: E402
from vlnpilot.tasks.task import parse_query  # noqa: E402

LOOPBACK = "127.0.0.1"
LAND_WITHIN_S = {"link": 2.0, "state": 2.0, "video": 3.0}  # the cut's silence limit and a second to spare
MOVES = ("B1", "A2", "B2", "A1")  # all allowed while searching an object; no reversal for the guard to veto
MAX_KILL_STEP, MAX_DELAY_S = 6, 1.5
PILOT_VERBS = ("forward", "cw", "ccw")  # the SDK commands of MOVES (A1 is an rc pulse)


def free_port(host: str = LOOPBACK) -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind((host, 0))
        return s.getsockname()[1]


def local_ports() -> tuple[int, int]:
    """Our reply and state ports: djitellopy binds them once per process, so every run (and a test) shares them."""
    import djitellopy.tello as dt

    if not dt.threads_initialized:
        dt.Tello.CONTROL_UDP_PORT, dt.Tello.STATE_UDP_PORT = free_port(""), free_port("")
    return dt.Tello.CONTROL_UDP_PORT, dt.Tello.STATE_UDP_PORT


def motions(received: list[tuple[float, str]]) -> int:
    """The pilot's moves as the emulator received them: SDK moves and rc pulses (not their stops)."""
    return sum(1 for _, c in received if c.split()[0] in PILOT_VERBS or (c.startswith("rc ") and c != "rc 0 0 0 0"))


class Killer:
    """At step `step` the pilot answers at once and the emulator dies `delay_s` later (wall clock); `asked` holds
    when each answer was given, to find the steps asked after the death."""

    name, model, privileged = "link-killer", "link-killer-1", False

    def __init__(self, emulator: TelloEmulator, step: int, delay_s: float, cut: str = "link"):
        self.emulator, self.step, self.delay_s, self.cut = emulator, step, delay_s, cut
        self.death: float | None = None
        self.received_at_death = 0
        self.asked: list[float] = []

    def decide(self, pilot_input: PilotInput) -> Decision:
        if pilot_input.step == self.step:
            threading.Thread(target=self._kill, daemon=True).start()
        self.asked.append(time.monotonic())
        move = MOVES[(pilot_input.step - 1) % len(MOVES)]
        return Decision(room="living_room", movement=move, state="Search Object", description="searching")

    def _kill(self) -> None:
        time.sleep(self.delay_s)
        self.death = time.monotonic()  # before close: the state and video threads stop within 0.1 s after it
        self.received_at_death = motions(list(self.emulator.log.received))
        if self.cut == "video":
            self.emulator.video.stop()
        elif self.cut == "state":
            self.emulator.faults.state_silent = True
        else:
            self.emulator.close()


@dataclass
class Run:
    cut: str
    kill_step: int
    delay_s: float
    outcome: str
    steps: int
    to_land_s: float | None
    recorded_moves: int
    moves_at_death: int
    executed_after: int  # steps asked after the death that are recorded as executed
    moves_received: int  # by the emulator in all: with one channel cut, commands still reach it

    @property
    def ok(self) -> bool:
        landed = (self.outcome == "link_lost" and self.to_land_s is not None
                  and self.to_land_s <= LAND_WITHIN_S[self.cut])
        if self.cut != "link":  # commands still reach the drone until the watchdog lands it: no move it did not get
            return landed and self.recorded_moves <= self.moves_received
        return landed and self.recorded_moves <= self.moves_at_death and self.executed_after == 0


def fly(kill_step: int, delay_s: float, cut: str = "link") -> Run:
    local_port, state_port = local_ports()
    emu_cfg = EmulatorConfig(host=LOOPBACK, port=free_port(), state_port=state_port, video_port=free_port())
    emu = TelloEmulator("cabin", emu_cfg, spawn="living_room")
    host, port = emu.address
    config = load_tello_config(host=host, command_port=port, local_port=local_port, state_port=state_port,
                               video_port=emu_cfg.video_port)
    env = TelloEnv("cabin", config, handle_sigint=False, operator=ConsoleOperator(io.StringIO(), io.StringIO()))
    killer = Killer(emu, kill_step, delay_s, cut)
    records: list[dict] = []
    try:
        task = parse_query("Go to the bedroom", env.scene)
        result = run_episode(env, killer, task, EpisodeConfig(max_steps=kill_step + 5, shield="assist"),
                             spawn="living_room", on_step=records.append)
    finally:
        env.close()  # lets the watchdog's landing sequence finish
        emu.close()
    land = next((t for t, c in env.watchdog.sent if c == "land"), None) if env.watchdog else None
    death = killer.death
    to_land = round(land - death, 3) if land is not None and death is not None else None
    recorded = sum(1 for r in records if r["executed"] not in (None, "E"))
    after = sum(1 for r, t in zip(records, killer.asked, strict=False)
                if death is not None and t > death and r["executed"] not in (None, "E"))
    return Run(cut, kill_step, round(delay_s, 2), result.outcome, result.steps, to_land, recorded,
               killer.received_at_death, after, motions(list(emu.log.received)))


def table(runs: list[Run], seed: int, cut: str) -> str:
    lines = [f"### Cut: `{cut}`", "", "| run | cut at step | delay (s) | outcome | steps | land after the cut (s) | "
             "moves recorded / sent at the cut / received in all | executed after the cut | ok |",
             "|---|---|---|---|---|---|---|---|---|"]
    for i, r in enumerate(runs, 1):
        land = "-" if r.to_land_s is None else f"{r.to_land_s:.2f}"
        lines.append(f"| {i} | {r.kill_step} | {r.delay_s:.2f} | {r.outcome} | {r.steps} | {land} | "
                     f"{r.recorded_moves} / {r.moves_at_death} / {r.moves_received} | {r.executed_after} | "
                     f"{'yes' if r.ok else 'NO'} |")
    times = [r.to_land_s for r in runs if r.to_land_s is not None]
    median = f"{statistics.median(times):.2f}" if times else "-"
    worst = f"{max(times):.2f}" if times else "-"
    lines += ["", f"{len(runs)} runs (seed {seed}): {sum(r.ok for r in runs)} passed; time from the cut "
              f"to `land`: median {median} s, max {worst} s (limit {LAND_WITHIN_S[cut]:g} s).", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--cuts", default="link,state,video", help="which channels to cut: link, state, video")
    parser.add_argument("--smoke", action="store_true", help="2 runs, nothing written (for a test)")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "link_loss.md")
    args = parser.parse_args(argv)
    cuts = [c.strip() for c in args.cuts.split(",") if c.strip()]
    unknown = sorted(set(cuts) - set(LAND_WITHIN_S))
    if unknown or not cuts:
        print(f"unknown cut {', '.join(unknown) or '(none)'}; valid cuts: {', '.join(LAND_WITHIN_S)}", file=sys.stderr)
        return 2
    count = 2 if args.smoke else args.runs
    tables, passed = [], True
    for cut in ["link"] if args.smoke else cuts:
        rng = random.Random(args.seed)  # the same steps and delays for every cut
        plan = [(rng.randint(1, MAX_KILL_STEP), rng.uniform(0.0, MAX_DELAY_S)) for _ in range(count)]
        runs = [fly(step, delay, cut) for step, delay in plan]
        tables.append(table(runs, args.seed, cut))
        passed = passed and all(r.ok for r in runs)
    publish("\n".join(tables) + f"\nMachine: {describe()}.\n", args.out, smoke=args.smoke)
    return 0 if passed else 1


if __name__ == "__main__":
    raise SystemExit(main())
