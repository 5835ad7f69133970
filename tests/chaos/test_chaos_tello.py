"""Chaos: the Tello's link dies, replies and commands are lost, settings do not match (issue 26, items 1-4).

Everything against the emulator on 127.0.0.1 (`loopback_only` fails a test whose sockets target any other
address). The watchdog's timing is driven by a manual clock (`link_clock`); nothing here asserts wall time.
"""

from __future__ import annotations

import io
import threading
from pathlib import Path

import pytest
import yaml

from cli_support import run_main
from polling import wait_for
from tello_support import emulator_config, loopback_only, rig, tello_config  # noqa: F401  (loopback_only: autouse)
from vlnpilot.core.decision import Decision, PilotInput
from vlnpilot.core.errors import ConfigError, LinkLost, RobotHalt
from vlnpilot.core.exits import BAD_INPUT, LINK_FAULT, OK, PILOT_ERROR, error_exit_code, exit_code_for
from vlnpilot.core.rundir import Recorder, load_run
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.pilots.base import make_pilot
from vlnpilot.robots.clock import ManualClock
from vlnpilot.robots.emulator import TelloEmulator
from vlnpilot.robots.operator import ConsoleOperator
from vlnpilot.robots.tello_config import load_tello_config
from vlnpilot.robots.tello_link import LinkError, RobotError
from vlnpilot.robots.tello_watchdog import POLL_S, LinkWatchdog
from vlnpilot.sim import SimConfig, Simulator
from vlnpilot.tasks.task import parse_query

pytestmark = pytest.mark.chaos

SILENCE_S, CONFIRM_S = 1.0, 5.0


class NoWaiting(ConsoleOperator):
    """An operator at a terminal who must not be asked to press Enter (after a link loss nobody waits)."""

    def __init__(self) -> None:
        super().__init__(io.StringIO(), io.StringIO())

    def wait(self, message: str, until: object = None) -> None:
        raise AssertionError(f"the operator was asked to wait: {message}")


# -- the watchdog alone, on a manual clock ----------------------------------------------------------------------
class FakePort:
    """The watchdog's view of a link: counters the test moves, and what the watchdog sent."""

    def __init__(self, clock: ManualClock):
        self.clock, self.lost = clock, threading.Event()
        self.counts = [0, 0, 0]  # state packets, frames, replies
        self.sent: list[tuple[float, str]] = []
        self.replies: list[str] = []
        self.grounded = False  # what the newest state packet shows

    def evidence(self) -> tuple[int, int, int]:
        return tuple(self.counts)  # type: ignore[return-value]

    def on_ground(self) -> bool:
        return self.grounded

    def emergency_send(self, command: str) -> None:
        self.sent.append((self.clock.now(), command))

    def poll_reply(self) -> str | None:
        return self.replies.pop(0) if self.replies else None


def _watchdog(tick: float = 0.05) -> tuple[ManualClock, FakePort, LinkWatchdog]:
    clock = ManualClock(tick=tick)
    port = FakePort(clock)
    dog = LinkWatchdog(port, clock, silence_s=SILENCE_S, land_confirm_s=CONFIRM_S)
    dog.start()
    return clock, port, dog


def _live(clock: ManualClock, port: FakePort, seconds: float, channels: tuple[int, ...] = (0, 1)) -> None:
    """`seconds` of the drone's state packets (10 Hz) and video frames, or of the `channels` given, arriving."""
    for _ in range(round(seconds / 0.1)):
        for channel in channels:
            port.counts[channel] += 1
        clock.sleep(0.1)


def test_the_watchdog_lands_within_one_silence_limit_of_the_last_sign_of_life() -> None:
    clock, port, dog = _watchdog()
    try:
        _live(clock, port, 3.0)  # 10 Hz state packets and the video: alive
        assert not dog.lost and port.sent == []
        death = clock.now()
        clock.sleep(SILENCE_S - 0.1)
        assert not dog.lost  # ten packets missing is not yet a death
        clock.sleep(0.3)
        assert dog.lost and port.lost.is_set()
        first_land, command = port.sent[0]
        assert command == "land" and first_land - death <= SILENCE_S + 2 * POLL_S
    finally:
        dog.close(timeout=0)


