"""Chaos: one channel of the Tello's link fails while the others live, the operator or the battery do not wait,
`land` is refused, replies come late, Ctrl-C or SIGHUP come mid-flight (an outside audit of the backend).

Everything against the emulator on 127.0.0.1 (`loopback_only` fails a test whose sockets target any other
address). The emulator's `faults` switch a failure on mid-flight. The waits poll for an outcome with a generous
bound; nothing asserts how long anything took.
"""

from __future__ import annotations

import io
import os
import signal
import threading

import pytest

from polling import wait_for
from tello_support import loopback_only, rig  # noqa: F401  (loopback_only: autouse)
from vlnpilot.cli import _sigterm_interrupts
from vlnpilot.core.errors import LinkLost, RobotHalt
from vlnpilot.robots.operator import ConsoleOperator

pytestmark = pytest.mark.chaos

FAST_LANDING = {"land_confirm_s": 1.5}  # `land` resent for 1.5 s, then emergency: the tests need not wait 5 s


class NoWaiting(ConsoleOperator):
    def __init__(self) -> None:
        super().__init__(io.StringIO(), io.StringIO())

    def wait(self, message: str, until: object = None) -> None:
        raise AssertionError(f"the operator was asked to wait: {message}")


@pytest.mark.parametrize(("cut", "words"), [
    ("video", "no video frame for"),  # the pilot would fly blind on the last frame
    ("state", "no state packet for"),  # no height, heading or battery
])
def test_one_channel_that_dies_in_flight_lands_the_drone_and_ends_link_lost(cut: str, words: str) -> None:
    with rig(operator=NoWaiting()) as (emu, env):
        env.reset("living_room")
        env.step("B1")
        if cut == "video":
            emu.video.stop()  # the stream stops; commands and state packets go on
        else:
            emu.faults.state_silent = True
        assert env.watchdog is not None and wait_for(lambda: env.watchdog.lost, timeout=20)
        with pytest.raises(LinkLost, match=words) as halt:
            env.step("A2")
        assert not halt.value.executed and "forward 25" not in emu.log.executed
        assert wait_for(lambda: "land" in emu.log.events, timeout=20)


def test_a_land_the_drone_refuses_is_resent_and_then_ends_in_emergency() -> None:
    with rig(operator=NoWaiting(), backend=FAST_LANDING) as (emu, env):
        env.reset("living_room")
        emu.faults.refuse = {"land"}  # answered "error", not carried out
        env.land()
        env.close()  # lets the landing sequence finish
        kinds = [e["event"] for e in env.events]
        assert "land_unconfirmed" in kinds and "emergency" in kinds
        landings = [c for _, c in emu.log.received if c == "land"]
        assert len(landings) >= 3  # its ask, then the watchdog's, resent every second
        assert "emergency" in emu.log.events and env.watchdog is not None and env.watchdog.landed is False


def test_a_land_confirmed_by_the_state_packets_needs_no_ok() -> None:
    with rig(operator=NoWaiting()) as (emu, env):
        env.reset("living_room")
        emu.faults.late = {"land": 30.0}  # the drone lands, its "ok" does not come
        env.land()
        assert [e["event"] for e in env.events][-1] == "land" and "emergency" not in emu.log.events


def test_an_rc_pulse_whose_commands_no_longer_reach_the_drone_is_not_flown() -> None:
    """A state packet after a pulse shows that the drone's packets reach us, not that ours reach it."""
    with rig(operator=NoWaiting(), backend=FAST_LANDING) as (emu, env):
        env.reset("living_room")
        pose = env._pose
        emu.faults.lose = {"rc", "battery?", "land", "emergency"}  # the uplink dies; state and video live on
        with pytest.raises(LinkLost, match="commands do not reach the drone") as halt:
            env.step("A1")
        assert not halt.value.executed and halt.value.observation.pose == pose


