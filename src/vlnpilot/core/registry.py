"""One registry style for everything chosen by name: pilots, executors, scenes, shields, robots.

A `Registry` maps a name to an object (a class or a factory). Three sources fill it, in this order:
- `@registry.register("NAME")` in a module that has been imported;
- the built-in modules, imported lazily by name (`builtins={"ray": "vlnpilot.bench.ray_executor"}`), so that an
  optional dependency is imported only when its entry is asked for;
- the installed distributions' entry points of the registry's group (for example `vlnpilot.pilots`): a third
  party registers with `[project.entry-points."vlnpilot.pilots"] mypilot = "mypkg.pilot"`, and the entry point is
  loaded (its module imported, which registers the name) the first time that name, or the list, is asked for.

A name nobody registered raises `UnknownNameError` naming the valid choices, so the command line can print one
line and exit 2.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterator, Mapping
from importlib.metadata import EntryPoint, entry_points
from typing import Generic, TypeVar

from vlnpilot.core.errors import UnknownNameError

T = TypeVar("T")


class Registry(Generic[T]):
    """Named objects of one kind (`kind` names it in errors: 'pilot', 'executor', ...)."""

    def __init__(self, kind: str, *, group: str | None = None, builtins: Mapping[str, str] | None = None):
        self.kind = kind
        self.group = group
        self._builtins = dict(builtins or {})
        self._entries: dict[str, T] = {}
        self._points: list[EntryPoint] | None = None  # the group's entry points, once read

    def register(self, name: str) -> Callable[[T], T]:
        """Decorator: `@registry.register("NAME")` over a class or a factory; the last registration wins."""

        def deco(obj: T) -> T:
            self._entries[name] = obj
            return obj

        return deco

    def add(self, name: str, obj: T) -> None:
        self._entries[name] = obj

    def unregister(self, name: str) -> None:
        """Forget a registered name (a test's or a plugin's); built-ins and entry points stay known."""
        self._entries.pop(name, None)

    def get(self, name: str) -> T:
        """The object registered under `name`, importing its built-in module or entry point if need be."""
        if name not in self._entries:
            self._load(name)
        if name not in self._entries:  # an entry point's module may register several names
            self._load_entry_points()
        if name not in self._entries:
            raise UnknownNameError(self.kind, name, self.names())
        return self._entries[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())

    def __contains__(self, name: object) -> bool:
        return name in self.names()

    def names(self) -> list[str]:
        """Every name: registered, built in (without importing optional modules) and from entry points."""
        found = dict.fromkeys(self._entries)
        found.update(dict.fromkeys(self._builtins))
        found.update(dict.fromkeys(ep.name for ep in self._entry_points()))
        return list(found)

    def loaded(self) -> Iterator[tuple[str, T]]:
        """Every entry, with all built-in modules and entry points imported first."""
        self._load_all()
        yield from self._entries.items()

    def _load(self, name: str) -> None:
        module = self._builtins.get(name)
        if module is not None:
            importlib.import_module(module)
            return
        for ep in self._entry_points():
            if ep.name == name:
                self._load_entry_point(ep)

    def _load_all(self) -> None:
        for module in dict.fromkeys(self._builtins.values()):
            importlib.import_module(module)
        self._load_entry_points()

    def _load_entry_points(self) -> None:
        for ep in self._entry_points():
            if ep.name not in self._entries:
                self._load_entry_point(ep)

    def _load_entry_point(self, ep: EntryPoint) -> None:
        """An entry point names a module that registers itself, or an object to register under its name."""
        obj = ep.load()
        if ep.name not in self._entries and not _is_module(obj):
            self._entries[ep.name] = obj

    def _entry_points(self) -> list[EntryPoint]:
        """The group's entry points, read once: scanning the installed distributions costs milliseconds, and
        `in SCENES` runs at every scene load."""
        if self._points is None:
            self._points = list(entry_points(group=self.group)) if self.group else []
        return self._points


def _is_module(obj: object) -> bool:
    return type(obj).__name__ == "module"
