"""The episode and benchmark reports, without a browser: what the pages hold, escaping, links, plots, video."""

from __future__ import annotations

import json
import re
import shutil
from html.parser import HTMLParser
from pathlib import Path

import pytest

from report_samples import EVIL, expected_table, make_bench, make_run
from vlnpilot.episode import record as episode_record
from vlnpilot.report.html import load_bench, write_bench_report, write_episode_report
from vlnpilot.report.timeline import SHOWN_RAW, load_episode


class _Collect(HTMLParser):
    """Tags and attributes of a page, and its text."""

    def __init__(self) -> None:
        super().__init__()
        self.tags: list[tuple[str, dict[str, str | None]]] = []
        self.text: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append((tag, dict(attrs)))

    def handle_data(self, data: str) -> None:
        self.text.append(data)


def parse(path: Path) -> _Collect:
    p = _Collect()
    p.feed(path.read_text(encoding="utf-8"))
    return p


def local_refs(page: _Collect) -> list[str]:
    refs = [a.get("src") for t, a in page.tags if t in ("img", "script", "video") and a.get("src")]
    refs += [a.get("href") for t, a in page.tags if t in ("a", "link") and a.get("href")]
    return [r for r in refs if r and not r.startswith(("#", "data:"))]


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_run(tmp_path_factory.mktemp("run") / "r", steps=8, outcome="collision", evil=True)


