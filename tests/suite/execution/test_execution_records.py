"""The typed records of execution in physics: every shipped execution.json and moving_bin.json reads
into ExecutionRecord and MovingBinRecord, and writes back as the same JSON (moving_bin.json of the
current format); an older moving-bin record reads with its missing counts as not recorded."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from suite.execution.execution_records import (
    ExecutionCan,
    ExecutionRecord,
    read_execution,
    read_moving_bin,
    write_execution,
    write_moving_bin,
)
from suite.execution.moving_bin_records import COUNTED_SINCE_V2, FORMAT_VERSION, MovingBinRecord

ROOT = Path(__file__).resolve().parents[3]
EXECUTIONS = sorted(ROOT.glob("results/**/execution.json"))
MOVING = sorted(ROOT.glob("results/**/moving_bin.json"))


def test_the_repository_ships_records_to_read():
    assert len(EXECUTIONS) >= 2 and len(MOVING) >= 2


@pytest.mark.parametrize("path", EXECUTIONS, ids=lambda p: str(p.parent.relative_to(ROOT)))
def test_every_shipped_execution_round_trips(path, tmp_path):
    raw = json.loads(path.read_text())["executions"]
    records = read_execution(path.parent)
    assert all(isinstance(r, ExecutionRecord) and all(isinstance(c, ExecutionCan) for c in r.cans) for r in records)
    assert [r.to_json() for r in records] == raw
    write_execution(tmp_path, records)
    assert json.loads((tmp_path / "execution.json").read_text())["executions"] == raw


@pytest.mark.parametrize("path", MOVING, ids=lambda p: str(p.parent.relative_to(ROOT)))
def test_every_shipped_moving_bin_file_reads_and_the_current_format_round_trips(path, tmp_path):
    doc = json.loads(path.read_text())
    records = read_moving_bin(path.parent)
    assert len(records) == len(doc["moving_bin"]) and all(isinstance(r, MovingBinRecord) for r in records)
    if doc.get("format_version") == FORMAT_VERSION:
        assert [r.to_json() for r in records] == doc["moving_bin"]
    else:  # an older format: what it did not count is None, not 0; what it held is written back unchanged
        missing = [k for k in COUNTED_SINCE_V2 if k not in doc["moving_bin"][0]]
        assert missing and all(getattr(records[0], k) is None for k in missing)
        for r, raw in zip(records, doc["moving_bin"], strict=True):
            out = r.to_json()
            assert {k: out.get(k) for k in raw} == raw
    write_moving_bin(tmp_path, records)
    assert read_moving_bin(tmp_path) == records


def test_a_failed_execution_and_its_fates():
    from suite.execution.execution_records import NOT_ATTEMPTED, fate_counts

    rec = ExecutionRecord.from_json({"planner": "rrt", "scene_seed": 3, "variant": "open", "cans_total": 2,
                                     "error": "RuntimeError: no grasps"})
    assert rec.error and rec.cans == [] and rec.cans_in_bin == 0
    assert list(rec.to_json()) == ["planner", "scene_seed", "variant", "cans_total", "error"]
    two = rec.with_(cans=[ExecutionCan(0, False, "plate"), ExecutionCan(1, False, "plate")])
    assert fate_counts([two])[NOT_ATTEMPTED] == 2 and rec.cans == []


def test_a_moving_bin_record_keeps_keys_it_does_not_name_and_a_newer_file_is_refused(tmp_path):
    from scenes.errors import SuiteError

    raw = {"planner": "rrt", "scene_seed": 1, "variant": "open", "speed_m_s": 0.1, "scenario": {}, "status": "ok",
           "a_later_field": [1, 2]}
    rec = MovingBinRecord.from_json(raw)
    assert rec.extra == {"a_later_field": [1, 2]} and rec.to_json()["a_later_field"] == [1, 2]
    assert MovingBinRecord.from_json(rec.to_json()) == rec
    (tmp_path / "moving_bin.json").write_text(json.dumps({"format_version": FORMAT_VERSION + 1, "moving_bin": [raw]}))
    with pytest.raises(SuiteError, match="newer than this suite reads"):
        read_moving_bin(tmp_path)


def test_older_moving_bin_records_keep_their_meaning():
    base = {"planner": "rrt", "scene_seed": 3, "variant": "open", "speed_m_s": 0.2, "scenario": {"speed_m_s": 0.2},
            "status": "ok", "cans_total": 2, "cans_in_bin": 1}
    old = MovingBinRecord.from_json(base)  # before releases on the move: the arm released at rest
    from suite.report.summary_moving_bin_paired import release_mode

    assert old.release_mode is None and release_mode(old) == "rest"
    assert release_mode(MovingBinRecord.from_json({**base, "release_mode": "moving"})) == "moving"
    # a dead worker's episode as run_jobs recorded it before the record named its scenario
    dead = MovingBinRecord.from_json({"planner": "rrt", "scene_seed": 3, "variant": "open", "cans_total": 5,
                                      "error": "BrokenProcessPool", "grasps": None, "reperceive": False,
                                      "status": "error", "reason": "BrokenProcessPool", "speed_m_s": 0.2})
    assert dead.status == "error" and dead.scenario == {} and dead.extra["error"] == "BrokenProcessPool"


def test_a_moving_bin_entry_that_is_not_a_record_is_one_error():
    from scenes.errors import SuiteError

    with pytest.raises(SuiteError, match="moving-bin record of 'rrt' on seed 3 is not one"):
        MovingBinRecord.from_json({"planner": "rrt", "scene_seed": 3})
