"""The free transit: a problem kind for a motion between two configurations that belongs to no can's
cycle, numbered by its task index in its scene instead of a can. A cycle's problems keep every id
and seed they had (pinned below from the code before the kind existed)."""

from __future__ import annotations

import numpy as np
import pytest

from planners.base import ALL_KINDS, FREE_TRANSIT, PROBLEM_KINDS, PlanningProblem
from scenes.errors import SuiteError
from scenes.scene import CanPose, Scene
from scenes.spec import load_spec

Q0 = np.linspace(-0.5, 0.5, 7)


def _cycle_problem() -> PlanningProblem:
    scene = Scene(load_spec(variant="open"), 3, (CanPose(0, (0.6, -0.1, 0.08), False, 0.2),
                                                 CanPose(1, (0.55, -0.15, 0.05), True, 1.0)))
    return PlanningProblem(kind="transit", scene=scene, can_id=1, q_start=Q0, q_goal=Q0[::-1].copy(), X_WG_goal=np.eye(4),
                           waypoints=(), held=None, gripper_opening_m=0.066, removed_can_ids=(0,), time_limit_s=5.0,
                           seed=5)


def _free(task_index: int, q_goal=None) -> PlanningProblem:
    scene = Scene(load_spec(variant="gcs-arm"), 0, ())
    return PlanningProblem(kind=FREE_TRANSIT, scene=scene, can_id=None, task_index=task_index, q_start=Q0,
                           q_goal=Q0[::-1].copy() if q_goal is None else q_goal, X_WG_goal=np.eye(4), waypoints=(),
                           held=None, gripper_opening_m=0.107, removed_can_ids=(), time_limit_s=5.0, seed=5)


def test_a_cycle_problem_keeps_its_ids_and_seeds():
    from planners.nominal_ik import _problem_seed
    from planners.ompl_adapter import trial_seed
    from suite.problems.identity import problem_id
    from suite.run.trial import make_trial, trial_record

    p = _cycle_problem()
    assert p.subject == 1 and p.name == "can1/transit" and p.task_index is None
    t = make_trial(p, planner="rrt", planner_config={"a": 1}, run_seed=7)
    assert (t.trial_id, t.problem.seed) == ("89cef0ae96bc898590b5", 394090309)
    assert "task_index" not in trial_record(t) and trial_record(t)["can_id"] == 1
    assert trial_seed(p) == 2181056314 and _problem_seed(p) == [5, 3, 1]
    assert problem_id(p) == "dfdc154d4c52a21e9c20"


def test_a_free_transit_is_numbered_by_its_task():
    from planners.nominal_ik import _problem_seed
    from suite.run.trial import make_trial, trial_record

    assert ALL_KINDS == (*PROBLEM_KINDS, FREE_TRANSIT) and FREE_TRANSIT not in PROBLEM_KINDS
    a, b = _free(0), _free(1)
    assert a.subject == "task0" and a.name == "task0/free"
    ta, tb = (make_trial(p, planner="rrt", planner_config={}, run_seed=7) for p in (a, b))
    assert ta.trial_id != tb.trial_id and ta.problem.seed != tb.problem.seed
    rec = trial_record(ta)
    assert rec["can_id"] is None and rec["task_index"] == 0 and rec["problem"] == FREE_TRANSIT
    assert _problem_seed(a) == [5, len(PROBLEM_KINDS), 0]


@pytest.mark.parametrize("change", [dict(task_index=None), dict(can_id=0), dict(kind="transit"), dict(kind="hop")])
def test_kind_can_and_task_must_agree(change):
    with pytest.raises(SuiteError, match="a free transit \\('free'\\) a task_index and no can_id"):
        _free(0).with_(**change)
    with pytest.raises(SuiteError):
        _cycle_problem().with_(task_index=0)


def test_a_stored_free_transit_reads_back_and_a_cycle_line_is_as_before():
    from suite.problems.identity import problem_id
    from suite.problems.stored import problem_from_record, problem_record

    free = _free(3)
    rec = problem_record(free, {"task": "AS->TS"}, rule="round9-unsigned-zero")
    assert rec["can_id"] is None and rec["task_index"] == 3 and rec["kind"] == FREE_TRANSIT
    back = problem_from_record(rec, free.scene, time_limit_s=1.0)
    assert back.task_index == 3 and back.can_id is None and problem_id(back) == rec["problem_id"] == problem_id(free)
    cycle = problem_record(_cycle_problem(), {}, rule="round9-unsigned-zero")
    assert "task_index" not in cycle and cycle["can_id"] == 1


def test_records_name_a_free_transits_task():
    from suite.run.records import problem_key, problem_number, problem_subject

    from suite.run.records import TrialRecord

    can = TrialRecord(planner="gcs", status="success", scene_seed=0, variant="open", can_id=2, problem="lift")
    free = TrialRecord(planner="gcs", status="success", scene_seed=0, variant="gcs-arm", can_id=None, task_index=4,
                       problem=FREE_TRANSIT)
    assert (problem_number(can), problem_subject(can)) == (2, "can 2")
    assert (problem_number(free), problem_subject(free)) == (4, "task 4")
    assert problem_key(free) == (0, "gcs-arm", 4, FREE_TRANSIT) and problem_key(can) == (0, "open", 2, "lift")