@pytest.fixture(scope="module")
def bench(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_bench(tmp_path_factory.mktemp("bench") / "b", rows=3, reps=1)


def test_episode_report_is_self_contained_and_complete(run: Path) -> None:
    path = write_episode_report(run)
    assert path == run / "report.html" and (run / "floorplan.png").is_file()
    page = parse(path)
    # no network: every reference is a relative file that exists beside the page
    for ref in local_refs(page):
        assert "://" not in ref and not ref.startswith("/"), ref
        assert (run / ref).is_file(), ref
    # one timeline entry per step plus the end, with both frames of what the pilot saw
    steps = [a for t, a in page.tags if t == "article"]
    assert [a["id"] for a in steps] == [f"step-{k}" for k in range(1, 9)] + ["end"]
    imgs = [a["src"] for t, a in page.tags if t == "img"]
    assert "frames/front_000.jpg" in imgs and "frames/rear_007.jpg" in imgs and "frames/front_008.jpg" in imgs
    text = " ".join(page.text)
    for expected in ("Go to the bathroom", "openai:gpt-4.1", "gpt-4.1", "collision", "wall_bedroom_east",
                     "movement C3 is not allowed", "no valid decision", "a propeller would come within",
                     "3 reversals in 6 steps", "Your alignment is good enough", "geometry"):
        assert expected in text, expected


def test_model_text_is_escaped(run: Path) -> None:
    html = write_episode_report(run).read_text(encoding="utf-8")
    assert "<script>window.__pwned" not in html and html.count("<script>") == 1  # the page's own
    page = parse(run / "report.html")
    assert not [a for _, a in page.tags if "onerror" in a]  # no attribute came from model text
    assert EVIL in " ".join(page.text)  # shown literally, as text


def test_report_of_a_run_still_running_and_without_frames(tmp_path: Path) -> None:
    run = make_run(tmp_path / "r", steps=3, finished=False)
    shutil.rmtree(run / "frames")
    page = parse(write_episode_report(run))
    assert not [a for t, a in page.tags if t == "img" and a["src"].startswith("frames/")]
    assert "no front frame recorded" in " ".join(page.text)
    assert "running" in " ".join(page.text)


def test_timeline_shows_what_the_pilot_saw(run: Path) -> None:
    ep = load_episode(run)
    assert len(ep.entries) == 9
    first, third, end = ep.entries[0], ep.entries[2], ep.entries[-1]
    assert first.frames["front"] == "frames/front_000.jpg" and first.pose == ep.summary["start_pose"]
    assert third.decision is None and third.executed == "E" and len(third.failures) == 3
    assert end.step is None and end.frames["front"] == "frames/front_008.jpg"
    assert ep.collision_point() == ep.steps[-1]["pose_after"]
    assert len(ep.trajectory()) == len(ep.trajectory_states()) == 9


def test_timeline_reads_the_keys_the_step_record_writes(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The timeline knows the recorded format from `episode_record`: a key added to the step record is known at
    once; the recorded keys the page has no place for, and keys no step record writes, are shown raw."""
    monkeypatch.setitem(episode_record.ALWAYS_WRITTEN, "wind_mps", lambda record: 0.3)
    run = make_run(tmp_path / "r", steps=2)
    lines = [json.loads(line) for line in (run / "episode.jsonl").read_text().splitlines()]
    every_key = dict.fromkeys(episode_record.step_keys(), None)
    raw = {key: f"recorded {key}" for key in SHOWN_RAW}
    for rec in lines:
        rec.update({**every_key, **rec, **raw, "wind_mps": 0.3, "vendor_note": "from elsewhere"})
    lines[1]["override"] = None  # written on every step, set on few: nothing to show when it is null
    (run / "episode.jsonl").write_text("".join(json.dumps(rec) + "\n" for rec in lines))
    first, second = load_episode(run).entries[:2]
    assert set(first.extra) == {*SHOWN_RAW, "vendor_note"} and first.extra["override"] == "recorded override"
    assert set(second.extra) == {*SHOWN_RAW, "vendor_note"} - {"override"}


def test_episode_video(run: Path) -> None:
    import av
    from PIL import Image

    from vlnpilot.report.video import write_episode_video

    mp4, gif = write_episode_video(run, hold_last=2)
    with av.open(str(mp4)) as container:
        stream = container.streams.video[0]
        frames = [f.to_ndarray(format="rgb24") for f in container.decode(stream)]
        fps, codec = stream.average_rate, stream.codec_context.name
    assert len(frames) == 9 + 1 and fps == 2  # 8 steps, the end, the end held once more
    assert codec == "h264"
    height, width = frames[0].shape[:2]
    assert height % 16 == 0 and width % 16 == 0 and width > 2 * height
    with Image.open(gif) as im:
        assert im.n_frames == 9 and im.width == 720


def test_report_of_a_real_flight(tmp_path: Path, sim) -> None:  # noqa: ANN001 - the shared simulator
    from vlnpilot.core.rundir import Recorder
    from vlnpilot.episode.config import EpisodeConfig
    from vlnpilot.episode.loop import run_episode
    from vlnpilot.pilots.base import make_pilot
    from vlnpilot.tasks.task import parse_query

    task = parse_query("Go to the bathroom", sim.scene)
    run_episode(sim, make_pilot("oracle"), task, EpisodeConfig(max_steps=4), spawn="living_room",
                recorder=Recorder(tmp_path / "run"))
    page = parse(write_episode_report(tmp_path / "run"))
    assert len([a for t, a in page.tags if t == "article"]) == 5
    for ref in local_refs(page):
        assert (tmp_path / "run" / ref).is_file(), ref
    assert "max steps" in " ".join(page.text)


def _table_cells(html: str) -> dict[str, dict[str, tuple[str, int, int]]]:
    pilots = re.findall(r'<th class="pilot" colspan="3">([^<]*)</th>', html)
    out = {}
    for row, body in re.findall(r'<tr[^>]*data-row="([^"]+)">(.*?)</tr>', html):
        ach = re.findall(r'<td class="first ach">([^<]*)</td>', body)
        coll = re.findall(r'<td class="coll">(.*?)</td>', body)
        steps = re.findall(r'<td class="steps">(.*?)</td>', body)
        num = (lambda s: int(s) if s.isdigit() else 0)  # noqa: E731 - '–' is zero
        out[row] = {p: (a, num(c), num(s)) for p, a, c, s in zip(pilots, ach, coll, steps, strict=True)}
    return out


def test_bench_report_table_plots_and_links(bench: Path) -> None:
    path = write_bench_report(bench)
    html = path.read_text(encoding="utf-8")
    assert _table_cells(html) == expected_table(bench)
    for name in ("success_rate", "outcomes", "failures_per_query", "cost_latency"):
        png = bench / "plots" / f"{name}.png"
        assert png.is_file() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    page = parse(path)
    links = [a["href"] for t, a in page.tags if t == "a" and a.get("href", "").endswith("report.html")]
    assert len(links) == len((bench / "results.jsonl").read_text().splitlines())
    for ref in local_refs(page):
        assert (bench / ref).is_file(), ref
    data = load_bench(bench)
    assert [r.label for r in data.rows] == ["Living Room and Kitchen"] * 3


def test_bench_report_without_manifest_or_episodes(tmp_path: Path, bench: Path) -> None:
    copy = tmp_path / "b"
    shutil.copytree(bench, copy)
    (copy / "bench.json").unlink()
    html = write_bench_report(copy, episode_reports=False).read_text(encoding="utf-8")
    assert _table_cells(html) == expected_table(copy)
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "results.jsonl").write_text("")
    assert "No finished episodes" in write_bench_report(empty).read_text(encoding="utf-8")


def test_bench_report_of_a_real_bench(tmp_path: Path) -> None:
    from vlnpilot.bench import bench_command

    suite = tmp_path / "tiny.yaml"
    suite.write_text("name: tiny\nscene: cabin\nrepetitions: 1\nmax_steps: 3\nrows:\n"
                     "  - {id: living-bathroom, spawn: living_room, query: Go to the bathroom}\n")
    out = bench_command(suite=suite, pilots="oracle", out=tmp_path / "bench", executor="inline", render=False,
                        progress=False)
    html = write_bench_report(out).read_text(encoding="utf-8")
    assert _table_cells(html) == expected_table(out) == {"living-bathroom": {"oracle": ("0/1", 0, 1)}}
    record = json.loads((out / "results.jsonl").read_text().splitlines()[0])
    assert (out / record["run_dir"] / "report.html").is_file()
