"""The nominal-trajectory IK planner (the paper's method): a whole pick-and-place cycle of one can
is solved with collision-free paths from q_start to q_goal that follow the nominal gripper
trajectory; bad problems are reported with the right status."""

import dataclasses

import numpy as np
import pytest

from planners.base import PlanStatus
from planners.nominal_ik import NominalIkConfig, knot_times
from planners.registry import make_planner
from scenes.grasp_rule import truth_grasp
from scenes.errors import SuiteError
from suite.problems.cycle import build_problems
from planners.worlds import collision_world


@pytest.fixture(scope="module")
def cycle(open_scene):
    # A budget with a wide margin: the first plan of a scene builds its Drake diagram inside the
    # clock (2 s of a 5 s budget on a busy machine); the planner returns as soon as it is done.
    # (The budget's own test sets its own.)
    scene = open_scene
    return build_problems(scene, [truth_grasp(scene, scene.cans[0])], time_limit_s=60.0, seed=3)


@pytest.fixture(scope="module")
def planner():
    return make_planner("ik")


def test_knot_times_follow_the_schedule():
    t = knot_times(np.array([18.0, 24.0, 30.0]), 0.5)
    assert t[0] == 18.0 and t[-1] == 30.0 and len(t) == 25
    assert np.allclose(np.diff(t), 0.5) and 24.0 in t
    assert list(knot_times(np.array([5.0, 10.0]), 2.0)) == [5.0, 7.5, 10.0]  # 2 steps of 2.5


def test_whole_cycle_of_one_can_is_solved(cycle, planner):
    assert [p.kind for p in cycle] == ["approach", "descend", "lift", "transit", "return"]
    for p in cycle:
        r = planner.plan(p)
        assert r.status is PlanStatus.SUCCESS, (p.name, r.stats)
        world = collision_world(p)
        assert np.array_equal(r.path[0], p.q_start) and np.array_equal(r.path[-1], p.q_goal)
        assert world.path_free(r.path, resolution_rad=0.01) == -1, p.name
        s = r.stats
        assert s["solver"] == "SNOPT" and s["solver_status"] == "kSolutionFound"
        assert s["knots"] >= 2 * (p.waypoints[-1].t - p.waypoints[0].t) + 1  # a knot every 0.5 units
        assert s["ik_solves"] >= s["knots"] - 1 and s["solve_time_s"] > 0
        assert s["goal_deviation_rad"] <= planner.config.goal_tolerance_rad
        # joint steps respect the velocity limits over the knot spacing (1 s per time unit)
        v_max = world.robot.velocity_limits_rad_s
        assert np.all(np.abs(np.diff(r.path, axis=0)) <= v_max * 0.5 + 1e-6)


def test_descend_follows_the_nominal_line_tightly(cycle, planner):
    (p,) = [p for p in cycle if p.kind == "descend"]
    r = planner.plan(p)
    assert r.status is PlanStatus.SUCCESS
    robot = collision_world(p).robot
    p_WG = robot.gripper_pose(r.path)[:, :3, 3]
    p_pre, p_grasp = p.waypoints[0].X_WG[:3, 3], p.waypoints[-1].X_WG[:3, 3]
    # the nominal descend is vertical: every knot stays within the tight box around that line
    tol = planner.config.position_tolerance_near_m
    assert np.all(np.abs(p_WG[:, :2] - p_grasp[:2]) <= tol + 1e-4)
    assert np.all((p_WG[:, 2] >= p_grasp[2] - tol - 1e-4) & (p_WG[:, 2] <= p_pre[2] + tol + 1e-4))
    # and it goes down monotonically in the nominal sense: from the pre-grasp to the grasp height
    assert p_WG[0, 2] - p_WG[-1, 2] == pytest.approx(p_pre[2] - p_grasp[2], abs=2e-3)


def test_start_in_collision_is_invalid_start(cycle, planner):
    p = cycle[3]
    world = collision_world(p)
    rng = np.random.default_rng(5)
    q_bad = next(q for q in world.robot.random_configurations(rng, 500) if not world.is_free(q))
    r = planner.plan(p.with_(q_start=q_bad))
    assert r.status is PlanStatus.INVALID_START and r.path is None


