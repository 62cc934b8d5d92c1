"""compare --budgets: every planner at every budget, the budget on each trial; bad budgets refused
in one line. Tuned settings are every run's defaults, and --config overrides them."""

from __future__ import annotations

import pytest

from planners.tuned import tuned_settings
from suite.cli import main
from suite.run.runner import CompareConfig, prepare_trials


def test_budgets_multiply_the_trials_and_are_recorded():
    base = CompareConfig(planners=("rrt", "ik"), dataset="recycle-v1:quick")
    plain = prepare_trials(base)
    budgets = prepare_trials(CompareConfig(planners=("rrt", "ik"), dataset="recycle-v1:quick", budgets=(0.2, 1.0)))
    assert len(budgets) == 2 * len(plain)
    assert len({t.trial_id for t in budgets}) == len(budgets)  # a budget is part of the trial's identity
    assert sorted({t.problem.time_limit_s for t in budgets}) == [0.2, 1.0]
    assert all(t.meta["budget_s"] == t.problem.time_limit_s for t in budgets)
    assert {t.meta["problem_id"] for t in budgets} == {t.meta["problem_id"] for t in plain}


@pytest.mark.parametrize("argv, expected", [
    (["--budgets", "0,1"], "budget '0' (seconds): input should be greater than 0"),
    (["--budgets", "0.2,x"], "'x' in '0.2,x' is not a number of seconds"),
    (["--budgets", "1,1"], "names a budget twice"),
    (["--budgets", "0.2,1", "--time-limit-s", "2"], "use one or the other"),
    (["--budgets", "0.2,1", "--execute"], "run them apart"),
])
def test_bad_budgets_are_one_line(argv, expected, tmp_path, capsys):
    try:
        code = main(["compare", "--planners", "rrt", "--out", str(tmp_path / "run"), *argv])
    except SystemExit as exc:  # argparse's own one-line error
        code = exc.code
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert code == 2 and len(err) == 1 and expected in err[0], err
    assert not (tmp_path / "run" / "trials.jsonl").exists()


def test_tuned_settings_are_the_defaults_and_config_overrides_them():
    tuned = tuned_settings("rrt")
    assert tuned, "planners/configs/rrt.yaml ships the tuned settings"
    (default,) = {t.planner_config["range_rad"] for t in prepare_trials(CompareConfig(planners=("rrt",)))}
    assert default == tuned["range_rad"]
    over = prepare_trials(CompareConfig(planners=("rrt",), planner_configs={"rrt": {"range_rad": 0.3}}))
    assert {t.planner_config["range_rad"] for t in over} == {0.3}


def test_a_success_returned_after_the_budget_is_a_timeout(open_transit):
    """A valid path that comes after the budget (an uninterruptible solve) does not count; an invalid
    one stays invalid."""
    from planners.base import PlanResult, PlanStatus
    from planners.worlds import collision_world
    from suite.run.trial import judge_result, late_after_s, make_trial, trial_record

    problem = open_transit.with_(time_limit_s=0.2)
    spec = make_trial(problem, planner="rrt", planner_config={}, run_seed=0)
    straight = PlanResult(PlanStatus.SUCCESS, [problem.q_start, problem.q_goal], {})
    world = collision_world(problem)
    on_time = judge_result(trial_record(spec), spec=spec, world=world, result=straight, planning_time_s=0.2)
    assert on_time["status"] == "success"  # the open transit's straight motion is valid
    late = judge_result(trial_record(spec), spec=spec, world=world, result=straight,
                        planning_time_s=late_after_s(0.2) + 0.01)
    assert late["status"] == "timeout" and late["path"] is None
    assert late["stats"]["late_by_s"] > 0 and "does not count" in late["stats"]["reason"]
    off = PlanResult(PlanStatus.SUCCESS, [problem.q_start, problem.q_goal + 0.01], {})
    late_invalid = judge_result(trial_record(spec), spec=spec, world=world, result=off, planning_time_s=9.0)
    assert late_invalid["status"] == "invalid_solution"
