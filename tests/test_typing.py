"""What a type checker sees equals what runs: the `if TYPE_CHECKING:` declarations of the classes derived at run
time from the measures (`EpisodeResult`, `PilotSummary`) list the same fields, types and defaults, in order."""

from __future__ import annotations

import ast
import dataclasses
import inspect
from types import ModuleType

import pytest

from vlnpilot.bench import results
from vlnpilot.episode import measures as episode_measures


def _declared(module: ModuleType, name: str) -> list[tuple[str, object, object]]:
    """(name, type, default) of each field of the class `name` declared under `if TYPE_CHECKING:` in `module`."""
    tree = ast.parse(inspect.getsource(module))
    blocks = [node for node in tree.body if isinstance(node, ast.If) and ast.unparse(node.test) == "TYPE_CHECKING"]
    classes = [c for block in blocks for c in block.body if isinstance(c, ast.ClassDef) and c.name == name]
    assert len(classes) == 1, f"{module.__name__} declares no {name} for type checkers"
    out = []
    for stmt in classes[0].body:
        if isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name):
            default = ast.literal_eval(stmt.value) if stmt.value is not None else dataclasses.MISSING
            out.append((stmt.target.id, eval(ast.unparse(stmt.annotation), vars(module)), default))  # noqa: S307
    return out


def _runtime(cls: type) -> list[tuple[str, object, object]]:
    return [(f.name, f.type, f.default) for f in dataclasses.fields(cls)]


@pytest.mark.parametrize(("module", "name", "derive"), [
    (episode_measures, "EpisodeResult", episode_measures.result_type),
    (results, "PilotSummary", results.summary_type),
])
def test_the_type_checkers_declaration_matches_the_derived_class(module: ModuleType, name: str, derive) -> None:
    assert _declared(module, name) == _runtime(derive())
    assert getattr(module, name) is derive()  # and the runtime name is the derived class
