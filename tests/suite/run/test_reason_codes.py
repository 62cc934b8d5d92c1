"""Every failed record has one enumerated cause beside its status (`planners.base.FailureReason`)."""

from __future__ import annotations

import pytest

from planners.base import FailureReason
from suite.report.summary import summary_json
from suite.report.summary_tables import reason_code_rows
from suite.run.records import TrialRecord, reason_code

CODES = {r.value for r in FailureReason}


@pytest.mark.parametrize("record,code", [
    ({"status": "success"}, None),
    ({"status": "invalid_solution", "stats": {"reason_code": "search_failed"}}, "path_rejected"),  # the judge's word wins
    ({"status": "invalid_solution", "stats": {"reason": "path_over_limit"}}, "path_over_limit"),
    ({"status": "timeout", "stats": {"late_by_s": 0.4, "reason_code": "budget_spent"}}, "late_path"),
    ({"status": "timeout", "stats": {}}, "budget_spent"),
    ({"status": "crash", "stats": {"reason": "out_of_memory"}}, "out_of_memory"),
    ({"status": "crash", "stats": {"error": "worker exited with code -9"}}, "crash"),
    ({"status": "killed_timeout", "stats": {}}, "killed"),
    ({"status": "timing_failed", "stats": {}}, "timing_failed"),
    ({"status": "no_solution", "stats": {"reason_code": "regions_disconnected"}}, "regions_disconnected"),
    # records written before the causes: their planners' words still say it
    ({"status": "no_solution", "stats": {"reason": "knot 16 (t=41): IK failed (kInfeasibleConstraints)"}}, "no_ik_at_knot"),
    ({"status": "no_solution", "stats": {"reason": "last knot 0.2 rad from q_goal"}}, "goal_not_reached"),
    ({"status": "no_solution", "stats": {"solver": "RRTConnect"}}, "search_failed"),
    ({"status": "no_solution", "stats": {"reason": "my planner gave up"}}, "not_stated"),  # an external word
    ({"status": "no_solution", "stats": {}, "reason_code": "solver_failed"}, "solver_failed"),
])
def test_each_record_gets_one_cause(record, code):
    got = reason_code(TrialRecord(planner="p", problem="transit", scene_seed=0, variant="open", can_id=0, **record))
    assert got == code
    assert got is None or got in CODES


def test_the_summary_counts_causes_per_planner_and_family():
    def rec(planner, family, status, **stats):
        return TrialRecord(planner=planner, variant=family, family=family, status=status, stats=stats,
                           problem="transit", scene_key=family, can_id=0, scene_seed=0, q_start=[0.0] * 7,
                           q_goal=[0.0] * 7, held=False, planning_time_s=1.0, time_limit_s=5.0, metrics={}, path=None)
    records = [rec("a", "wall", "no_solution", reason_code="search_failed"),
               rec("a", "window", "no_solution", reason_code="search_failed"),
               rec("a", "window", "timeout"),
               rec("b", "window", "invalid_solution")]
    headers, rows = reason_code_rows(records, ["a", "b"])
    assert headers == ["planner", "cause", "all", "wall", "window"]
    assert rows == [["a", "search_failed", 2, 1, 1], ["a", "budget_spent", 1, 0, 1], ["b", "path_rejected", 1, 0, 1]]
    js = summary_json(records, pairs=[], planners=["a", "b"])
    assert js["planners"]["a"]["failure_causes"] == {"search_failed": {"wall": 1, "window": 1}, "budget_spent": {"window": 1}}
