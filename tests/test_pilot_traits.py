"""Pilots declare their traits (as environments declare capabilities) and inherit no-op hooks from BasePilot."""

from __future__ import annotations

import re
from pathlib import Path

from vlnpilot.core.decision import NO_TRAITS, Decision, PilotInput, PilotTraits, traits_of
from vlnpilot.pilots.base import BasePilot, as_base_pilot, pilot_factory

SRC = Path(__file__).resolve().parents[1] / "src" / "vlnpilot"


def test_the_builtin_pilots_declare_their_traits() -> None:
    assert traits_of(pilot_factory("oracle")) == PilotTraits(privileged=True)
    assert traits_of(pilot_factory("noisy-oracle")).privileged
    assert traits_of(pilot_factory("remote")) == PilotTraits(uses_step_deadline=True)
    for name in ("stdin", "files", "replay"):
        assert traits_of(pilot_factory(name)) == NO_TRAITS, name
        assert issubclass(pilot_factory(name), BasePilot), name  # type: ignore[arg-type]


def test_a_model_pilot_validates_its_decisions_unless_told_not_to(monkeypatch) -> None:
    monkeypatch.setenv("OPENAI_API_KEY", "sk-test")
    from vlnpilot.pilots.base import make_pilot

    assert traits_of(make_pilot("openai:gpt-4.1")) == PilotTraits(validates_decisions=True, uses_step_deadline=True)
    unchecked = make_pilot("openai:gpt-4.1", validate_replies=False)
    assert traits_of(unchecked) == PilotTraits(uses_step_deadline=True)


class _Bare:
    """A pilot written to the bare protocol: a name, a model, decide; one hook of its own."""

    name, model = "bare", None

    def __init__(self) -> None:
        self.finished: list[object] = []

    def decide(self, pilot_input: PilotInput) -> Decision:
        raise AssertionError("not asked here")

    def episode_finished(self, result: object) -> None:
        self.finished.append(result)


def test_a_bare_protocol_pilot_is_adapted_once_keeping_its_own_hooks() -> None:
    bare = _Bare()
    adapted = as_base_pilot(bare)
    assert isinstance(adapted, BasePilot) and adapted.name == "bare" and adapted.traits == NO_TRAITS
    adapted.episode_finished("done")
    adapted.episode_started(None, None)  # not its own: the base's no-op
    adapted.close()
    assert bare.finished == ["done"]
    assert as_base_pilot(adapted) is adapted


def test_no_module_probes_a_pilot_for_a_hook_or_a_trait() -> None:
    """The traits are read through `traits_of`, the hooks are called on a BasePilot: nothing else probes."""
    probe = re.compile(r"getattr\([^)]*pilot[^)]*,\s*\"(privileged|validates_decisions|uses_step_deadline|attach|"
                       r"reseed|episode_started|episode_finished|cancel_pending|close)\"")
    found = [f"{p.relative_to(SRC)}:{i}" for p in SRC.rglob("*.py")
             for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1) if probe.search(line)]
    assert found == []
