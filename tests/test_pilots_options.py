"""Typed pilot options: every registered pilot has an options class; bad options are one line; the bench and the
server ask the class (base_url, the suite row, the default model) instead of probing the factory."""

from __future__ import annotations

import ast
import inspect
import textwrap
from typing import Any

import pytest

from vlnpilot.bench.runner import BenchSettings, config_hash, config_of, effective_suite, resolve_pilots
from vlnpilot.core.errors import ConfigError
from vlnpilot.pilots.base import known_pilots, make_pilot, pilot_factory, pilot_options_class, register_pilot
from vlnpilot.pilots.options import OpenPilotOptions, PilotOptions, parse_option_pairs
from vlnpilot.server.pool import canonical_spec

BUILTIN = ["anthropic", "files", "gemini", "gullible", "noisy-oracle", "openai", "oracle", "remote", "replay", "stdin"]
SECRET = "sk-this-must-never-be-printed-0000"

# One bad value per pilot: (option, value, a fragment of the reason)
BAD_VALUES = {
    "oracle": ("approach_m", "far", "valid number"),
    "noisy-oracle": ("p_offset", 1.5, "less than or equal to 1"),
    "gullible": ("view_m", "near", "valid number"),
    "openai": ("detail", "ultra", "'low', 'high' or 'auto'"),
    "gemini": ("thinking_budget", "lots", "valid integer"),
    "anthropic": ("cache", "maybe", "valid boolean"),
    "remote": ("timeout", 0, "greater than 0"),
    "stdin": ("jpeg_quality", 0, "greater than or equal to 1"),
    "files": ("timeout_s", -1, "greater than 0"),
    "replay": ("strict", "sometimes", "valid boolean"),
}


def _one_line(exc: BaseException) -> str:
    message = str(exc)
    assert "\n" not in message and "pydantic" not in message and "errors.pydantic.dev" not in message, message
    return message


def test_every_builtin_pilot_has_its_own_options_class():
    assert set(BUILTIN) <= set(known_pilots())
    for name in BUILTIN:
        cls = pilot_options_class(name)
        assert issubclass(cls, PilotOptions) and cls is not OpenPilotOptions, name


@pytest.mark.parametrize("name", BUILTIN)
def test_unknown_option_is_one_line_with_the_pilot_and_the_valid_options(name):
    with pytest.raises(ConfigError) as info:
        make_pilot(name, no_such_option=1)
    message = _one_line(info.value)
    assert f"unknown option 'no_such_option' for the {name} pilot" in message
    assert "valid options: " + ", ".join(pilot_options_class(name).option_names()) in message


@pytest.mark.parametrize("name", BUILTIN)
def test_bad_value_is_one_line_naming_the_option_and_the_reason(name):
    option, value, reason = BAD_VALUES[name]
    with pytest.raises(ConfigError) as info:
        make_pilot(name, **{option: value})
    message = _one_line(info.value)
    assert f"bad value for option '{option}' of the {name} pilot" in message and reason in message, message
    assert "valid options: " in message


@pytest.mark.parametrize(("name", "option"), [("openai", "api_key"), ("gemini", "api_key"),
                                              ("anthropic", "api_key"), ("remote", "token")])
def test_a_secret_is_never_in_an_error_or_a_repr(name, option):
    cls = pilot_options_class(name)
    assert option in cls.secret_names()
    with pytest.raises(ConfigError) as info:  # a bad value for the secret itself
        make_pilot(name, **{option: [SECRET]})
    assert SECRET not in str(info.value) and f"'{option}'" in str(info.value)
    with pytest.raises(ConfigError) as info:  # a bad value for another option, with the secret given
        make_pilot(name, **{option: SECRET, "timeout": "soon"})
    assert SECRET not in str(info.value)
    options = cls.build(name, **{option: SECRET})
    assert SECRET not in repr(options) and SECRET not in str(options)


def test_command_line_strings_are_coerced_by_the_options_class():
    openai = pilot_options_class("openai")
    assert openai.from_command_line("openai", {"detail": "high", "timeout": "30", "validate": "false"}) == \
        {"detail": "high", "timeout": 30.0, "validate": False}
    assert pilot_options_class("gemini").from_command_line("gemini", {"thinking_budget": "0"}) == {"thinking_budget": 0}
    assert pilot_options_class("noisy-oracle").from_command_line("noisy-oracle", {"offset_m": "0.2,0.3"}) == \
        {"offset_m": [0.2, 0.3]}
    assert parse_option_pairs(["detail=high", " timeout = 30 "]) == {"detail": "high", "timeout": "30"}


@pytest.mark.parametrize(("pairs", "fragment"), [
    (["detail"], "takes KEY=VALUE"),
    (["=high"], "takes KEY=VALUE"),
    (["detail=high", "detail=low"], "'detail' given twice"),
])
def test_malformed_pairs_are_refused(pairs, fragment):
    with pytest.raises(ConfigError, match=fragment):
        parse_option_pairs(pairs)


