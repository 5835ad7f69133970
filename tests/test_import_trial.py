"""scripts/import_trial.py records what the trial's pilot remembered (`pilot_memory`), and refuses a bad value in
one line with exit code 2 before it writes anything."""

from __future__ import annotations

import json
import runpy
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
RUN = ROOT / "trials" / "after-paper" / "bathroom-living-1"  # a recorded run: summary.json + episode.jsonl


@pytest.fixture(scope="module")
def script() -> dict:
    return runpy.run_path(str(ROOT / "scripts" / "import_trial.py"))


def test_the_trial_records_its_pilot_memory(script, tmp_path):
    dest = script["import_trial"](RUN, tmp_path / "stateless", "bathroom-living-1", flown_by="a test",
                                  interface="files", scene=None, account=None, memory="none")
    trial = json.loads((dest / "trial.json").read_text())
    assert trial["pilot_memory"] == "none" and trial["interface"] == "files"
    assert (tmp_path / "stateless" / "suite.yaml").is_file()


@pytest.mark.parametrize("memory", [None, "some", "history=0"])
def test_a_missing_or_bad_pilot_memory_is_one_line_and_exit_2(script, tmp_path, capsys, memory):
    with pytest.raises(SystemExit) as stop:
        script["import_trial"](RUN, tmp_path / "set", "row", flown_by="a test", interface="files", scene=None,
                               account=None, memory=memory)
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "conversation, none or history=N" in err
    assert not (tmp_path / "set").exists()


def test_a_run_that_records_its_pilot_memory_gives_the_default(script):
    assert script["pilot_memory"](None, {"pilot_memory": "history=4"}) == "history=4"
    assert script["pilot_memory"]("conversation", {"pilot_memory": "history=4"}) == "conversation"
