"""Kinematic trajectory optimization: transits (over the wall too) come out collision-free at the
validator's resolution, because the dense python-fcl re-check catches what SNOPT calls a success
between its constraint samples and the re-solve repairs it; bad problems get the right status."""

import dataclasses

import numpy as np
import pytest

from planners.base import PlanStatus
from planners.registry import make_planner
from planners.trajopt import TrajoptConfig, colliding_s
from scenes.grasp_rule import truth_grasp
from scenes.errors import SuiteError
from suite.problems.cycle import build_problems
from planners.worlds import collision_world


def _check_path(problem, r, output_samples=100):
    world = collision_world(problem)
    assert r.status is PlanStatus.SUCCESS, r.stats
    assert r.path.shape == (output_samples, 7)
    assert np.array_equal(r.path[0], problem.q_start) and np.array_equal(r.path[-1], problem.q_goal)
    assert world.path_free(r.path, resolution_rad=0.01) == -1
    assert np.all(r.path >= world.robot.lower_rad - 1e-9) and np.all(r.path <= world.robot.upper_rad + 1e-9)


@pytest.mark.parametrize("variant", ["open", "wall"])
def test_transit_is_solved_collision_free(variant, open_transit, wall_transit):
    # a budget with a wide margin (it solves in well under a second): a success is not a race
    p = (open_transit if variant == "open" else wall_transit).with_(time_limit_s=60.0)
    r = make_planner("trajopt").plan(p)
    _check_path(p, r)
    s = r.stats
    assert s["solver"] == "SNOPT" and s["initial_guess"] == "straight"
    assert s["colliding_samples"][-1] == 0 and len(s["colliding_samples"]) == s["resolves"] + 1
    assert s["constraint_samples"] >= TrajoptConfig().num_collision_samples
    assert TrajoptConfig().min_duration_s <= s["duration_s"] <= TrajoptConfig().max_duration_s
    assert s["cost"] > 0 and s["solve_time_s"] > 0
    # every SNOPT evaluation queries each distance-constraint sample once; their time is replayed
    assert s["drake_distance_queries"] >= s["constraint_samples"] and s["drake_distance_queries"] % 1 == 0
    assert 0 < s["drake_distance_query_s"] < float("inf")


def test_a_solve_running_past_the_budget_is_stopped_there(wall_transit):
    # SNOPT's first solve of this transit takes some 0.3 s; with a 0.05 s budget it used to run to
    # its end (and re-solves beyond), now the deadline callback aborts it. (How soon after the
    # deadline it stops depends on the machine: a benchmark's figure, not this test's.)
    p = wall_transit.with_(time_limit_s=0.05)
    r = make_planner("trajopt").plan(p)
    assert r.status is PlanStatus.TIMEOUT and r.path is None, r.stats
    assert r.stats["solve_interrupted"] and r.stats["reason"] == "time limit reached"


def test_straight_line_through_the_wall_is_caught(wall_transit):
    world = collision_world(wall_transit)
    line = np.linspace(wall_transit.q_start, wall_transit.q_goal, 100)
    s = np.linspace(0, 1, 100)
    bad = colliding_s(world, line, s, resolution_rad=0.01)
    # the held can crosses the wall in the middle of the motion, and only there
    assert len(bad) > 0 and world.path_free(line, resolution_rad=0.01) >= 0
    assert 0.05 < bad.min() <= bad.max() < 0.95
    assert world.is_free(line[0]) and world.is_free(line[-1])
    # the s values are those of the validator's own interpolation
    first = world.path_free(line, resolution_rad=0.01)
    dense = world.interpolate(line, 0.01)
    assert not world.is_free(dense[first])


def test_dense_recheck_repairs_what_few_samples_miss(wall_scene):
    # One constraint sample: on some transit of the scene SNOPT converges (info 1, "success") on
    # a path through the wall (on others it stops at its iteration limit) ...
    # (a budget with a wide margin: a solve cut short by a busy machine would prove nothing)
    single = TrajoptConfig(num_collision_samples=1, max_resolves=0)
    for can in wall_scene.cans:
        problems = build_problems(wall_scene, [truth_grasp(wall_scene, can)], time_limit_s=60.0, seed=3)
        transit = next(p for p in problems if p.kind == "transit")
        once = make_planner("trajopt", single).plan(transit)
        if once.stats["snopt_info"] == [1]:
            break
    else:
        pytest.fail("SNOPT converged on no single-sample transit of the scene")
    assert once.status is PlanStatus.NO_SOLUTION and once.path is None
    assert once.stats["solver_converged"]
    assert once.stats["colliding_samples"][0] > 0
    assert "collides" in once.stats["reason"]
    # ... and the re-solve with samples added where it collided fixes it.
    fixed = make_planner("trajopt", TrajoptConfig(num_collision_samples=1)).plan(transit)
    _check_path(transit, fixed)
    assert fixed.stats["resolves"] >= 1 and fixed.stats["colliding_samples"][0] > 0
    assert fixed.stats["constraint_samples"] > 1


def test_via_point_is_near_the_middle_waypoint(wall_transit):
    from planners.worlds import drake_plan_scene

    planner = make_planner("trajopt", TrajoptConfig(initial_guess="via_waypoints"))
    ds, _, plant_context = planner._plant(wall_transit)
    q = planner._via_point(wall_transit, ds.plant, plant_context, ds.plant.GetFrameByName("body", ds.wsg))
    assert q is not None and ds is drake_plan_scene(wall_transit)
    world = collision_world(wall_transit)
    X_WG = world.robot.gripper_pose(q)
    X_mid = wall_transit.waypoints[1].X_WG
    cfg = planner.config
    assert np.all(np.abs(X_WG[:3, 3] - X_mid[:3, 3]) <= cfg.via_position_tolerance_m + 1e-4)
    cos = (np.trace(X_mid[:3, :3].T @ X_WG[:3, :3]) - 1) / 2
    assert np.arccos(np.clip(cos, -1, 1)) <= cfg.via_orientation_tolerance_rad + 1e-3
    assert world.is_free(q)  # above the wall, clear of it


def test_start_in_collision_is_invalid_start(wall_transit):
    world = collision_world(wall_transit)
    rng = np.random.default_rng(5)
    q_bad = next(q for q in world.robot.random_configurations(rng, 500) if not world.is_free(q))
    r = make_planner("trajopt").plan(wall_transit.with_(q_start=q_bad))
    assert r.status is PlanStatus.INVALID_START and r.path is None


def test_unreachable_grasp_is_ik_failed(open_scene):
    scene = open_scene
    g = truth_grasp(scene, scene.cans[0])
    far = dataclasses.replace(g, X_WG=g.X_WG.copy(), X_WGpre=g.X_WGpre.copy())
    far.X_WG[0, 3] += 2.0
    far.X_WGpre[0, 3] += 2.0
    problems = build_problems(scene, [far], time_limit_s=5.0, seed=3)
    assert all(p.pre_status is PlanStatus.IK_FAILED for p in problems)
    r = make_planner("trajopt").plan(problems[0])
    assert r.status is PlanStatus.IK_FAILED and r.path is None


@pytest.mark.parametrize("bad", [dict(initial_guess="curvy"), dict(spline_order=5, num_control_points=4),
                                 dict(min_duration_s=2.0, max_duration_s=1.0), dict(min_distance_m=0.0)])
def test_bad_config_is_a_suite_error(bad):
    with pytest.raises(SuiteError):
        TrajoptConfig(**bad)
