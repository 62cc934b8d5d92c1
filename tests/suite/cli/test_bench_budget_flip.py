"""`bench budget-flip`: a tuning run read again at a smaller budget, and its input errors."""

from __future__ import annotations

import pytest

from scenes.errors import SuiteError
from suite.bench.budget_flip import _factors, at_smaller_budget
from suite.run.records import TrialRecord


def test_a_success_later_than_the_smaller_budget_is_a_timeout_there():
    base = {"planner": "rrt", "problem": "transit", "scene_seed": 0, "variant": "open", "can_id": 0}
    recs = [TrialRecord.from_json({**base, "status": "success", "planning_time_s": 0.5, "time_limit_s": 5.0}),
            TrialRecord.from_json({**base, "status": "success", "planning_time_s": 4.5, "time_limit_s": 5.0}),
            TrialRecord.from_json({**base, "status": "no_solution", "planning_time_s": 0.1, "time_limit_s": 5.0})]
    out = at_smaller_budget(recs, 4.0)
    assert [r.status for r in out] == ["success", "timeout", "no_solution"]
    assert all(r.time_limit_s == 4.0 for r in out)  # failures count at the new budget
    assert recs[1].status == "success"  # the run's own records are left as they were


@pytest.mark.parametrize("text", ["", "0.8,x", "0.8,-1", "0"])
def test_bad_factors_are_one_line_errors(text):
    with pytest.raises(SuiteError, match="--factors"):
        _factors(text)
    assert _factors("0.8, 1.2") == [0.8, 1.2]
