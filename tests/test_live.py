"""The live ground station without a browser: control over HTTP, tokens, stale commands, human steps, watch."""

from __future__ import annotations

import asyncio
import json
import sys
import threading
from pathlib import Path
from types import SimpleNamespace

import httpx
import pytest

from live_episode import LiveEpisode
from vlnpilot import cli
from vlnpilot.core.rundir import load_run
from vlnpilot.episode.config import OUTCOMES
from vlnpilot.live import app as live_app
from vlnpilot.live.control import LiveControl, Refused
from vlnpilot.live.feed import RunFeed
from vlnpilot.live.station import LiveStation
from vlnpilot.scene import load_scene


def post(station: LiveStation, body: dict, token: str | None = None) -> httpx.Response:
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    return httpx.post(f"{station.url}api/control", json=body, headers=headers, timeout=10)


def test_control_without_the_token_gets_401_and_changes_nothing(tmp_path: Path) -> None:
    control = LiveControl(pilot=None)  # type: ignore[arg-type]  # no episode: only the messages are under test
    with LiveStation(tmp_path, control=control, port=0, token="s3cret") as station:
        run = tmp_path.name
        before = control.status()
        for token in (None, "wrong"):
            for action in ("pause", "stop", "take_over"):
                r = post(station, {"run": run, "action": action}, token)
                assert r.status_code == 401, r.text
        after = control.status()
        assert (after["paused"], after["stopped"], after["human"]) == (False, False, False)
        assert after["version"] == before["version"]
        assert post(station, {"run": run, "action": "pause"}, "s3cret").json()["paused"] is True
        assert httpx.get(f"{station.url}api/meta", timeout=10).json()["token_required"] is True