def test_a_late_reply_is_not_taken_for_the_next_commands() -> None:
    with rig(operator=NoWaiting(), backend={"reply_timeout_s": 1.0}) as (emu, env):
        env.reset("living_room")
        emu.faults.late = {"cw": 1.6}  # its "ok" comes 0.6 s after the backend stopped waiting
        env.step("B1")  # judged from the yaw
        emu.faults.late, emu.faults.lose = {}, {"forward"}  # the next move never reaches the drone
        with pytest.raises(RobotHalt, match="no reply to 'forward 25'") as halt:
            env.step("A2")
        assert not halt.value.executed and "forward 25" not in emu.log.executed
        assert "battery?" in [c for _, c in emu.log.received]  # the link found its replies again first
        env.awaiting_operator = False  # the test is the operator: land


def test_a_drone_that_landed_by_itself_is_not_flown_on() -> None:
    with rig(operator=NoWaiting()) as (emu, env):
        env.reset("living_room")
        emu._land("auto_land")  # as when this computer slept for more than 15 s
        assert wait_for(lambda: env.link is not None and str(env.link.state().get("h")) == "0")
        with pytest.raises(RobotHalt, match="on the ground") as halt:
            env.step("A2")
        assert not halt.value.executed and "forward 25" not in [c for _, c in emu.log.received]
        assert env.events[-1]["event"] == "auto_landed"


def test_the_battery_floor_lands_the_drone_while_the_pilot_thinks() -> None:
    with rig(operator=NoWaiting()) as (emu, env):
        env.reset("living_room")
        emu.battery = 12.0  # below the floor of 15 %, between two steps
        assert env.watchdog is not None and wait_for(lambda: env.watchdog.lost, timeout=20)
        assert env.watchdog.cause == "battery_low" and wait_for(lambda: "land" in emu.log.events)
        with pytest.raises(RobotHalt, match="below the landing floor of 15 %") as halt:
            env.step("A2")
        assert not isinstance(halt.value, LinkLost) and halt.value.landed


def test_ctrl_c_during_an_rc_pulse_stops_it_and_lands_until_the_drone_is_down() -> None:
    with rig(operator=NoWaiting(), handle_sigint=True, backend=FAST_LANDING) as (emu, env):
        env.reset("living_room")
        emu.faults.lose = {"land"}  # every `land` is lost: the drone is not down, emergency follows
        timer = threading.Timer(0.2, os.kill, (os.getpid(), signal.SIGINT))  # 0.2 s into the 0.5 s pulse
        timer.start()
        with pytest.raises(KeyboardInterrupt):
            env.step("A1")
        env.close()
        received = [c for _, c in emu.log.received]
        assert received.index("rc 0 0 0 0") > received.index("rc 0 20 0 0")  # the pulse was stopped
        assert emu.log.lost.count("land") >= 2 and "emergency" in emu.log.events


def test_ctrl_c_while_the_event_lock_is_held_does_not_deadlock() -> None:
    with rig(operator=NoWaiting(), handle_sigint=True) as (_emu, env):
        env.reset("living_room")
        with env._event_lock, pytest.raises(KeyboardInterrupt):  # the main thread inside `_event`
            env._on_sigint(signal.SIGINT, None)
        assert env.events[-1] == {**env.events[-1], "event": "operator_interrupt", "action": "land"}


def test_sighup_is_handled_as_ctrl_c() -> None:
    with _sigterm_interrupts(), pytest.raises(KeyboardInterrupt):
        os.kill(os.getpid(), signal.SIGHUP)
        threading.Event().wait(5)  # the signal arrives between two bytecodes of this thread
    assert signal.getsignal(signal.SIGHUP) is signal.SIG_DFL


def test_the_operators_wait_ends_when_the_drone_is_landed_without_them() -> None:
    read_end, write_end = os.pipe()
    try:
        with os.fdopen(read_end, closefd=False) as answers:
            out, landed = io.StringIO(), threading.Event()
            threading.Timer(0.1, landed.set).start()
            ConsoleOperator(answers, out).wait("Press Enter to land it.", until=landed)  # nobody presses Enter
            assert "no longer waiting" in out.getvalue()
    finally:
        os.close(read_end)
        os.close(write_end)
