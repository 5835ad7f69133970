"""A bench directory read back (`load_bench`): the one reader of bench.json and results.jsonl for the reports.

It sits in `bench/` so that `report/` never knows the bench directory's layout.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vlnpilot.bench.results import RESULTS
from vlnpilot.core.errors import ConfigError, VLNPilotError


@dataclass(frozen=True)
class BenchRow:
    """A row of the paper's Table 4: a (starting room, query) pair of the suite."""

    id: str
    spawn: str
    label: str  # the starting room as the tables name it
    query: str


@dataclass
class BenchData:
    """A bench directory read back: the suite's rows and pilots (from bench.json) and the finished episodes."""

    bench_dir: Path
    name: str
    description: str
    scene_name: str
    pilots: list[str]
    rows: list[BenchRow]
    records: list[dict[str, Any]]
    expected: int | None
    manifest: dict[str, Any]

    def of(self, pilot: str, row: str | None = None) -> list[dict[str, Any]]:
        return [r for r in self.records if r["pilot"] == pilot and (row is None or r["row"] == row)]

    def run_dir(self, record: Mapping[str, Any]) -> Path | None:
        raw = record.get("run_dir")
        if not raw:
            return None
        path = Path(raw)
        return path if path.is_absolute() else self.bench_dir / path

    def groups(self) -> list[tuple[str, list[BenchRow]]]:
        """Rows grouped by consecutive starting room, as the bench tables group them."""
        out: list[tuple[str, list[BenchRow]]] = []
        for row in self.rows:
            if out and out[-1][1][0].spawn == row.spawn:
                out[-1][1].append(row)
            else:
                out.append((row.label, [row]))
        return out


def _scene_or_none(name: str) -> Any | None:
    """The named scene, or None for one that is not built in (the labels then stay spawn names)."""
    from vlnpilot.scene import load_scene

    try:
        return load_scene(name)
    except (VLNPilotError, KeyError, ValueError):
        return None


def load_bench(bench_dir: str | Path) -> BenchData:
    """Read a bench directory (bench.json and results.jsonl, through the bench package's own readers)."""
    from vlnpilot.bench.manifest import read_manifest
    from vlnpilot.bench.results import ResultsLog
    from vlnpilot.bench.suite import suite_from_dict

    bench_dir = Path(bench_dir)
    if not (bench_dir / RESULTS).is_file():
        raise ConfigError(f"{bench_dir} is not a bench directory: {RESULTS} is missing")
    records = ResultsLog(bench_dir / RESULTS).read()
    manifest = read_manifest(bench_dir) or {}
    if manifest.get("suite"):
        suite = suite_from_dict(manifest["suite"], source=str(bench_dir / "bench.json"))
        pilots = [str(p["spec"]) for p in manifest.get("pilots", [])] or list(dict.fromkeys(r["pilot"]
                                                                                              for r in records))
        rows = [BenchRow(r.id, r.spawn, suite.spawn_label(r.spawn), r.query) for r in suite.rows]
        name, description, scene_name = suite.name, suite.description, suite.scene
        expected = manifest.get("episodes")
    else:  # results without a manifest: rows and pilots in the order they appear
        pilots = list(dict.fromkeys(str(r["pilot"]) for r in records))
        scene_name = str(next((r["scene"] for r in records if r.get("scene")), "cabin"))
        scene = _scene_or_none(scene_name)
        rows, seen = [], set()
        for r in records:
            if r["row"] in seen:
                continue
            seen.add(r["row"])
            spawn = str(r.get("spawn") or r["row"])
            label = spawn
            if scene is not None:
                try:
                    label = scene.room(scene.spawn(spawn).room).name.title()
                except VLNPilotError:
                    pass
            rows.append(BenchRow(str(r["row"]), spawn, label, str(r.get("query") or r["row"])))
        first = {spawn: i for i, spawn in reversed(list(enumerate(x.spawn for x in rows)))}
        rows.sort(key=lambda row: first[row.spawn])  # stable: grouped by the spawn's first appearance
        name, description, expected = bench_dir.resolve().name, "", None
    known_rows = {row.id for row in rows}
    records = [r for r in records if r["pilot"] in pilots and r["row"] in known_rows]
    return BenchData(bench_dir=bench_dir, name=name, description=description, scene_name=scene_name, pilots=pilots,
                     rows=rows, records=records, expected=expected, manifest=manifest)