def test_off_loopback_needs_a_token(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                    capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.delenv("VLN_LIVE_TOKEN", raising=False)
    monkeypatch.setattr(sys, "argv", ["vln-pilot", "run", "Go to the bathroom", "--live", "--live-host", "0.0.0.0",
                                      "--pilot", "oracle", "--out", str(tmp_path / "r")])
    with pytest.raises(SystemExit) as info:
        cli.main()
    err = capsys.readouterr().err
    assert info.value.code == 2 and len(err.strip().splitlines()) == 1 and "VLN_LIVE_TOKEN" in err
    assert not (tmp_path / "r" / "episode.jsonl").exists()


def test_stale_or_early_commands_are_refused_not_queued() -> None:
    control = LiveControl(pilot=None)  # type: ignore[arg-type]
    with pytest.raises(Refused, match="take over first"):
        control.act("command", step=1, movement="B1", state="Recognize Room")
    control.act("take_over")
    with pytest.raises(Refused, match="no step is waiting"):  # nothing waits yet: the key press is dropped
        control.act("command", step=1, movement="B1", state="Recognize Room")
    with pytest.raises(Refused, match="unknown action"):
        control.act("land")
    control.finish()
    with pytest.raises(Refused, match="over"):
        control.act("resume")


def test_human_steps_are_recorded_and_the_stop_aborts_within_one_step(tmp_path: Path) -> None:
    ep = LiveEpisode(tmp_path / "run")
    try:
        ep.pilot.release(2)
        ep.wait_steps(2)
        ep.control.act("take_over")
        ep.pilot.release(1)  # step 3 is the pilot's: it was already asked when the person took over
        for _ in range(2):
            waiting = ep.wait_status(lambda s: s["waiting"] is not None)["waiting"]
            with pytest.raises(Refused, match="is waiting"):  # a message for another step is never used
                ep.control.act("command", step=waiting["step"] + 1, movement="B1", state=waiting["state"])
            ep.control.act("command", step=waiting["step"], movement="B1", state=waiting["state"])
            ep.wait_steps(waiting["step"])
        ep.control.act("stop")
    finally:
        result = ep.close()
    # the stop came while step 6 waited for the person: step 6 is recorded, nothing more is executed
    assert result is not None and result.outcome == "aborted" and result.steps == 6
    summary, steps = load_run(tmp_path / "run")
    assert summary["result"]["outcome"] == "aborted" and summary["status"] == "finished"
    assert [s.get("human", False) for s in steps] == [False, False, False, True, True, False]
    assert [s["executed"] for s in steps[3:]] == ["B1", "B1", None] and steps[3]["model"] == "human"
    assert steps[5]["failures"][0]["kind"] == "emergency_stop" and steps[5]["pose_after"] == steps[4]["pose_after"]
    assert ep.pilot.calls == 3
    from vlnpilot.report.html import write_episode_report

    assert "aborted" in write_episode_report(tmp_path / "run").read_text(encoding="utf-8")


def test_watch_streams_a_finished_run_read_only(tmp_path: Path) -> None:
    ep = LiveEpisode(tmp_path / "run", max_steps=3)
    ep.pilot.release(3)
    ep.thread.join(60)
    ep.close()
    with LiveStation(tmp_path / "run", scene=load_scene("cabin"), port=0) as station:
        kinds, steps = [], []
        with httpx.stream("GET", f"{station.url}api/events", timeout=30) as r:
            for line in r.iter_lines():
                if line.startswith("event: "):
                    kinds.append(line[7:])
                elif line.startswith("data: ") and kinds[-1] == "step":
                    steps.append(json.loads(line[6:])["step"])
        assert steps == [1, 2, 3] and kinds[-1] == "end" and "summary" in kinds
        assert post(station, {"run": "run", "action": "stop"}).status_code == 404
        assert httpx.get(f"{station.url}frames/front_001.jpg", timeout=10).status_code == 200
        assert httpx.get(f"{station.url}frames/..%2Fsummary.json", timeout=10).status_code == 404
        assert httpx.get(f"{station.url}plan.png", timeout=10).headers["content-type"] == "image/png"


def test_a_step_written_while_the_stream_waits_goes_out_after_one_poll(tmp_path: Path,
                                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """The page's 1 s to show a finished step, without a clock: the event stream sends a step written while it
    waits right after that one wait of POLL_S, and POLL_S leaves most of the second to the page."""
    episode = tmp_path / "episode.jsonl"
    episode.write_text(json.dumps({"step": 1}) + "\n")
    waits: list[float] = []

    async def sleep(seconds: float) -> None:  # the step ends while the stream waits
        waits.append(seconds)
        with episode.open("a") as f:
            f.write(json.dumps({"step": len(waits) + 1}) + "\n")

    async def connected() -> bool:
        return False

    monkeypatch.setattr(live_app, "asyncio", SimpleNamespace(sleep=sleep))
    stream = live_app._stream(SimpleNamespace(is_disconnected=connected), RunFeed(tmp_path), None)

    async def first_events(n: int) -> list[str]:
        return [await anext(stream) for _ in range(n)]

    events = asyncio.run(first_events(2))
    assert [json.loads(e.split("data: ", 1)[1])["step"] for e in events] == [1, 2]
    assert waits == [live_app.POLL_S] and live_app.POLL_S <= 0.25


def test_watch_of_a_directory_without_a_run_is_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(sys, "argv", ["vln-pilot", "watch", str(tmp_path)])
    with pytest.raises(SystemExit) as info:
        cli.main()
    err = capsys.readouterr().err
    assert info.value.code == 2 and len(err.strip().splitlines()) == 1 and "summary.json" in err


def test_reports_know_the_aborted_outcome() -> None:
    from vlnpilot.report.plots import OUTCOME_COLORS, OUTCOME_LABELS, OUTCOME_ORDER

    assert set(OUTCOMES) <= set(OUTCOME_ORDER) and set(OUTCOME_ORDER) <= set(OUTCOME_COLORS) & set(OUTCOME_LABELS)


def test_the_stop_releases_a_held_loop() -> None:
    control = LiveControl(pilot=None)  # type: ignore[arg-type]
    control.act("pause")
    gates = []
    loop = threading.Thread(target=lambda: gates.append(control.before_step(4)))
    loop.start()
    with control._cond:
        assert control._cond.wait_for(lambda: control.status()["holding"], timeout=30)
    assert gates == []  # held: the pilot is not asked
    control.act("stop")
    loop.join(30)
    assert gates[0].abort and gates[0].pilot is None and not control.status()["holding"]


def test_run_live_prints_the_address_and_flies(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(sys, "argv", ["vln-pilot", "run", "Go to the bathroom", "--spawn", "living_room", "--pilot",
                                      "oracle", "--max-steps", "3", "--live", "--live-port", "0", "--no-video",
                                      "--out", str(tmp_path / "r")])
    with pytest.raises(SystemExit) as info:
        cli.main()
    out = capsys.readouterr().out
    assert info.value.code == 0 and "live station: http://127.0.0.1:" in out
    assert load_run(tmp_path / "r")[0]["status"] == "finished"


def test_a_read_only_station_off_loopback_without_a_token_says_what_it_would_expose(monkeypatch, tmp_path) -> None:
    from vlnpilot.core.errors import ConfigError
    from vlnpilot.live.station import TOKEN_ENV, LiveStation

    monkeypatch.delenv(TOKEN_ENV, raising=False)
    with pytest.raises(ConfigError, match="would let anyone who reaches it see the run") as info:
        LiveStation(tmp_path, host="0.0.0.0")  # noqa: S104 - refused before it binds
    assert "fly" not in str(info.value)  # `watch` is read-only: nobody could fly anything through it
