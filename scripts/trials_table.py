"""The real-VLM trials as tables: outcomes per set (the README's before/after table) and one line per trial.

    python scripts/trials_table.py [trials]            # markdown on stdout
    python scripts/trials_table.py --write [trials]    # the same tables into README.md (the summary),
                                                       # docs/results.md (per row), docs/pilot-memory.md,
                                                       # docs/camera.md (Tello camera beside ideal),
                                                       # docs/events-safety.md (events) and trials/README.md

Reads only trials/SET/ROW/trial.json, so every figure in the README comes from the committed trials.
"""

from __future__ import annotations

import json
import sys
from collections import defaultdict
from pathlib import Path

from vlnpilot.bench.results import wilson_interval

OUTCOMES = ("success", "false_success", "collision", "max_steps", "pilot_error", "unreachable")
LABELS = {  # the sets in the order the tables list them (a set not named here comes last)
    "baseline": "before (baseline)", "after-paper": "after, paper context", "after-plus": "after, plus context",
    "houses-paper": "unseen houses, paper context", "houses-plus": "unseen houses, plus context",
    "houses-long": "unseen houses, longer routes, plus context",
    "houses-fast": "unseen houses, longer routes, plus context, fast profile",
    "houses-objects": "unseen houses, objects of every kind, plus context",
    "stateless-paper": "after, paper context, one fresh pilot per step (stateless)",
    "stateless-plus": "after, plus context, one fresh pilot per step (stateless)",
    "missions": "missions of two stages, cabin, plus context (planning included)",
    "missions-houses": "missions of two stages, unseen houses, plus context (planning included)",
    "objects-tof": "unseen houses, low and wide objects, plus context, ToF range sensor",
    "objects-none": "unseen houses, the same objects, plus context, no range sensor",
    "objects20-tof": "unseen houses, 20 objects of all 12 kinds, plus context, ToF, ranged profile",
    "objects20-none": "unseen houses, the same 20 objects, plus context, no range sensor, fast profile",
    "objects-tv-none": "unseen houses, TV rows after the TV's cue named its own body, no range sensor, fast profile",
    "missions-houses-fast": "missions of two and three stages, unseen houses, plus context, fast profile",
    "stateless-houses-paper": "unseen houses, paper context, one fresh pilot per step (stateless)",
    "stateless-houses-plus": "unseen houses, plus context, one fresh pilot per step (stateless)",
    "tello-cabin": "cabin rows of after-plus, Tello camera model, randomised world",
    "tello-houses": "house routes of houses-plus, Tello camera model, randomised world",
    "tello-objects": "objects of objects20-none, Tello camera model, randomised world, fast profile",
    "tello-stateless-objects": "objects of objects20-none, Tello camera, one fresh pilot per step (stateless)",
    "tello-stale-cabin": "Tello camera, first build (frames one move behind), cabin",
    "tello-stale-houses": "Tello camera, first build (frames one move behind), houses",
    "tello-stale-objects": "Tello camera, first build (frames one move behind), objects, fast profile",
    "events-cabin": "events in the cabin: people, pets, doors that close, lights out, signs",
    "events-houses": "events in unseen houses: people, pets, doors that close, lights out, signs",
}


def _order(name: str) -> tuple[int, str]:
    return (list(LABELS).index(name) if name in LABELS else len(LABELS), name)


def load(root: Path) -> dict[str, list[dict]]:
    sets: dict[str, list[dict]] = defaultdict(list)
    for path in sorted(root.glob("*/*/trial.json")):
        sets[path.parent.parent.name].append({"row": path.parent.name, **json.loads(path.read_text())})
    return dict(sets)


def summary_table(sets: dict[str, list[dict]]) -> str:
    lines = ["| trials | context | pilot memory | scene | episodes | success (95% CI) | false success | collisions | "
             "steps exceeded | mean steps |", "|---|---|---|---|---|---|---|---|---|---|"]
    for name in sorted(sets, key=_order):
        trials = sets[name]
        n = len(trials)
        count = {o: sum(t["outcome"] == o for t in trials) for o in OUTCOMES}
        lo, hi = wilson_interval(count["success"], n)
        mean = sum(t["steps"] for t in trials) / n
        scenes = sorted({t["scene"] for t in trials})
        scene = scenes[0] if len(scenes) == 1 else ", ".join(scenes)
        memory = ", ".join(sorted({t["pilot_memory"] for t in trials}))  # conversation, none, history=N
        lines.append(f"| {LABELS.get(name, name)} | {trials[0]['context']} | {memory} | {scene} | {n} | "
                     f"{count['success']}/{n} = {count['success'] / n:.0%} ({lo:.0%}-{hi:.0%}) | "
                     f"{count['false_success']} | {count['collision']} | {count['max_steps']} | {mean:.1f} |")
    return "\n".join(lines)


def _base_row(row: str) -> str:
    """A trial's row without its repetition number (`living-bathroom-2` -> `living-bathroom`)."""
    return row.rsplit("-", 1)[0] if row[-1].isdigit() and "-" in row else row