def test_state_packets_and_video_alive_keep_the_link_alive_without_replies() -> None:
    clock, port, dog = _watchdog()
    try:
        _live(clock, port, 5.0, (0, 1))  # no command answered for 5 s: the pilot is thinking
        assert not dog.lost and port.sent == []
    finally:
        dog.close(timeout=0)


@pytest.mark.parametrize(("alive", "silent_s", "words"), [
    ((1, 2), SILENCE_S, "no state packet for"),  # frames and replies, but no height, heading or battery
    ((0, 2), 2 * SILENCE_S, "no video frame for"),  # state packets, but the pilot would fly blind
], ids=["state stream dies", "video dies"])
def test_one_channel_the_drone_is_flown_on_going_silent_lands_it(alive: tuple[int, ...], silent_s: float,
                                                                 words: str) -> None:
    clock, port, dog = _watchdog()
    try:
        _live(clock, port, 2.0, (0, 1, 2))
        _live(clock, port, silent_s - 0.2, alive)
        assert not dog.lost
        _live(clock, port, 0.4, alive)
        assert dog.lost and words in dog.reason and dog.cause == "link"
        assert [c for _, c in port.sent][:1] == ["land"]
    finally:
        dog.close(timeout=0)


def test_a_limit_passed_between_steps_lands_the_drone_from_the_watchdog() -> None:
    """The battery does not wait for a slow pilot or operator: the watchdog checks the limits between steps."""
    clock = ManualClock()
    port = FakePort(clock)
    battery = [50]
    dog = LinkWatchdog(port, clock, silence_s=SILENCE_S, land_confirm_s=CONFIRM_S,
                       limits=lambda: ("battery_low", "battery at 12 %") if battery[0] < 15 else None)
    dog.start()
    try:
        _live(clock, port, 1.0, (0, 1))
        assert not dog.lost
        battery[0] = 12
        _live(clock, port, 0.3, (0, 1))
        assert dog.lost and dog.cause == "battery_low" and [c for _, c in port.sent] == ["land"]
        port.grounded = True  # the state packets show it down: no emergency, whatever the replies
        _live(clock, port, CONFIRM_S + 1.0, (0, 1))
        assert dog.done.is_set() and dog.landed and [c for _, c in port.sent] == ["land"]
    finally:
        dog.close(timeout=0)


def test_an_error_to_land_is_no_landing() -> None:
    clock, port, dog = _watchdog()
    _live(clock, port, 1.0)
    clock.sleep(SILENCE_S + 0.2)
    port.replies.append("error")
    clock.sleep(CONFIRM_S + 0.5)
    assert dog.done.is_set() and not dog.landed
    assert [c for _, c in port.sent][-1] == "emergency"


def test_an_unanswered_land_is_resent_then_followed_by_emergency() -> None:
    clock, port, dog = _watchdog()
    _live(clock, port, 1.0)
    clock.sleep(SILENCE_S + CONFIRM_S + 0.5)
    assert dog.done.is_set()
    commands = [c for _, c in port.sent]
    assert commands == ["land"] * 5 + ["emergency"]  # every second while unanswered, then motors off
    assert port.sent[-1][0] - port.sent[0][0] == pytest.approx(CONFIRM_S, abs=POLL_S)


def test_an_answered_land_is_not_followed_by_emergency() -> None:
    clock, port, dog = _watchdog()
    _live(clock, port, 1.0)
    clock.sleep(SILENCE_S + 0.2)
    assert [c for _, c in port.sent] == ["land"]
    port.replies.append("ok")
    clock.sleep(CONFIRM_S + 1.0)
    assert dog.done.is_set() and [c for _, c in port.sent] == ["land"]


def test_time_the_watchdog_did_not_run_is_not_counted_as_silence() -> None:
    """A starved process wakes late: what it did not watch is no evidence that the link died."""
    clock, port, dog = _watchdog(tick=3.0)  # one tick jumps 3 s: the watchdog sleeps through them
    try:
        clock.sleep(3.0)
        assert not dog.lost
        clock.tick = 0.05
        clock.sleep(SILENCE_S - 0.2)
        assert not dog.lost
        clock.sleep(0.4)  # silence it watched on schedule: now it is a death
        assert dog.lost
    finally:
        dog.close(timeout=0)


