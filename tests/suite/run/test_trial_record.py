"""The typed trial record: every shipped trials.jsonl line reads into a TrialRecord and writes back
as the same JSON, key order included; keys a version does not name are kept."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from suite.run.records import REQUIRED_FIELDS, TrialRecord, read_trials

ROOT = Path(__file__).resolve().parents[3]
SHIPPED = sorted(p for p in ROOT.glob("results/**/trials.jsonl"))


def test_the_repository_ships_trial_records_to_read():
    assert len(SHIPPED) >= 3


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_shipped_line_round_trips_exactly(path):
    lines = [line for line in path.read_text(encoding="utf-8").split("\n") if line.strip()]
    records = read_trials(path)
    assert len(records) == len(lines)
    for line, rec in zip(lines, records):
        assert isinstance(rec, TrialRecord)
        assert json.dumps(rec.to_json()) == json.dumps(json.loads(line))


def _line(**more):
    return {"format_version": 1, "trial_id": "t", "planner": "rrt", "scene_seed": 3, "variant": "open", "can_id": 2,
            "problem": "lift", "status": "success", "planning_time_s": 0.5, "metrics": {"path_length_rad": 1.0},
            "stats": {"solver": "RRTConnect"}, **more}


def test_an_unknown_key_is_kept_in_extra_and_written_back_in_place():
    obj = _line(hardware="a laptop", notes="x")
    rec = TrialRecord.from_json(obj)
    assert rec.extra == {"hardware": "a laptop", "notes": "x"}
    assert list(rec.to_json()) == list(obj) and rec.to_json() == obj


def test_fields_are_attributes_and_a_missing_field_is_its_default():
    rec = TrialRecord.from_json(_line())
    assert (rec.planner, rec.status, rec.can_id, rec.problem) == ("rrt", "success", 2, "lift")
    assert rec.succeeded and rec.path is None and rec.task_index is None and rec.certification is None
    assert "path" not in rec.to_json()  # a field the line did not have is not written


def test_a_field_set_after_reading_is_written_and_with_copies_the_inner_dicts():
    rec = TrialRecord.from_json(_line())
    late = rec.with_(status="timeout")
    late.stats["late_by_s"] = 0.2
    assert rec.status == "success" and "late_by_s" not in rec.stats
    assert late.to_json()["status"] == "timeout" and late.to_json()["stats"]["late_by_s"] == 0.2
    rec.attribution = {"engine": "python-fcl"}
    assert rec.to_json()["attribution"] == {"engine": "python-fcl"}


def test_a_line_without_a_required_field_is_one_error_line(tmp_path):
    from scenes.errors import SuiteError

    path = tmp_path / "trials.jsonl"
    obj = _line()
    del obj["can_id"]
    path.write_text(json.dumps(_line()) + "\n" + json.dumps(obj) + "\n")
    with pytest.raises(SuiteError, match="line 2 lacks the field.s. can_id"):
        read_trials(path)
    assert set(REQUIRED_FIELDS) <= {f for f in TrialRecord.__dataclass_fields__}