def row_table(sets: dict[str, list[dict]]) -> str:
    """Successes per paper-suite row and set (the rows of the paper's Table 4, flown in the cabin, one goal each)."""
    names = sorted((n for n in sets if not n.startswith("missions")
                    and all(t["scene"].startswith("cabin") for t in sets[n])), key=_order)
    per: dict[str, dict[str, list[str]]] = defaultdict(lambda: defaultdict(list))
    for name in names:
        for t in sets[name]:
            per[_base_row(t["row"])][name].append(t["outcome"])
    lines = ["| row | " + " | ".join(LABELS.get(n, n) for n in names) + " |", "|---|" + "---|" * len(names)]
    for row in sorted(per):
        cells = []
        for name in names:
            got = per[row][name]
            cells.append(f"{got.count('success')}/{len(got)}" if got else "")
        lines.append(f"| {row} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def mission_table(root: Path, sets: dict[str, list[dict]]) -> str:
    """The missions flown by real VLMs, planning included (issue 22): mission success, ISR (each stage judged on its
    own: stages judged a success / stages flown) and CSR (stages reached in a row / all stages), per set."""
    lines = ["| missions (real VLMs, planning included) | missions | stages | mission success | ISR | CSR |",
             "|---|---|---|---|---|---|"]
    for name in sorted((n for n in sets if n.startswith("missions")), key=_order):
        stages = reached = flown = wins = 0
        for t in sets[name]:
            result = json.loads((root / name / t["row"] / "summary.json").read_text())["result"]
            stages += result["stages"]
            reached += result["stages_reached"]
            flown += result["stages_reached"] + (t["outcome"] != "success")
            wins += t["outcome"] == "success"
        n = len(sets[name])
        lines.append(f"| {LABELS.get(name, name)} | {n} | {stages} | {wins}/{n} | {reached}/{flown} = "
                     f"{reached / flown:.2f} | {reached}/{stages} = {reached / stages:.2f} |")
    return "\n".join(lines)


MEMORY_COLUMNS = (("paper", "conversation"), ("paper", "none"), ("plus", "conversation"), ("plus", "none"))


def memory_table(sets: dict[str, list[dict]]) -> str:
    """The rows flown by stateless pilots, beside the same rows flown by pilots with memory (issue 28): successes,
    episodes and mean steps per context and pilot memory, over every set and prompt version."""
    every = [t for trials in sets.values() for t in trials if t.get("sensors", "none") == "none"]
    cells: dict[tuple[str, str], dict[tuple[str, str], list[dict]]] = defaultdict(lambda: defaultdict(list))
    for t in every:
        cells[(t["scene"], _base_row(t["row"]))][(t["context"], t["pilot_memory"])].append(t)
    rows = sorted(key for key, got in cells.items() if any(m == "none" for _, m in got))
    head = " | ".join(f"{c}, {'stateless' if m == 'none' else 'memory'}" for c, m in MEMORY_COLUMNS)
    lines = [f"| row (stateless and memory) | scene | {head} |", "|---|---|" + "---|" * len(MEMORY_COLUMNS)]
    for scene, row in rows:
        out = []
        for column in MEMORY_COLUMNS:
            got = cells[(scene, row)][column]
            wins = sum(t["outcome"] == "success" for t in got)
            out.append(f"{wins}/{len(got)} ({sum(t['steps'] for t in got) / len(got):.0f} steps)" if got else "")
        lines.append(f"| {row} | {scene} | " + " | ".join(out) + " |")
    return "\n".join(lines)


def images(trial: dict) -> str:
    """What the pilot's camera showed: the ideal render, or the Tello camera model with its randomisation seed."""
    camera = trial.get("camera") or {}
    if camera.get("model", "ideal") == "ideal":
        return "ideal"
    seed = (camera.get("randomize") or {}).get("seed")
    return f"tello, lag {camera.get('lag_ms', 0):g} ms" + (f", world seed {seed}" if seed is not None else "")


def _same_row(t: dict) -> tuple[str, str, str, str, str, str]:
    return (t["scene"], _base_row(t["row"]), t["context"], t.get("profile", "paper"), t.get("sensors", "none"),
            t["pilot_memory"])


def camera_table(sets: dict[str, list[dict]]) -> str:
    """The rows flown through the Tello camera model (issue 25) beside the same rows (scene, row, context, profile,
    sensor and pilot memory) flown with the ideal camera: successes, episodes and mean steps, every prompt version."""
    every = [t for name, trials in sets.items() if not name.startswith("tello-stale") for t in trials]
    tello = [t for t in every if images(t) != "ideal"]
    ideal: dict[tuple, list[dict]] = defaultdict(list)
    for t in every:
        if images(t) == "ideal":
            ideal[_same_row(t)].append(t)

    def cell(got: list[dict]) -> str:
        wins = sum(t["outcome"] == "success" for t in got)
        return f"{wins}/{len(got)} ({sum(t['steps'] for t in got) / len(got):.0f} steps)" if got else ""

    lines = ["| row (Tello camera and ideal) | scene | ideal camera | Tello camera, randomised |", "|---|---|---|---|"]
    both_ideal, both_tello = [], []
    for key in sorted({_same_row(t) for t in tello}):
        mine = [t for t in tello if _same_row(t) == key]
        both_ideal += ideal[key]
        both_tello += mine
        lines.append(f"| {key[1]} | {key[0]} | {cell(ideal[key])} | {cell(mine)} |")
    if both_tello:
        rate = [sum(t["outcome"] == "success" for t in g) / len(g) for g in (both_ideal, both_tello)]
        lines.append(f"| all | | {cell(both_ideal)} = {rate[0]:.0%} | {cell(both_tello)} = {rate[1]:.0%} |")
    return "\n".join(lines)


def _mover_hovers(trial_dir: Path) -> int:
    """Moves the pilot proposed that the mover shield replaced by a hover (an unsafe command proposed, not flown)."""
    lines = (trial_dir / "episode.jsonl").read_text().splitlines()
    return sum(str(i.get("reason", "")).startswith("mover:")
               for line in lines for i in (json.loads(line).get("interventions") or []))


def events_table(root: Path, sets: dict[str, list[dict]]) -> str:
    """The episodes flown among events (issue 24), per set: outcomes (a goal rightly reported unreachable is a
    success of its own kind), redirecting signs and whether one was obeyed, and what the mover shield did."""
    lines = ["| events (real VLMs) | episodes | events flown | success | unreachable, rightly reported | "
             "false success | steps exceeded | redirecting signs / obeyed | mover collisions | "
             "moves stopped near a mover |", "|---|---|---|---|---|---|---|---|---|---|"]
    for name in sorted((n for n in sets if n.startswith("events")), key=_order):
        trials, kinds = sets[name], defaultdict(int)
        redirect = obeyed = collisions = hovers = 0
        for t in trials:
            summary = json.loads((root / name / t["row"] / "summary.json").read_text())
            for kind in t.get("events", []):
                kinds[kind] += 1
            signs = [e for e in summary["scenario"]["events"] if e["kind"] == "sign" and e.get("redirect")]
            redirect += bool(signs)
            obeyed += bool(summary["result"].get("signs_obeyed"))
            collisions += summary["result"].get("mover_collisions") or 0
            hovers += _mover_hovers(root / name / t["row"])
        count = {o: sum(t["outcome"] == o for t in trials) for o in OUTCOMES}
        flown = ", ".join(f"{k} {v}" for k, v in sorted(kinds.items()))
        lines.append(f"| {LABELS.get(name, name)} | {len(trials)} | {flown} | {count['success']} | "
                     f"{count['unreachable']} | {count['false_success']} | {count['max_steps']} | {redirect} / "
                     f"{obeyed} | {collisions} | {hovers} |")
    return "\n".join(lines)


def trial_lines(sets: dict[str, list[dict]]) -> str:
    lines = ["| trials | row | outcome | steps | prompt version | images | flown |", "|---|---|---|---|---|---|---|"]
    for name in sorted(sets, key=_order):
        for t in sets[name]:
            lines.append(f"| {name} | {t['row']} | {t['outcome']} | {t['steps']} | {t['prompt_hash']} | {images(t)} | "
                         f"{t['started_at'][:16]} |")
    return "\n".join(lines)


def replace_table(text: str, table: str) -> str:
    """`text` with the Markdown table whose header starts as `table`'s (its first cell) replaced by `table`:
    a new set adds a column, so the whole header is not a stable anchor."""
    first_cell = table.splitlines()[0].split("|")[1]
    start = text.index(f"|{first_cell}|")
    end = text.find("\n\n", start)
    return text[:start] + table + (text[end:] if end >= 0 else "\n")


def write_readmes(root: Path) -> None:
    """Put the tables into README.md (summary), docs/results.md (rows) and trials/README.md (one line per trial)."""
    sets = load(root)
    readme, results = root.parent / "README.md", root.parent / "docs" / "results.md"
    readme.write_text(replace_table(replace_table(readme.read_text(), summary_table(sets)),
                                    mission_table(root, sets)))
    results.write_text(replace_table(results.read_text(), row_table(sets)))
    memory = root.parent / "docs" / "pilot-memory.md"
    memory.write_text(replace_table(memory.read_text(), memory_table(sets)))
    camera = root.parent / "docs" / "camera.md"
    camera.write_text(replace_table(camera.read_text(), camera_table(sets)))
    events = root.parent / "docs" / "events-safety.md"
    events.write_text(replace_table(events.read_text(), events_table(root, sets)))
    (root / "README.md").write_text(replace_table((root / "README.md").read_text(), trial_lines(sets)))


def main() -> None:
    args = [a for a in sys.argv[1:] if a != "--write"]
    root = Path(args[0] if args else "trials")
    if "--write" in sys.argv[1:]:
        write_readmes(root)
        return
    sets = load(root)
    print(summary_table(sets))
    print()
    print(row_table(sets))
    print()
    print(memory_table(sets))
    print()
    print(mission_table(root, sets))
    print()
    print(camera_table(sets))
    print()
    print(events_table(root, sets))
    print()
    print(trial_lines(sets))


if __name__ == "__main__":
    main()
