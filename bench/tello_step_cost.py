"""Wall time of a Tello step through djitellopy against the emulator, and the age of the frame it returns.

Starts the emulator on free loopback ports, connects the Tello backend (default settings of tello.yaml:
video_latency_s 0.8, move_settle_s 0.3, rc pulses 0.5 s + 0.6 s settle), takes off and flies a fixed mix of
commands, then prints per command class the median and p90 of the step's wall time, the median frame age
(decode to return) and how many stale frames were dropped, the start-up time (connect, video, take-off), how
far each 10 cm rc pulse really moved the emulated drone, and the machine. On a real Tello the SDK moves take
longer (the drone flies them; ~1-3 s), so these are the controller's own overheads: mostly the deliberate
wait for a frame decoded after the motion settled.

    .venv/bin/python bench/tello_step_cost.py [--rounds 3] [--smoke]
"""

from __future__ import annotations

import argparse
import socket
import statistics
import time

from machine import describe  # bench/machine.py, beside this script

from vlnpilot.core.commands import get_command
from vlnpilot.robots.emulator import EmulatorConfig, TelloEmulator
from vlnpilot.robots.tello import TelloEnv
from vlnpilot.robots.tello_config import load_tello_config

SEQUENCE = ("A2", "B1", "A1", "C1", "D1", "D2", "E", "B2", "C2", "A2")
CLASSES = {"SDK move (A2/A3)": ("A2", "A3"), "rotation (B/C)": ("B1", "B2", "B3", "C1", "C2", "C3"),
           "rc pulse (A1/D1/D2)": ("A1", "D1", "D2"), "hover (E)": ("E",)}


def free_port(host: str = "127.0.0.1") -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind((host, 0))
        return s.getsockname()[1]


def p90(values: list[float]) -> float:
    s = sorted(values)
    return s[min(len(s) - 1, int(round(0.9 * (len(s) - 1))))]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3, help="times the command mix is flown")
    parser.add_argument("--smoke", action="store_true", help="one round of two commands (for the tests)")
    args = parser.parse_args()
    sequence = SEQUENCE[1:3] if args.smoke else SEQUENCE  # a rotation and an rc pulse
    if args.smoke:
        args.rounds = 1
    state_port = free_port("")
    emu_cfg = EmulatorConfig(port=free_port(), state_port=state_port, video_port=free_port())
    timings: dict[str, list[float]] = {}
    ages: dict[str, list[float]] = {}
    dropped: dict[str, list[int]] = {}
    pulse_errors: list[float] = []
    with TelloEmulator("cabin", emu_cfg, spawn="living_room") as emu:
        host, port = emu.address
        config = load_tello_config(host=host, command_port=port, local_port=free_port(""), state_port=state_port,
                                   video_port=emu_cfg.video_port, geofence_m=50.0)
        env = TelloEnv("cabin", config, handle_sigint=False)
        try:
            t0 = time.perf_counter()
            env.reset("living_room")
            startup = time.perf_counter() - t0
            for _ in range(args.rounds):
                for code in sequence:
                    before = emu.pose
                    t = time.perf_counter()
                    obs = env.step(get_command(code))
                    timings.setdefault(code, []).append(time.perf_counter() - t)
                    if code in CLASSES["rc pulse (A1/D1/D2)"]:  # how far the timed pulse really flew the drone
                        pulse_errors.append(abs(emu.pose.distance_xy(before) - get_command(code).amount))
                    ages.setdefault(code, []).append(obs.info["frame_age_s"])
                    dropped.setdefault(code, []).append(obs.info["frames_dropped"])
        finally:
            env.close()
    print(f"machine: {describe()}; emulator video {emu_cfg.fps:g} fps H.264 640x480")
    print(f"start-up (connect, streamon + decoder probe, take-off, climb, first frame): {startup:.2f} s")
    print(f"{'command class':<22} {'n':>3} {'median s':>9} {'p90 s':>7} {'frame age ms':>13} {'stale dropped':>14}")
    for name, codes in CLASSES.items():
        t = [x for c in codes for x in timings.get(c, [])]
        if not t:
            continue
        a = [x for c in codes for x in ages.get(c, [])]
        d = [x for c in codes for x in dropped.get(c, [])]
        print(f"{name:<22} {len(t):>3} {statistics.median(t):>9.2f} {p90(t):>7.2f} "
              f"{statistics.median(a) * 1000:>13.0f} {statistics.median(d):>14.0f}")
    print(f"rc pulse distance error on the emulator (wall-clock timing over loopback): median "
          f"{statistics.median(pulse_errors) * 1000:.1f} mm, max {max(pulse_errors) * 1000:.1f} mm of 100 mm")


if __name__ == "__main__":
    main()