def test_unreachable_grasp_is_ik_failed(open_scene, planner):
    scene = open_scene
    g = truth_grasp(scene, scene.cans[0])
    far = dataclasses.replace(g, X_WG=g.X_WG.copy(), X_WGpre=g.X_WGpre.copy())
    far.X_WG[0, 3] += 2.0
    far.X_WGpre[0, 3] += 2.0
    problems = build_problems(scene, [far], time_limit_s=5.0, seed=3)
    approach = problems[0]
    assert approach.kind == "approach" and approach.pre_status is PlanStatus.IK_FAILED
    assert approach.q_goal is None
    r = planner.plan(approach)
    assert r.status is PlanStatus.IK_FAILED and r.path is None


def test_failing_knot_is_named(cycle):
    # With 1 ms per time unit the joint-step bound is about 1 mrad per knot: the arm stays put
    # while the nominal gripper leaves the 5 cm transit box within the first few knots.
    p = cycle[3]  # transit
    cfg = NominalIkConfig(seconds_per_time_unit=1e-3, max_refinements=0)
    r = make_planner("ik", cfg).plan(p)
    assert r.status is PlanStatus.NO_SOLUTION and r.path is None
    k = r.stats["failed_knot"]
    times = knot_times(np.array([w.t for w in p.waypoints]), cfg.knot_dt_tu)
    assert 1 <= k <= 3 and r.stats["failed_t"] == pytest.approx(times[k])
    assert r.stats["reason"].startswith(f"knot {k} ")


def test_bad_config_is_a_suite_error():
    with pytest.raises(SuiteError, match="knot_dt_tu"):
        NominalIkConfig(knot_dt_tu=0.0)
    with pytest.raises(SuiteError, match="knot_retries=-1 must be a non-negative integer"):
        NominalIkConfig(knot_retries=-1)


def test_same_problem_gives_the_same_path(cycle):
    p = cycle[2]  # lift, holding the can
    a, b = make_planner("ik").plan(p), make_planner("ik").plan(p)
    assert a.status is PlanStatus.SUCCESS and np.array_equal(a.path, b.path)


def test_out_of_budget_is_timeout(cycle):
    # A knot within the first few fails (see test_failing_knot_is_named); with no budget left
    # it gets no retries or refinements.
    p = dataclasses.replace(cycle[3], time_limit_s=1e-6)
    r = make_planner("ik", NominalIkConfig(seconds_per_time_unit=1e-3)).plan(p)
    assert r.status is PlanStatus.TIMEOUT and r.path is None
    k = r.stats["failed_knot"]
    assert r.stats["reason"].startswith(f"knot {k} ") and r.stats["reason"].endswith(": time limit reached")
    assert r.stats["ik_solves"] == k and r.stats["retries"] == r.stats["refinements"] == 0  # one solve a knot


@pytest.fixture(scope="module")
def stalling_knot():
    """A `shelf` lift of recycle-v3 (frozen data, so it stays put) where SNOPT stops at its
    iteration limit from q_prev at knot 2 although the knot is feasible. (Found by planning the
    quick tier's `ik` successes that needed a retry again without retries.)"""
    from suite.problems.dataset import load_dataset

    ds = load_dataset("recycle-v3:quick", time_limit_s=60.0)  # wide margin, as for `cycle`
    return dict(zip(ds.ids, ds.problems))["d2fc5d3ad7cd3895b004"]


def test_a_stalled_knot_is_retried_from_other_guesses(stalling_knot):
    p = stalling_knot
    plain = make_planner("ik", NominalIkConfig(knot_retries=0)).plan(p)
    assert plain.status is PlanStatus.NO_SOLUTION and "IK failed" in plain.stats["reason"]
    r = make_planner("ik").plan(p)
    assert r.status is PlanStatus.SUCCESS and r.stats["retries"] >= 1, r.stats
    assert collision_world(p).path_free(r.path, resolution_rad=0.01) == -1
    assert np.array_equal(r.path[0], p.q_start) and np.array_equal(r.path[-1], p.q_goal)
