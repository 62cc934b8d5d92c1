"""Check density: `rrt`'s motion samples in the largest-joint or the L2 norm (`resolution_norm`),
the L2 grid is the one roboplan 0.7.0 checks an edge at, and both planners record the samples
checked per tree edge."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planners.base import PlanStatus
from planners.ompl_adapter import OmplProblem, joint_resolution_for_steps, motion_steps
from planners.ompl_rrt import RRTConnectConfig
from planners.registry import make_planner
from planners.worlds import collision_world, planning_world
from scenes.errors import SuiteError
from scenes.grasp_rule import truth_grasp
from suite.problems.cycle import build_problems


@pytest.fixture(scope="module")
def transit(wall_scene):
    problems = build_problems(wall_scene, [truth_grasp(wall_scene, wall_scene.cans[0])], time_limit_s=60.0, seed=3)
    (p,) = [p for p in problems if p.kind == "transit"]
    return p


def test_motion_steps_in_either_norm():
    d = np.array([0.03, -0.04, 0, 0, 0, 0, 0])
    assert (motion_steps(d, 0.01, "linf"), motion_steps(d, 0.01, "l2")) == (4, 5)
    diagonal = np.full(7, 0.01)  # every joint one step: sqrt(7) = 2.65 steps in L2
    assert (motion_steps(diagonal, 0.01, "linf"), motion_steps(diagonal, 0.01, "l2")) == (1, 3)
    assert motion_steps(np.zeros(7), 0.01, "l2") == 1  # a zero motion: its end, once
    assert motion_steps(np.array([1.0, 0, 0, 0, 0, 0, 0]), 0.05, "l2") == 20


def test_joint_resolution_gives_the_world_exactly_n_steps():
    rng = np.random.default_rng(0)
    for _ in range(20_000):
        d = rng.normal(size=7) * rng.choice([1e-4, 0.01, 0.3, 3.0])
        n = motion_steps(d, float(rng.choice([0.01, 0.05])), "l2")
        res = joint_resolution_for_steps(d, n, 0.01)
        assert max(1, math.ceil(float(np.max(np.abs(d))) / res)) == n  # the world's count
    assert joint_resolution_for_steps(np.zeros(7), 1, 0.05) == 0.05


def test_l2_motion_check_answers_as_every_l2_sample_does(transit):
    """The validator (compiled world, proved skips) against every sample of the L2 grid, each
    checked by the judge's numpy world."""
    judge, checks = collision_world(transit), planning_world(transit)
    ops = {norm: OmplProblem(checks, transit.q_start, transit.q_goal, resolution_rad=0.01, optimizing=False,
                             norm=norm, count_accepted=True) for norm in ("l2", "linf")}
    rng = np.random.default_rng(1)
    q0 = np.asarray(transit.q_start, float)
    answers = []
    for _ in range(60):
        a = q0 + rng.normal(scale=0.05, size=7)
        if not judge.is_free(a):
            continue
        b = a + rng.normal(size=7) * rng.choice([0.02, 0.2, 0.6])
        d = b - a
        for norm, op in ops.items():
            v = op.validator
            n = motion_steps(d, 0.01, norm)
            every = bool(judge.states_free(a + (np.arange(1, n + 1) / n)[:, None] * d).all())
            before = (v.accepted, v.accepted_samples())
            assert v.motion_free(a, b) == every
            assert (v.accepted, v.accepted_samples()) == (before[0] + every, before[1] + (n if every else 0))
            if norm == "l2":
                answers.append(every)
    assert len(answers) >= 40 and any(answers) and not all(answers)
    assert ops["l2"].validator.accepted_samples(3) < ops["l2"].validator.accepted_samples()