# -- the backend against the emulator ----------------------------------------------------------------------------
def test_a_dead_link_lands_sends_nothing_else_and_executes_nothing() -> None:
    dog_clock = ManualClock()
    with rig(link_clock=dog_clock, operator=NoWaiting()) as (emu, env):
        env.reset("living_room")
        env.step("B1")
        assert env.watchdog is not None and not env.watchdog.lost
        sent_before = len(env.link.sent)
        emu.close()  # the emulator dies: no more state packets, frames or replies
        death = dog_clock.now()
        dog_clock.sleep(SILENCE_S + 0.5)
        assert env.watchdog.lost
        first_land = env.watchdog.sent[0]
        assert first_land[1] == "land" and first_land[0] - death <= SILENCE_S + 3 * POLL_S
        pose = env._pose
        with pytest.raises(LinkLost, match="link to the Tello is lost") as halt:
            env.step("A2")  # the pilot's next move: refused before anything is sent
        assert halt.value.outcome == "link_lost" and not halt.value.executed
        assert not halt.value.observation.executed and halt.value.observation.pose == pose  # no dead reckoning
        dog_clock.sleep(CONFIRM_S + 0.5)  # no reply to `land`: emergency
        after = env.link.sent[sent_before:]
        assert set(after) == {"land", "emergency"} and after[-1] == "emergency"
        env.close()  # nobody is asked to press Enter (NoWaiting), nothing more is sent
        assert env.link.sent[sent_before:] == after


class KillingPilot:
    """Flies `moves` in turn (searching an object: they are all allowed); at step `kill_at` it kills the emulator,
    then asks for its move all the same."""

    name, model = "killer", "killer-1"

    def __init__(self, emulator: TelloEmulator, kill_at: int, moves: tuple[str, ...] = ("B1", "A2", "B1", "A1")):
        self.emulator, self.kill_at, self.moves = emulator, kill_at, moves

    def decide(self, pilot_input: PilotInput) -> Decision:
        if pilot_input.step == self.kill_at:
            self.emulator.close()
        move = self.moves[(pilot_input.step - 1) % len(self.moves)]
        return Decision(room="living_room", movement=move, state="Search Object", description="flying on")


def test_an_episode_whose_link_dies_ends_link_lost_with_no_move_executed_after_it(tmp_path: Path) -> None:
    with rig(operator=NoWaiting()) as (emu, env):
        task = parse_query("Go to the bedroom", env.scene)
        result = run_episode(env, KillingPilot(emu, kill_at=4), task, EpisodeConfig(max_steps=10, shield="assist"),
                             spawn="living_room", recorder=Recorder(tmp_path, save_frames=False))
        moved = list(emu.log.executed)
    assert result.outcome == "link_lost" and result.steps == 4, result.reason
    summary, steps = load_run(tmp_path)
    assert summary["result"]["outcome"] == "link_lost"
    assert [s["executed"] for s in steps] == ["B1", "A2", "B1", None]  # the move after the death: not executed
    assert steps[-1]["pose_after"] == steps[-1]["pose_before"]  # and the estimated pose did not advance
    assert moved[1:] == ["cw 15", "forward 25", "cw 15"]  # after "up 20": what the emulator flew
    events = [e["event"] for e in steps[-1]["robot"]["events"]]
    assert "link_lost" in events
    assert "land" in env.link.sent[-6:]


@pytest.fixture(scope="module")
def sim_runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Oracle runs on the simulator: one with the Tello's `assist` shield, one as `vln-pilot run` flies by default."""
    runs = {}
    for shield in ("assist", "geometry"):
        run_dir = tmp_path_factory.mktemp(f"sim-{shield}")
        with Simulator("cabin", SimConfig(render=False)) as sim:
            task = parse_query("Go to the bedroom", sim.scene)
            run_episode(sim, make_pilot("oracle"), task, EpisodeConfig(shield=shield), spawn="living_room",
                        recorder=Recorder(run_dir, save_frames=False))
        runs[shield] = run_dir
    return runs


