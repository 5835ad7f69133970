"""Chaos: provider calls that fail, hang, over-answer or name retired models (issue 16), through the official
SDKs against the fake servers on 127.0.0.1."""

from __future__ import annotations

import contextlib
import json
import threading

import pytest

from fakes import FakeAnthropic, FakeGemini, FakeOpenAI, ServerThread, sample_input, warm_up
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.rundir import Recorder, load_run
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.pilots.base import PilotError, make_pilot
from vlnpilot.pilots.gemini import GeminiPilot
from vlnpilot.pilots.openai import OpenAIPilot
from vlnpilot.prompting.render import build_prompt
from vlnpilot.server import create_app
from vlnpilot.tasks.task import parse_query

pytestmark = pytest.mark.chaos
KEY = "sk-not-a-real-key-0000"


def openai(fake: FakeOpenAI, **options) -> OpenAIPilot:
    return make_pilot("openai:gpt-4.1", base_url=fake.base_url, api_key=KEY, **options)


# -- structured output is switched off only when the server says it has none ------------------------------------
@pytest.mark.parametrize("message", ["Unsupported value: 'temperature' does not support 0.2 with this model.",
                                     "Unsupported parameter: 'max_tokens' is not supported with this model."])
def test_an_unrelated_400_does_not_switch_structured_output_off(message) -> None:
    with FakeOpenAI() as fake:
        pilot = openai(fake)
        fake.push("status", status_code=400, message=message, code="unsupported_value")
        with pytest.raises(PilotError) as info:
            pilot.decide(sample_input())
        pilot.decide(sample_input())
        formats = [r.json["response_format"]["type"] for r in fake.requests]
    assert info.value.reason == "bad_request" and info.value.fatal
    assert formats == ["json_schema", "json_schema"]  # no wasted JSON-mode call, and still strict afterwards


def test_a_server_without_json_schema_gets_json_mode() -> None:
    with FakeOpenAI(supports_json_schema=False) as fake:
        assert openai(fake).decide(sample_input()).movement
        assert [r.json["response_format"]["type"] for r in fake.requests] == ["json_schema", "json_object"]


@pytest.mark.parametrize(("base_url", "param"), [(None, "max_completion_tokens"),
                                                 ("https://api.openai.com/v1", "max_completion_tokens"),
                                                 ("http://127.0.0.1:8000/v1", "max_tokens")])
def test_the_official_address_is_treated_like_no_address(base_url, param) -> None:
    pilot = OpenAIPilot(base_url=base_url, api_key=KEY)  # nothing is sent: the request is only built
    kwargs = pilot._kwargs(build_prompt(sample_input()), "json_schema")
    assert param in kwargs and kwargs[param] == pilot.max_output_tokens
    assert (pilot.provider == "OpenAI") == (param == "max_completion_tokens")


# -- retired models ------------------------------------------------------------------------------------------------
def test_a_retired_model_is_named_in_one_line_with_current_ones() -> None:
    with FakeOpenAI() as fake:
        fake.push("status", status_code=404, code="model_not_found",
                  message="The model `gpt-4.1` does not exist or you do not have access to it.")
        with pytest.raises(PilotError) as info:
            openai(fake).decide(sample_input())
    text = str(info.value)
    assert info.value.reason == "model_unavailable" and info.value.fatal and "\n" not in text
    assert "'gpt-4.1'" in text and "gpt-5" in text and "gemini" not in text


def test_a_retired_gemini_model_names_current_gemini_models() -> None:
    with FakeGemini() as fake:
        fake.push("status", status_code=404, message="models/gemini-2.0-flash is not found for API version v1beta")
        pilot = make_pilot("gemini:gemini-2.0-flash", base_url=fake.base_url, api_key="AIza-not-a-real-key")
        with pytest.raises(PilotError) as info:
            pilot.decide(sample_input())
    assert info.value.reason == "model_unavailable" and "gemini-2.5-flash" in str(info.value)


