"""Cost of the live ground station: the extra time per step of an episode watched by a connected page.

Flies the oracle's "Go to the bathroom" from the living room (recorded, as `vln-pilot run` does), alternately
without the station and with it and a page connected (headless Chromium when /usr/bin/chromium exists, else a
Server-Sent Events client), and prints the median time per step of each and their difference. Aim: <= 5 ms.

    .venv/bin/python bench/live_cost.py [--reps 5] [--client chromium|sse] [--smoke]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import statistics
import tempfile
import threading
import time
from pathlib import Path

from machine import describe  # bench/machine.py, beside this script

from vlnpilot.core.rundir import Recorder
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.live.control import LiveControl
from vlnpilot.live.station import LiveStation
from vlnpilot.pilots.oracle import OraclePilot
from vlnpilot.sim import Simulator
from vlnpilot.tasks.task import parse_query

CHROMIUM = Path("/usr/bin/chromium")
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking", "--no-first-run"]


def step_times(sim: Simulator, run_dir: Path, control: LiveControl | None, pilot: OraclePilot,
               max_steps: int = 60) -> list[float]:
    """Seconds between consecutive step records (the first step is measured from the episode's start)."""
    stamps = [time.perf_counter()]
    recorder = Recorder(run_dir)
    task = parse_query("Go to the bathroom", sim.scene)
    run_episode(sim, pilot, task, EpisodeConfig(max_steps=max_steps), spawn="living_room", recorder=recorder,
                on_step=lambda _rec: stamps.append(time.perf_counter()), control=control)
    return [b - a for a, b in zip(stamps[1:], stamps[2:], strict=False)]  # the first includes reset and start


def thread_cpu_s(native_id: int) -> float:
    """CPU seconds (user + system) a thread of this process has used, from /proc (Linux)."""
    fields = open(f"/proc/self/task/{native_id}/stat").read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


@contextlib.contextmanager
def connected_page(url: str, client: str):
    """A page (Chromium) or a bare SSE reader connected to the station for the duration."""
    if client == "chromium":
        from playwright.sync_api import sync_playwright

        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=ARGS)
            page = browser.new_page(viewport={"width": 1400, "height": 1000})
            page.goto(url)
            page.wait_for_function("() => document.getElementById('conn').textContent === 'live'")
            yield
            browser.close()
        return
    import httpx

    stop = threading.Event()

    def read() -> None:
        with httpx.stream("GET", f"{url}api/events", timeout=60) as r:
            for _ in r.iter_lines():
                if stop.is_set():
                    return

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    yield
    stop.set()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reps", type=int, default=5)
    parser.add_argument("--client", choices=("chromium", "sse"), default="chromium" if CHROMIUM.exists() else "sse")
    parser.add_argument("--smoke", action="store_true", help="1 repetition of 4 steps, SSE client (for the tests)")
    args = parser.parse_args()
    if args.smoke:
        args.reps, args.client = 1, "sse"
    steps = 4 if args.smoke else 60
    plain: list[float] = []
    live: list[float] = []
    server_cpu = 0.0
    with Simulator("cabin") as sim, tempfile.TemporaryDirectory() as tmp:
        pilot = OraclePilot()
        step_times(sim, Path(tmp) / "warm", None, pilot, steps)  # warm-up: renderers, caches
        for rep in range(args.reps):
            plain += step_times(sim, Path(tmp) / f"plain-{rep}", None, pilot, steps)
            run_dir = Path(tmp) / f"live-{rep}"
            control = LiveControl(pilot)
            with LiveStation(run_dir, control=control, scene=sim.scene, port=0) as station, \
                    connected_page(station.url, args.client):
                cpu0 = thread_cpu_s(station.native_id)
                live += step_times(sim, run_dir, control, pilot, steps)
                time.sleep(0.5)  # let the page take the last step before it closes
                server_cpu += thread_cpu_s(station.native_id) - cpu0
            control.finish()
    p, q = statistics.median(plain), statistics.median(live)
    print(f"steps: {len(plain)} without the station, {len(live)} with it and a {args.client} page connected")
    print(f"median time per step: {p * 1000:.2f} ms without, {q * 1000:.2f} ms with; extra {(q - p) * 1000:.2f} ms"
          f" (aim <= 5 ms)")
    print(f"the station's own thread (HTTP, SSE, frames): {server_cpu / len(live) * 1000:.2f} ms CPU per step")
    print(f"machine: {describe()}")


if __name__ == "__main__":
    main()