def _settings(tmp_path: Path, emu: TelloEmulator, monkeypatch: pytest.MonkeyPatch) -> None:
    settings = tmp_path / "tello.yaml"
    fast = {"calibration": {side: {"speed": 20, "duration_s": 0.5, "settle_s": 0.0}
                            for side in ("forward_10cm", "left_10cm", "right_10cm")} | {"move_settle_s": 0.0}}
    settings.write_text(yaml.safe_dump(tello_config(emu, **fast).model_dump(exclude={"host"})))
    monkeypatch.setenv("VLN_PILOT_TELLO_CONFIG", str(settings))


def _motions(emu: TelloEmulator) -> list[str]:
    """The pilot's moves the emulator received: SDK moves and rotations, and rc pulses (not their stops)."""
    return [c for _, c in emu.log.received if c.split()[0] in ("forward", "cw", "ccw")
            or (c.startswith("rc ") and c != "rc 0 0 0 0")]


def test_the_command_line_exits_with_the_link_fault_code_when_the_link_dies(sim_runs, tmp_path: Path, monkeypatch,
                                                                            capsys) -> None:
    with TelloEmulator("cabin", emulator_config(), spawn="living_room") as emu:
        _settings(tmp_path, emu, monkeypatch)
        killer = threading.Thread(target=lambda: wait_for(lambda: len(_motions(emu)) >= 4, 120) and emu.close())
        killer.start()
        out = tmp_path / "run"
        code, stdout, err = run_main(monkeypatch, capsys, "run", "Go to the bedroom", "--robot", "tello",
                                     "--tello-host", "127.0.0.1", "--pilot", f"replay:{sim_runs['assist']}",
                                     "--out", str(out), "--no-video", "--quiet")
        killer.join()
        flown = len(_motions(emu))
    assert code == LINK_FAULT, err
    assert "link_lost" in stdout and "Press Enter" not in err
    summary, steps = load_run(out)
    assert summary["result"]["outcome"] == "link_lost"
    executed = [s["executed"] for s in steps if s["executed"] not in (None, "E")]
    assert len(executed) <= flown and steps[-1]["executed"] is None


def test_exit_codes_of_link_faults() -> None:
    assert exit_code_for(["success", "link_lost", "pilot_error"]) == LINK_FAULT
    assert exit_code_for(["pilot_error"]) == PILOT_ERROR and exit_code_for(["halted"]) == OK
    assert error_exit_code(LinkError("no reply")) == LINK_FAULT
    assert error_exit_code(RobotError("battery low")) == BAD_INPUT == error_exit_code(ConfigError("bad"))


# -- item 2: every setting that can be checked on the ground, before take-off ---------------------------------
def test_a_replay_of_a_default_sim_run_is_refused_before_take_off(sim_runs, tmp_path: Path, monkeypatch,
                                                                  capsys) -> None:
    """The README's example: `--pilot replay:` of a run flown with the simulator's default shield (geometry)."""
    with TelloEmulator("cabin", emulator_config(), spawn="living_room") as emu:
        _settings(tmp_path, emu, monkeypatch)
        code, _, err = run_main(monkeypatch, capsys, "run", "Go to the bedroom", "--robot", "tello",
                                "--tello-host", "127.0.0.1", "--pilot", f"replay:{sim_runs['geometry']}",
                                "--out", str(tmp_path / "run"), "--no-video", "--quiet")
        received = [c for _, c in emu.log.received]
    assert code == BAD_INPUT and len(err.strip().splitlines()) == 1, err
    # The replay asks for the shield it was flown with, which a Tello cannot have: refused, naming the valid ones.
    assert "--shield geometry needs ground truth" in err and "valid shields here: off, assist" in err
    assert received == []  # not even `command`: nothing was sent before the refusal


def test_a_library_run_with_a_mismatched_replay_never_takes_off(sim_runs) -> None:
    with rig() as (emu, env):
        task = parse_query("Go to the bedroom", env.scene)
        with pytest.raises(ConfigError, match="--shield geometry"):
            run_episode(env, make_pilot(f"replay:{sim_runs['geometry']}"), task, EpisodeConfig(shield="assist"),
                        spawn="living_room")
        assert "takeoff" not in [c for _, c in emu.log.received] and env.link is None