# -- Gemini thinking: each family its valid settings, and thoughts never eat the answer's budget ---------------------
@pytest.mark.parametrize(("model", "options", "thinking", "min_output"), [
    ("gemini-2.5-flash", {}, {"thinking_budget": 0}, 512),
    ("gemini-2.5-flash", {"thinking_budget": -1}, {"thinking_budget": -1}, 512 + 4096),
    ("gemini-2.5-flash", {"thinking_budget": None}, None, 512 + 4096),
    ("gemini-2.5-flash", {"thinking_level": "low"}, {"thinking_level": "LOW"}, 512 + 4096),
    ("gemini-2.5-flash", {"thinking_budget": 1024}, {"thinking_budget": 1024}, 512 + 1024),
    ("gemini-2.5-pro", {}, {"thinking_budget": 128}, 512 + 128),  # cannot switch thinking off
    ("gemini-3-pro-preview", {}, {"thinking_level": "LOW"}, 512 + 4096),
])
def test_gemini_thinking_settings_per_family(model, options, thinking, min_output) -> None:
    with FakeGemini() as fake:
        make_pilot(f"gemini:{model}", base_url=fake.base_url, api_key="AIza-not-a-real-key", **options) \
            .decide(sample_input())
        config = fake.last.json["generationConfig"]
    assert config.get("thinkingConfig") == thinking
    assert config["maxOutputTokens"] >= min_output


@pytest.mark.parametrize(("model", "budget"), [("gemini-2.5-pro", 64), ("gemini-2.5-flash", 100_000)])
def test_an_invalid_thinking_budget_names_the_valid_ones(model, budget) -> None:
    with pytest.raises(ConfigError, match=r"valid: .*\d+\.\.\d+"):
        GeminiPilot(model, api_key="AIza-not-a-real-key", thinking_budget=budget)


# -- episodes: re-asks, abandoned calls, over-long replies ---------------------------------------------------------
def test_a_transient_failure_is_not_re_asked_nor_told_to_the_model(geo_sim) -> None:
    with FakeOpenAI() as fake:
        fake.push("server_error", times=3)  # the SDK's 1 + 2 retries, all refused
        result = run_episode(geo_sim, openai(fake), parse_query("Go to the bedroom", geo_sim.scene),
                             EpisodeConfig(max_steps=2), spawn="living_room")
        texts = [r.text for r in fake.requests]
    assert len(texts) == 3 + 1  # step 1: the SDK's attempts only, no re-ask; step 2: one call
    assert result.invalid_decisions == 1
    assert not any("unavailable" in t or "rejected" in t for t in texts)


def test_a_429_is_asked_again_in_its_step_and_never_told_to_the_model(geo_sim) -> None:
    """Issue 27: a 429 the SDK's retries did not get past is the provider's limit, not a step nor a failure."""
    with FakeOpenAI() as fake:
        fake.push("rate_limit", times=3, retry_after=0.01)  # the SDK's 1 + 2 retries, all refused
        result = run_episode(geo_sim, openai(fake), parse_query("Go to the bedroom", geo_sim.scene),
                             EpisodeConfig(max_steps=2), spawn="living_room")
        texts = [r.text for r in fake.requests]
    assert len(texts) == 3 + result.steps  # step 1: the SDK's refused attempts, then asked again; one call a step
    assert result.invalid_decisions == 0 and result.outcome != "pilot_error"
    assert not any("rate_limited" in t or "rejected" in t for t in texts)