def test_rrt_with_l2_steps_records_its_samples_per_edge(transit):
    cfg = RRTConnectConfig(range_rad=1.0, resolution_rad=0.01, resolution_norm="l2", validate_resolution_rad=None)
    r = make_planner("rrt", cfg).plan(transit)
    assert r.status is PlanStatus.SUCCESS
    s = r.stats
    assert (s["resolution_rad"], s["resolution_norm"], s["post_processing"]) == (0.01, "l2", "rope")
    assert s["samples_per_edge_from"] == "counted" and not s["replanned_fine"]
    assert 0 < s["tree_edges"] < s["graph_vertices"]  # one edge per vertex but the two roots
    assert s["samples_per_edge"] == pytest.approx(s["edge_samples"] / s["tree_edges"])
    assert 1 <= s["samples_per_edge"] <= 101  # an edge is at most range_rad = 1.0 rad long (to rounding)
    with pytest.raises(SuiteError, match="resolution_norm must be one of linf, l2, got 'l1'"):
        RRTConnectConfig(resolution_norm="l1")


# --- roboplan ------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def window_problem():
    pytest.importorskip("roboplan")
    from suite.problems import DEFAULT_DATASET
    from suite.problems.dataset import load_dataset

    ds = load_dataset(f"{DEFAULT_DATASET}:quick:family=window,kind=transit")
    return ds.problems[0]


def test_roboplan_checks_an_edge_at_the_l2_grid(window_problem):
    """roboplan 0.7.0's `hasCollisionsAlongPath` checks n = ceil(L2 / step) equal steps: on an
    edge whose last stretch collides, it finds the collision exactly when sample (n - 1) / n
    falls in that stretch."""
    import roboplan.core as rpc

    from planners.roboplan_rrt import roboplan_world

    rw, _ = roboplan_world(window_problem)
    has = rw.scene.hasCollisions
    q0, q1 = np.asarray(window_problem.q_start, float), np.asarray(window_problem.q_goal, float)
    ts = np.linspace(0, 1, 20_001)  # 5e-5 apart: the motion is free up to its first collision
    first = next((i for i, t in enumerate(ts) if has(q0 + t * (q1 - q0))), None)
    assert first, "the straight motion of a window transit collides"
    lo, hi = ts[first - 1], ts[first]
    for _ in range(50):  # where the motion enters the obstacle, by roboplan's own check
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if has(q0 + mid * (q1 - q0)) else (mid, hi)
    t_a, t_b = 0.5 * hi, hi + 0.004
    a, b = q0 + t_a * (q1 - q0), q0 + t_b * (q1 - q0)
    f_in = (hi - t_a) / (t_b - t_a)  # the edge collides from this fraction on, to its end
    length = float(np.linalg.norm(b - a))
    tried = 0
    for step in np.linspace(length / 300, length / 20, 400):
        n = motion_steps(b - a, float(step), "l2")
        if abs((n - 1) / n - f_in) < 1e-6:
            continue  # too close to call
        expected = (n - 1) / n >= f_in  # the last interior sample is inside
        for bisection in (False, True):  # the same samples in either order
            assert rpc.hasCollisionsAlongPath(rw.scene, a, b, float(step), bisection, False) == expected, (step, n)
        tried += 1
    assert tried > 300


def test_roboplan_records_its_computed_samples_per_edge(window_problem):
    from suite.run.trial import run_problem

    rec = run_problem(window_problem.with_(time_limit_s=30.0), planner="roboplan-rrt",
                      planner_config={"range_rad": 1.0, "collision_check_step_rad": 0.05}, run_seed=0)
    s = rec.stats
    assert (s["resolution_rad"], s["resolution_norm"], s["samples_per_edge_from"]) == (0.05, "l2", "computed")
    assert s["post_processing"] == "PathShortcutter(100)"
    assert s["tree_edges"] == s["graph_vertices"] - 2  # every node but the two roots has its edge
    assert s["edge_samples"] == s["roboplan_checks_min"]
    # an edge is at most 1.0 rad: 20 steps of 0.05, 21 where its length rounds just above 1.0 (as
    # it does for roboplan's own count, ceil(distance / step) in C++)
    assert 1 <= s["samples_per_edge"] <= 21
