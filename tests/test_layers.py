"""Imports point down only: every module's imports checked against the layer list of docs/architecture.md.

The list is parsed out of the document (the ```layers block), so the map and this test cannot disagree. A
unit is a package (`scene/`: every module under it) or a top-level module (`fsm`). A module may import its
own unit, its own layer and every layer below it. Imports inside functions count; imports under
`if TYPE_CHECKING:` do not (they never run).
"""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "src" / "vlnpilot"
DOC = ROOT / "docs" / "architecture.md"

# Upward arrows that remain, each named and explained (docs/architecture.md lists them too). Only these pass;
# a new upward import fails the test. Keys: (importing module, imported module).
KNOWN_UPWARD: dict[tuple[str, str], str] = {}


def layers() -> list[list[str]]:
    """The layers of the document, top first: each a list of units ('cli', 'server/', ...)."""
    blocks = re.findall(r"^```layers[ \t]*\n(.*?)^```", DOC.read_text(encoding="utf-8"), re.M | re.S)
    assert len(blocks) == 1, f"{DOC} needs exactly one ```layers block"
    out = [line.split("#", 1)[0].split() for line in blocks[0].splitlines()]
    return [units for units in out if units]


def module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def unit_of(module: str) -> str:
    """'vlnpilot.scene.model' -> 'scene/'; 'vlnpilot.cli' -> 'cli'; the package itself -> '__init__'."""
    parts = module.split(".")[1:]
    if not parts:
        return "__init__"
    return parts[0] + "/" if (PACKAGE / parts[0]).is_dir() else parts[0]


def _is_module(name: str) -> bool:
    if name == "vlnpilot":
        return True
    if not name.startswith("vlnpilot."):
        return False
    rel = PACKAGE.joinpath(*name.split(".")[1:])
    return rel.with_suffix(".py").is_file() or (rel / "__init__.py").is_file()


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    skipped: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skipped |= {id(n) for stmt in node.body for n in ast.walk(stmt)}
    return skipped


def imports(path: Path) -> set[str]:
    """The vlnpilot modules a file imports, at the top or inside functions, outside `if TYPE_CHECKING:`."""
    module = module_name(path)
    tree = ast.parse(path.read_text(encoding="utf-8"))
    skipped = _type_checking_nodes(tree)
    found: set[str] = set()
    for node in ast.walk(tree):
        if id(node) in skipped:
            continue
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: resolved against this module's package
                package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
                base = ".".join(package[: len(package) - node.level + 1] + ([node.module] if node.module else []))
            # `from vlnpilot.pilots import pricing` imports the module vlnpilot.pilots.pricing, not the package
            names = [f"{base}.{a.name}" if _is_module(f"{base}.{a.name}") else base for a in node.names]
        else:
            continue
        for name in names:
            if name == "vlnpilot" or name.startswith("vlnpilot."):
                while not _is_module(name):  # vlnpilot.core.fsm.State -> vlnpilot.core.fsm
                    name = name.rpartition(".")[0]
                found.add(name)
    return found


def all_modules() -> list[Path]:
    return sorted(PACKAGE.rglob("*.py"))


def test_the_layer_list_names_every_unit_once() -> None:
    listed = [u for layer in layers() for u in layer]
    twice = sorted({u for u in listed if listed.count(u) > 1})
    assert not twice, f"units listed twice: {twice}"
    units = {unit_of(module_name(p)) for p in all_modules()}
    assert units - set(listed) == set(), "place every module of src/vlnpilot in the ```layers block of " + str(DOC)
    assert set(listed) - units == set(), "the ```layers block names units that do not exist"


def upward_imports() -> list[tuple[str, str]]:
    """Every (importer, imported) pair whose target sits on a higher layer than its importer."""
    rank = {unit: i for i, layer in enumerate(reversed(layers())) for unit in layer}  # 0 is the floor
    found = []
    for path in all_modules():
        importer = module_name(path)
        for imported in sorted(imports(path)):
            if rank[unit_of(imported)] > rank[unit_of(importer)]:
                found.append((importer, imported))
    return found


def test_no_module_imports_from_a_layer_above_it() -> None:
    new = [f"{a} imports {b} ({unit_of(a)} sits below {unit_of(b)})" for a, b in upward_imports()
           if (a, b) not in KNOWN_UPWARD]
    assert not new, "upward imports (move the code down, or the unit up in docs/architecture.md):\n" + "\n".join(new)


def test_the_known_upward_imports_still_exist() -> None:
    gone = set(KNOWN_UPWARD) - set(upward_imports())
    assert not gone, f"remove these fixed exceptions from KNOWN_UPWARD and docs/architecture.md: {sorted(gone)}"


def test_the_walker_sees_function_imports_and_skips_type_checking(tmp_path: Path,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    fake = tmp_path / "src" / "vlnpilot"
    (fake / "sub").mkdir(parents=True)
    for name in ("__init__.py", "floor.py", "sub/__init__.py", "sub/x.py", "ground.py", "tc.py"):
        (fake / name).write_text("")
    (fake / "sub" / "y.py").write_text(
        "from typing import TYPE_CHECKING\nfrom . import x\nfrom vlnpilot import floor\n"
        "if TYPE_CHECKING:\n    from vlnpilot.tc import T\n"
        "def f():\n    from vlnpilot.floor import State\n    import vlnpilot.ground\n")
    monkeypatch.setattr(sys.modules[__name__], "PACKAGE", fake)
    assert imports(fake / "sub" / "y.py") == {"vlnpilot.sub.x", "vlnpilot.floor", "vlnpilot.ground"}
    assert unit_of("vlnpilot.sub.x") == "sub/" and unit_of("vlnpilot.floor") == "floor"


TOP_LEVEL_MODULES = {"__init__", "__main__", "cli"}


def test_the_top_level_holds_only_packages_and_the_entry_points() -> None:
    loose = {p.stem for p in PACKAGE.glob("*.py")} - TOP_LEVEL_MODULES
    assert not loose, f"move these modules into a package (docs/architecture.md names one per layer): {sorted(loose)}"


def test_every_layer_below_the_command_line_is_one_package() -> None:
    for units in layers():
        if set(units) <= TOP_LEVEL_MODULES:
            continue
        assert len(units) == 1 and units[0].endswith("/"), f"one package per layer line, not {units}"


def file_graph() -> dict[str, set[str]]:
    """Module -> the vlnpilot modules it imports (TYPE_CHECKING imports skipped: they never run)."""
    return {module_name(p): imports(p) - {module_name(p)} for p in all_modules()}


def import_circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected groups of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in graph.get(node, ()):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            group = []
            while True:
                top = stack.pop()
                on_stack.discard(top)
                group.append(top)
                if top == node:
                    break
            if len(group) > 1:
                found.append(sorted(group))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def test_no_import_circle_between_files() -> None:
    circles = import_circles(file_graph())
    assert not circles, "files that import each other (directly or around a circle):\n" + "\n".join(
        " <-> ".join(c) for c in circles)


def test_the_circle_finder_finds_a_circle() -> None:
    assert import_circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert import_circles({"a": {"b"}, "b": set()}) == []