@pytest.mark.parametrize("provider", ["openai", "gemini", "anthropic", "remote"])
def test_abandoned_calls_send_nothing_after_the_episode(geo_sim, provider) -> None:
    fakes = {"openai": FakeOpenAI, "gemini": FakeGemini, "anthropic": FakeAnthropic, "remote": FakeOpenAI}
    with fakes[provider]() as fake, contextlib.ExitStack() as stack:
        if provider == "remote":  # our server in a thread, in front of the fake: the hang reaches the client
            app = create_app(pilot_spec="openai:gpt-4.1", pilot_options={"base_url": fake.base_url, "api_key": KEY,
                                                                          "timeout": 4.0, "max_retries": 0})
            url = stack.enter_context(ServerThread(app))
            pilot = make_pilot("remote", url=url, timeout=0.5, max_retries=2, retry_base_delay=0.01)
        else:
            key = {"gemini": "AIza-not-a-real-key"}.get(provider, KEY)
            pilot = make_pilot(provider, base_url=fake.base_url, api_key=key, timeout=0.5, max_retries=2)
        warm = warm_up(fake, geo_sim, pilot)  # a cold first call could outlast the 0.2 s deadline below
        fake.push("hang", times=20, seconds=5.0)
        result = run_episode(geo_sim, pilot, parse_query("Go to the bedroom", geo_sim.scene),
                             EpisodeConfig(max_steps=2, step_deadline_s=0.2), spawn="living_room")
        at_end = len(fake.requests) - warm
        calls = [t for t in threading.enumerate() if t.name == "pilot-call"]
        assert calls and all(t.daemon for t in calls)  # never holds up the process's exit
        for t in calls:
            t.join(timeout=30)  # the abandoned calls end (time-out, then their retries are refused)
        assert not any(t.is_alive() for t in calls)
        after = len(fake.requests) - warm
    assert result.invalid_decisions == 2
    assert at_end == 2 and after == at_end  # one request per step, none after the end (there were 2 retries each)


def test_a_huge_valid_reply_is_too_long_not_json_and_is_recorded_capped(geo_sim, tmp_path) -> None:
    huge = json.dumps({"room": "living_room", "movement": "C1", "state": "Recognize Room",
                       "description": "x" * 1_000_000, "door_position": "not_visible"})
    with FakeOpenAI() as fake:
        fake.push("text", times=3, text=huge)
        run_episode(geo_sim, openai(fake), parse_query("Go to the bedroom", geo_sim.scene),
                    EpisodeConfig(max_steps=1), spawn="living_room", recorder=Recorder(tmp_path / "run"))
    _, steps = load_run(tmp_path / "run")
    failures = steps[0]["failures"]
    assert [f["kind"] for f in failures] == ["too_long"] * 3
    assert "1000" in failures[0]["reason"] and "characters" in failures[0]["reason"]
    assert failures[0]["raw_text"].endswith(f"[cut: {len(huge)} characters in all]")
    assert (tmp_path / "run" / "episode.jsonl").stat().st_size < 50_000  # not 3 MB


HANGING_EPISODE = """
import sys
sys.path.insert(0, sys.argv[1])
from fakes import FakeOpenAI, warm_up
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.pilots.base import make_pilot
from vlnpilot.sim import SimConfig, Simulator
from vlnpilot.tasks.task import parse_query

fake = FakeOpenAI().start()  # left running: its hung answers would keep an abandoned call waiting
pilot = make_pilot("openai:gpt-4.1", base_url=fake.base_url, api_key="sk-not-a-real-key-0000", timeout=300)
with Simulator("cabin", SimConfig(render=False)) as sim:
    warm = warm_up(fake, sim, pilot)  # a fresh process's first call could outlast the 0.2 s deadline
    fake.push("hang", times=20, seconds=600.0)
    result = run_episode(sim, pilot, parse_query("Go to the bedroom", sim.scene),
                         EpisodeConfig(max_steps=1, step_deadline_s=0.2), spawn="living_room")
print(result.outcome, len(fake.requests) - warm, flush=True)
"""


def test_the_process_exits_at_once_although_a_call_still_hangs(tmp_path) -> None:
    import subprocess
    import sys
    from pathlib import Path

    script = tmp_path / "hang.py"
    script.write_text(HANGING_EPISODE)
    proc = subprocess.Popen([sys.executable, str(script), str(Path(__file__).parents[1])], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        out, err = proc.communicate(timeout=120)  # the hung call would hold a non-daemon thread for 300 s
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    assert out.split() == ["pilot_error", "1"]  # its one step got no decision: the pilot failed, not the flight