@pytest.mark.parametrize(("name", "key", "fragment"), [
    ("openai", "api_key", "a secret does not go on the command line"),
    ("openai", "model", "the model is the SPEC's"),
    ("files", "clock", "not a command-line option"),
    ("oracle", "detail", "unknown option"),
])
def test_command_line_refuses_secrets_models_programmatic_and_unknown_keys(name, key, fragment):
    cls = pilot_options_class(name)
    with pytest.raises(ConfigError) as info:
        cls.from_command_line(name, {key: SECRET})
    message = _one_line(info.value)
    assert fragment in message and f"valid keys: {', '.join(cls.settable())}" in message and SECRET not in message
    assert key not in cls.settable()


def test_defaults_live_in_the_options_class():
    assert pilot_options_class("openai").default_model() == "gpt-4.1"
    assert canonical_spec("openai") == "openai:gpt-4.1"  # the server pool asks the options class
    assert canonical_spec("gemini") == f"gemini:{pilot_options_class('gemini').default_model()}"
    assert canonical_spec("remote") == "remote"  # no default model: the server's
    pilot = make_pilot("noisy-oracle")
    defaults = pilot_options_class("noisy-oracle")()
    assert (pilot.model, pilot.p_offset, pilot.approach_m) == (defaults.model, defaults.p_offset, defaults.approach_m)


# ------------------------------------------------------------------ the options each constructor reads
def _reads(cls: type) -> set[str]:
    """Attributes read off the validated options (`o.X`, `options.X`) in the constructors of `cls` and its bases."""
    names: set[str] = set()
    for klass in cls.__mro__[:-1]:  # not object
        for method in ("__init__", "_configure"):
            fn = klass.__dict__.get(method)
            if fn is None:
                continue
            tree = ast.parse(textwrap.dedent(inspect.getsource(fn)))
            names |= {n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute)
                      and isinstance(n.value, ast.Name) and n.value.id in ("o", "options")}
    return names


@pytest.mark.parametrize("name", BUILTIN)
def test_options_fields_are_exactly_what_the_constructor_reads(name):
    fields = set(pilot_options_class(name).model_fields)
    reads = _reads(pilot_factory(name))
    assert reads == fields, f"read but not an option: {reads - fields}; option never read: {fields - reads}"


# ------------------------------------------------------------------ the bench asks the options class
class UrlOptions(PilotOptions):
    base_url: str | None = None


class _UrlPilot:
    name = "test-url"

    def __init__(self, **options: Any):  # takes base_url only through **options: inspect could not tell
        self.model, self.base_url = options.get("model"), options.get("base_url")

    def decide(self, pilot_input):  # pragma: no cover - never flown
        raise NotImplementedError


register_pilot("test-url", options=UrlOptions)(_UrlPilot)


def test_bench_gives_base_url_to_the_pilots_whose_options_take_it():
    url = "http://127.0.0.1:9/v1"
    entries = resolve_pilots(["oracle", "test-url", "openai:local-model"], url)
    assert [e.options for e in entries] == [{}, {"base_url": url}, {"base_url": url}]


def test_bench_pilot_options_go_to_the_pilots_that_take_them_and_into_the_hash():
    plain = BenchSettings(pilots=("oracle", "noisy-oracle"), episode_options={"shield": "off"})
    given = BenchSettings(pilots=("oracle", "noisy-oracle"), episode_options={"shield": "off"},
                          pilot_options={"p_offset": "0.5", "approach_m": "0.4"})
    entries = resolve_pilots(given.pilots, None, given.pilot_options)
    assert [e.options for e in entries] == [{"approach_m": 0.4}, {"approach_m": 0.4, "p_offset": 0.5}]
    suite = effective_suite(plain)
    hashes = {config_hash(config_of(suite, resolve_pilots(s.pilots, None, s.pilot_options), s)) for s in (plain, given)}
    assert len(hashes) == 2
    with pytest.raises(ConfigError, match="'detail' is taken by none of the pilots oracle, noisy-oracle"):
        resolve_pilots(given.pilots, None, {"detail": "high"})


def test_a_bench_without_pilot_options_hashes_as_before():
    """The oracle's paper-suite config hash, as main computed it before pilots had options classes."""
    settings = BenchSettings(pilots=("oracle",), episode_options={"shield": "geometry"})
    entries = resolve_pilots(settings.pilots, None, settings.pilot_options)
    assert config_hash(config_of(effective_suite(settings), entries, settings)) == "781fa072efff6c1a"


def test_replay_gets_the_suite_row_because_its_options_take_one():
    from vlnpilot.bench.episode_job import EpisodeSpec, _pilot_options

    fields = {f: None for f in EpisodeSpec.__dataclass_fields__}
    spec = EpisodeSpec(**{**fields, "pilot": "replay:trials/x", "row": "to-bedroom", "pilot_options": {}})
    assert _pilot_options(spec) == {"row": "to-bedroom"}
    assert _pilot_options(EpisodeSpec(**{**fields, "pilot": "oracle", "row": "r1", "pilot_options": {}})) == {}
