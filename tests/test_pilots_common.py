"""Shared pilot machinery: prices, retries, Retry-After, redaction, keys, reply codes, the registry."""

from __future__ import annotations

import email.utils
import json
import time

import pytest

from vlnpilot.core.decision import DecisionError, parse_decision
from vlnpilot.core.errors import ConfigError
from vlnpilot.pilots import model as model_module
from vlnpilot.pilots import transport
from vlnpilot.pilots.base import PilotError, known_pilots
from vlnpilot.pilots.pricing import DEFAULT_PRICES, PRICES_AS_OF, Price, cost_usd, find_price, load_prices
from vlnpilot.pilots.secrets import redact, resolve_api_key
from vlnpilot.pilots.transport import call_with_retries, parse_retry_after, status_error


def test_model_pilots_are_registered():
    assert {"openai", "gemini", "anthropic", "remote"} <= set(known_pilots())


# ------------------------------------------------------------------------------------------------ pricing

def test_price_table_is_dated_and_covers_the_default_models():
    assert len(PRICES_AS_OF) == 10 and PRICES_AS_OF[4] == "-"
    for model in ("gpt-4.1", "gemini-2.5-flash", "claude-sonnet-4-6"):
        assert model in DEFAULT_PRICES


def test_cost_and_prefix_matching():
    cost = cost_usd("gpt-4.1", 1_000_000, 400_000, 100_000)
    assert cost.known and cost.usd == pytest.approx(0.6 * 2.0 + 0.4 * 0.5 + 0.1 * 8.0)
    assert find_price("gpt-4.1-2025-04-14") == DEFAULT_PRICES["gpt-4.1"]
    assert find_price("gpt-4.1-mini-2025-04-14") == DEFAULT_PRICES["gpt-4.1-mini"]  # longest prefix wins
    assert find_price("models/gemini-2.5-flash") == DEFAULT_PRICES["gemini-2.5-flash"]
    assert find_price("gpt-4.10") is None  # not a '-' boundary
    unknown = cost_usd("llava-13b", 1000, 0, 1000)
    assert unknown.usd == 0 and not unknown.known


def test_price_overrides_from_env_json(tmp_path, monkeypatch):
    path = tmp_path / "prices.json"
    path.write_text(json.dumps({"as_of": "2030-01-01", "models": {"gpt-4.1": {"input": 1, "output": 2},
                                                                  "llava-13b": {"input": 0.1, "output": 0.2}}}))
    monkeypatch.setenv("VLN_PILOT_PRICES", str(path))
    table = load_prices()
    assert table["gpt-4.1"] == Price(1, 1, 2)  # cached defaults to the input price
    assert cost_usd("llava-13b", 1_000_000, 0, 0).usd == pytest.approx(0.1)
    monkeypatch.delenv("VLN_PILOT_PRICES")
    assert load_prices()["gpt-4.1"] == DEFAULT_PRICES["gpt-4.1"]


@pytest.mark.parametrize("content", ["[1, 2]", '{"m": {"input": 1}}', '{"m": {"input": -1, "output": 1}}',
                                     '{"m": {"input": 1, "output": 1, "typo": 3}}', "{not json"])
def test_bad_price_files_are_config_errors(tmp_path, content):
    path = tmp_path / "p.json"
    path.write_text(content)
    with pytest.raises(ConfigError):
        load_prices(path)


def test_missing_price_file_is_a_config_error(tmp_path):
    with pytest.raises(ConfigError, match="price file"):
        load_prices(tmp_path / "nope.json")


# ------------------------------------------------------------------------------------------------ retries

def test_parse_retry_after(monkeypatch: pytest.MonkeyPatch):
    assert parse_retry_after({"retry-after": "2"}) == 2.0
    assert parse_retry_after({"retry-after": "0.25"}) == 0.25
    assert parse_retry_after({"retry-after-ms": "150", "retry-after": "9"}) == 0.15
    now = 1_700_000_000.0
    monkeypatch.setattr(time, "time", lambda: now)  # an HTTP date is read against the clock: a fixed one here
    assert parse_retry_after({"retry-after": email.utils.formatdate(now + 30, usegmt=True)}) == 30.0
    assert parse_retry_after({"retry-after": email.utils.formatdate(now - 30, usegmt=True)}) == 0.0  # past
    assert parse_retry_after({"retry-after": "soon"}) is None
    assert parse_retry_after({}) is None and parse_retry_after(None) is None


class Flaky(Exception):
    pass


def test_call_with_retries_is_bounded_and_honours_retry_after():
    sleeps: list[float] = []
    calls = []

    def fn():
        calls.append(1)
        raise Flaky()

    with pytest.raises(Flaky):
        call_with_retries(fn, classify=lambda e: (True, 0.3), max_retries=3, sleep=sleeps.append)
    assert len(calls) == 4 and sleeps == [0.3, 0.3, 0.3]


