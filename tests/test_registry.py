"""One registry style: registered names, lazily imported built-ins, and third parties' entry points."""

from __future__ import annotations

import sys
from importlib.metadata import EntryPoint
from pathlib import Path

import pytest

from vlnpilot.core import registry as registry_module
from vlnpilot.core.errors import UnknownNameError
from vlnpilot.core.registry import Registry


def _module(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, name: str, body: str) -> None:
    (tmp_path / f"{name}.py").write_text(body, encoding="utf-8")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, name, raising=False)


def test_a_registered_name_is_found_and_an_unknown_one_lists_the_choices() -> None:
    reg: Registry[int] = Registry("widget")
    reg.add("one", 1)
    assert reg.get("one") == 1 and "one" in reg and list(reg) == ["one"]
    with pytest.raises(UnknownNameError, match=r"unknown widget 'two'; valid widgets: one"):
        reg.get("two")


def test_a_builtin_module_is_imported_only_when_its_name_is_asked_for(tmp_path: Path,
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    reg: Registry[str] = Registry("widget", builtins={"lazy": "lazy_widget_mod"})
    monkeypatch.setattr(sys.modules[__name__], "REG", reg, raising=False)
    _module(tmp_path, monkeypatch, "lazy_widget_mod",
            f"import sys\nsys.modules[{__name__!r}].REG.add('lazy', 'loaded')\n")
    assert reg.names() == ["lazy"] and "lazy_widget_mod" not in sys.modules  # listed without importing
    assert reg.get("lazy") == "loaded" and "lazy_widget_mod" in sys.modules


def test_an_entry_point_registers_its_module_or_its_object(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    reg: Registry[object] = Registry("pilot", group="vlnpilot.pilots")
    monkeypatch.setattr(sys.modules[__name__], "REG", reg, raising=False)
    _module(tmp_path, monkeypatch, "third_party_pilot",
            f"import sys\nsys.modules[{__name__!r}].REG.add('theirs', 'by module')\nOBJ = 'by object'\n")
    points = [EntryPoint("theirs", "third_party_pilot", "vlnpilot.pilots"),
              EntryPoint("direct", "third_party_pilot:OBJ", "vlnpilot.pilots")]
    monkeypatch.setattr(registry_module, "entry_points",
                        lambda group: [p for p in points if p.group == group])
    assert set(reg.names()) == {"theirs", "direct"}
    assert reg.get("theirs") == "by module"
    assert reg.get("direct") == "by object"


def test_the_builtin_registries_speak_the_same_way() -> None:
    from vlnpilot.bench.executors import executor_names
    from vlnpilot.pilots.base import known_pilots
    from vlnpilot.scene import SCENES

    assert {"local", "inline", "ray"} <= set(executor_names())
    assert {"oracle", "openai", "files", "stdin"} <= set(known_pilots())
    assert {"cabin", "cabin-v1"} <= set(SCENES)