# -- item 3: start-up under lost replies -----------------------------------------------------------------------
def test_a_lost_takeoff_reply_is_waited_on_well_inside_the_tellos_auto_land() -> None:
    assert load_tello_config().takeoff_timeout_s <= 10  # the Tello lands by itself after 15 s without a command
    with pytest.raises(ConfigError, match="takeoff_timeout_s"):
        load_tello_config(takeoff_timeout_s=20)
    with rig(emulator={"drop_verbs": ("takeoff",)}, backend={"takeoff_timeout_s": 0.5}) as (emu, env):
        obs = env.reset("living_room")  # airborne by the state packets: it flies on
        assert emu.flying and obs.pose.z > 0.5
        assert any(e["event"] == "lost_reply" and e["command"] == "takeoff" for e in env.events)


def test_a_lost_streamon_reply_is_resent() -> None:
    with rig(emulator={"drop_first": ("streamon",)}) as (emu, env):
        env.reset("living_room")
        assert env.link.sent.count("streamon") == 2 and emu.flying
        assert any(e["event"] == "lost_reply" and e["command"] == "streamon" for e in env.events)


def test_streamon_never_answered_is_a_link_fault_not_the_firmware() -> None:
    with rig(emulator={"drop_verbs": ("streamon",)}, backend={"connect_timeout_s": 0.3}) as (emu, env):
        with pytest.raises(LinkError, match="no reply to 'streamon' in 3 tries") as error:
            env.reset("living_room")
        assert "firmware" not in str(error.value) and error_exit_code(error.value) == LINK_FAULT
        assert "takeoff" not in [c for _, c in emu.log.received]


def test_the_emulators_drop_pattern_is_seeded_from_the_command_line(monkeypatch, capsys) -> None:
    from vlnpilot.robots import session

    seen = []
    monkeypatch.setattr(session, "serve_emulator", lambda scene, spawn, config, say: seen.append(config))
    code, _, err = run_main(monkeypatch, capsys, "tello-emulator", "--drop-replies", "0.3", "--drop-seed", "7")
    assert code == 0, err
    assert seen[0].seed == 7 and seen[0].drop_replies == 0.3


# -- item 4: a rotation that did not happen is not executed -----------------------------------------------------
def test_a_rotation_that_did_not_happen_is_not_recorded_as_executed(tmp_path: Path) -> None:
    with rig(emulator={"lose_verbs": ("cw",)}, backend={"reply_timeout_s": 0.5}, operator=NoWaiting()) as (emu, env):
        task = parse_query("Go to the bedroom", env.scene)
        pilot = KillingPilot(emu, kill_at=0, moves=("B1",))  # never kills: only turns right
        result = run_episode(env, pilot, task, EpisodeConfig(max_steps=2, shield="assist"), spawn="living_room",
                             recorder=Recorder(tmp_path, save_frames=False))
        assert emu.log.lost == ["cw 15", "cw 15"] and "cw 15" not in emu.log.executed
    assert result.outcome == "max_steps"
    _, steps = load_run(tmp_path)
    assert [s["executed"] for s in steps] == [None, None]
    assert all(s["pose_after"] == s["pose_before"] for s in steps)
    assert "did not happen" in steps[0]["robot"]["events"][-1]["action"]


def test_a_halt_before_the_move_records_nothing_executed() -> None:
    halt = RobotHalt("battery at 14 %")
    assert not halt.executed and halt.outcome == "halted"


def test_the_link_loss_bench_smoke_mode_passes(capsys) -> None:
    """bench/link_loss.py --smoke: two episodes whose emulator is killed end `link_lost`, landed, nothing after."""
    import runpy

    bench = runpy.run_path(str(Path(__file__).parents[2] / "bench" / "link_loss.py"))
    assert bench["main"](["--smoke"]) == 0, capsys.readouterr().out
    assert "2 runs (seed 0): 2 passed" in capsys.readouterr().out
