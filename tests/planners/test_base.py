"""The planner contract's shared stats (`planners.base.shared_stats`, run by `PlannerBase.plan`)."""

import numpy as np
import pytest

from planners.base import FailureReason, PlanResult, PlanStatus, shared_stats


def test_a_failure_without_a_cause_gets_its_status_cause_and_the_solver():
    out = shared_stats(PlanResult(PlanStatus.TIMEOUT, None, {"reason": "budget"}), solver="RRTConnect")
    assert out.stats == {"reason": "budget", "reason_code": FailureReason.BUDGET_SPENT.value, "solver": "RRTConnect"}


def test_a_planner_s_own_cause_and_solver_are_kept():
    stats = {"reason_code": FailureReason.NO_IK_AT_KNOT.value, "solver": "SNOPT"}
    out = shared_stats(PlanResult(PlanStatus.NO_SOLUTION, None, stats), solver="other")
    assert out.stats == stats


def test_a_success_names_no_cause():
    path = np.zeros((2, 7))
    out = shared_stats(PlanResult(PlanStatus.SUCCESS, path, {}), solver=None)
    assert out.stats == {} and out.path is path


def test_a_word_that_is_no_cause_is_the_planner_s_bug():
    with pytest.raises(ValueError):
        shared_stats(PlanResult(PlanStatus.NO_SOLUTION, None, {"reason_code": "bad luck"}), solver=None)