def test_call_with_retries_backoff_is_capped_exponential():
    sleeps: list[float] = []
    with pytest.raises(Flaky):
        call_with_retries(lambda: (_ for _ in ()).throw(Flaky()), classify=lambda e: (True, None), max_retries=6,
                          base_delay=0.5, max_delay=4.0, sleep=sleeps.append)
    caps = [0.5, 1.0, 2.0, 4.0, 4.0, 4.0]
    assert len(sleeps) == 6
    assert all(0.75 * cap <= s <= cap for s, cap in zip(sleeps, caps, strict=True))


def test_call_with_retries_gives_up_on_long_retry_after_and_non_retryable():
    sleeps: list[float] = []
    with pytest.raises(Flaky):
        call_with_retries(lambda: (_ for _ in ()).throw(Flaky()), classify=lambda e: (True, 3600.0),
                          sleep=sleeps.append)
    with pytest.raises(Flaky):
        call_with_retries(lambda: (_ for _ in ()).throw(Flaky()), classify=lambda e: (False, None),
                          sleep=sleeps.append)
    assert sleeps == []
    assert call_with_retries(lambda: 42, classify=lambda e: (True, None)) == 42


# ------------------------------------------------------------------------------------------------ errors

@pytest.mark.parametrize(("status", "reason", "fatal"), [
    (400, "bad_request", True), (401, "auth", True), (403, "permission", True), (404, "not_found", True),
    (408, "timeout", False), (409, "unavailable", False), (429, "rate_limited", False), (500, "unavailable", False),
    (503, "unavailable", False), (529, "unavailable", False),
])
def test_status_error_mapping(status, reason, fatal):
    err = status_error("OpenAI", status, "msg", key_env="OPENAI_API_KEY", model="gpt-4.1")
    assert (err.reason, err.fatal) == (reason, fatal)
    assert f"({status})" in str(err)


def test_gemini_invalid_key_400_is_an_auth_error():
    err = status_error("Gemini", 400, "API key not valid. Please pass a valid API key.", key_env="GEMINI_API_KEY",
                       model="gemini-2.5-flash")
    assert err.reason == "auth" and "GEMINI_API_KEY" in str(err)


def test_redaction():
    assert "sk-abcdef123456" not in redact("key sk-abcdef123456 rejected")
    assert "AIzaSyA1234567890123456789012" not in redact("key=AIzaSyA1234567890123456789012")
    assert "my-plain-secret" not in redact("echo my-plain-secret", "my-plain-secret")
    assert "Bearer ***" in redact("Authorization: Bearer abcdefghijkl")


def test_a_model_pilot_keeps_its_key_out_of_its_repr_and_attributes():
    from vlnpilot.pilots.openai import OpenAIPilot

    pilot = OpenAIPilot(api_key="sk-hunter22secret", base_url="http://127.0.0.1:9/v1")
    shown = repr(pilot) + str(pilot) + repr(vars(pilot)) + str(pilot._secret)
    assert "hunter22" not in shown and pilot._secret.get_secret_value() == "sk-hunter22secret"
    pilot.close()


def test_resolve_api_key(monkeypatch):
    monkeypatch.delenv("A_KEY", raising=False)
    monkeypatch.setenv("B_KEY", "b-value")
    assert resolve_api_key("explicit", ["A_KEY", "B_KEY"], "X") == "explicit"
    assert resolve_api_key(None, ["A_KEY", "B_KEY"], "X") == "b-value"
    monkeypatch.delenv("B_KEY")
    assert resolve_api_key(None, ["A_KEY"], "X", optional=True) is None
    with pytest.raises(PilotError, match="A_KEY or B_KEY") as info:
        resolve_api_key(None, ["A_KEY", "B_KEY"], "X")
    assert info.value.fatal


@pytest.mark.parametrize(("text", "code"), [
    ("turn left", "not_json"),
    ('{"room": "hall"}', "missing_field"),
    ('{"room": "hall", "movement": 3, "state": "x"}', "invalid_value"),
    ('{"room": "hall", "movement": "A1", "state": "x", "door_position": "up"}', "invalid_enum"),
    ('{"room": null, "movement": "A1", "state": null}', "missing_field"),
    (b"{}", "invalid_value"),
])
def test_decision_error_codes(text, code):
    with pytest.raises(DecisionError) as info:
        parse_decision(text)
    assert info.value.code == code and code in model_module.REPLY_REASONS  # the pilot raises it as its reason


def test_reply_reasons_are_distinct_from_transient_ones():
    assert not (model_module.REPLY_REASONS & transport.TRANSIENT_REASONS)
