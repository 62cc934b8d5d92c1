"""The OMPL planners: rrt solves a transit over the wall with a collision-free path, bad endpoints
are reported at once, a trial's path depends on its seed alone, an optimizing planner solves."""

import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from planners.base import PlanStatus
from planners.ompl_adapter import drop_collinear, trial_seed
from planners.ompl_rrt import AORRTCConfig, RRTConnectConfig
from planners.registry import make_planner
from scenes.grasp_rule import truth_grasp
from scenes.errors import SuiteError
from suite.problems.cycle import build_problems
from planners.worlds import collision_world

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def problems(wall_scene):
    # A budget with a wide margin: rrt solves these in well under a second, and returns as soon as
    # it has; a success must not hang on the machine's speed. (Tests of a budget set their own.)
    scene = wall_scene
    return build_problems(scene, [truth_grasp(scene, scene.cans[0])], time_limit_s=60.0, seed=3)


@pytest.fixture(scope="module")
def transit(problems):
    (p,) = [p for p in problems if p.kind == "transit"]
    assert p.pre_status is None
    return p


def _colliding_configuration(world, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    for q in world.robot.random_configurations(rng, 500):
        if not world.is_free(q):
            return q
    raise AssertionError("no colliding configuration among 500 random ones")


def test_rrt_solves_transit_over_the_wall(transit):
    world = collision_world(transit)
    # the straight motion hits the wall: the planner has to go around it
    assert world.path_free(np.array([transit.q_start, transit.q_goal]), resolution_rad=0.01) >= 0
    r = make_planner("rrt").plan(transit)
    assert r.status is PlanStatus.SUCCESS
    assert r.path.ndim == 2 and r.path.shape[1] == 7 and len(r.path) >= 3
    assert np.array_equal(r.path[0], transit.q_start) and np.array_equal(r.path[-1], transit.q_goal)
    assert world.path_free(r.path, resolution_rad=0.01) == -1
    s = r.stats
    assert s["solver"] == "RRTConnect" and s["waypoints"] == len(r.path) and not s["interpolated"]
    assert s["collision_checks"] > 0 and s["solve_time_s"] > 0 and s["simplify_time_s"] >= 0
    assert 0 < s["length_after_rad"] <= s["length_before_rad"] + 1e-9
    assert s["length_after_rad"] == pytest.approx(np.linalg.norm(np.diff(r.path, axis=0), axis=1).sum())


def test_interpolated_path_keeps_joint_steps_small(transit):
    r = make_planner("rrt", RRTConnectConfig(interpolate_rad=0.05)).plan(transit)
    assert r.status is PlanStatus.SUCCESS and r.stats["interpolated"]
    assert np.max(np.abs(np.diff(r.path, axis=0))) <= 0.05 + 1e-12
    assert np.array_equal(r.path[0], transit.q_start) and np.array_equal(r.path[-1], transit.q_goal)


@pytest.mark.parametrize("end", ["start", "goal"])
def test_endpoint_in_collision_is_reported_at_once(transit, end):
    world = collision_world(transit)
    q = _colliding_configuration(world, seed=5)
    problem = transit.with_(q_start=q) if end == "start" else transit.with_(q_goal=q)
    r = make_planner("rrt").plan(problem)
    assert r.status is (PlanStatus.INVALID_START if end == "start" else PlanStatus.INVALID_GOAL)
    assert r.path is None and r.stats["reason"] == "in collision"
    assert r.stats["reason_code"] == "endpoint_in_collision" and r.stats["solver"] == "RRTConnect"
    # at once: before any search (no solve, no collision checks of its own in the stats)
    assert set(r.stats) == {"reason", "reason_code", "solver"}


def test_ik_failure_passes_through(transit):
    r = make_planner("rrt").plan(transit.with_(q_goal=None))
    assert r.status is PlanStatus.IK_FAILED and r.path is None
    assert r.stats["reason_code"] == "no_goal_ik"


def test_same_seed_same_path_different_seed_other_path(problems, transit):
    planner = make_planner("rrt")
    first = planner.plan(transit)
    # other trials in between must not change this trial's result
    for p in problems:
        if p.kind in ("approach", "return"):
            planner.plan(p)
    second = planner.plan(transit)
    assert first.status is second.status is PlanStatus.SUCCESS
    assert np.array_equal(first.path, second.path)
    other = planner.plan(transit.with_(seed=transit.seed + 1))
    assert trial_seed(transit.with_(seed=transit.seed + 1)) != trial_seed(transit)
    assert other.status is PlanStatus.SUCCESS
    assert other.path.shape != first.path.shape or not np.allclose(other.path, first.path)


def test_same_seed_same_path_across_processes(transit, tmp_path):
    """A fresh process (OMPL seeded differently at start) gives the same path; nothing OMPL
    allocated is reported leaked at exit."""
    here = make_planner("rrt").plan(transit)
    (tmp_path / "p.pkl").write_bytes(pickle.dumps(transit))
    code = (
        "import pickle, sys\n"
        "from ompl import util as ou\n"
        "ou.RNG.setSeed(987654)\n"
        "from planners.registry import make_planner\n"
        f"p = pickle.loads(open({str(tmp_path / 'p.pkl')!r}, 'rb').read())\n"
        "r = make_planner('rrt').plan(p)\n"
        "sys.stdout.write(r.status.value + ' ' + r.path.tobytes().hex())\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=300)
    assert out.returncode == 0, out.stderr
    status, hexpath = out.stdout.split()
    assert status == "success"
    assert np.array_equal(np.frombuffer(bytes.fromhex(hexpath)).reshape(-1, 7), here.path)
    assert "leak" not in out.stderr, out.stderr


def test_optimizing_planner_solves_transit(transit):
    budget_s = 1.0  # over ten times what its first solution takes on a busy 2-core machine
    r = make_planner("aorrtc", AORRTCConfig(time_limit_s=budget_s)).plan(transit)
    assert r.status is PlanStatus.SUCCESS
    assert collision_world(transit).path_free(r.path, resolution_rad=0.01) == -1
    assert np.array_equal(r.path[0], transit.q_start) and np.array_equal(r.path[-1], transit.q_goal)
    assert r.stats["solver"] == "AORRTC" and r.stats["best_cost"] > 0
    # it runs to its budget (less the simplification share)
    assert r.stats["solve_time_s"] >= 0.8 * budget_s


def test_drop_collinear_keeps_corners_only():
    a, b, c = np.zeros(7), np.full(7, 1.0), np.array([1.0, 2, 1, 1, 1, 1, 1])
    Q = np.vstack([a, 0.25 * b, 0.5 * b, b, 0.5 * (b + c), c])
    assert np.array_equal(drop_collinear(Q), np.vstack([a, b, c]))


def test_bad_config_is_a_user_error():
    with pytest.raises(SuiteError, match="resolution_rad"):
        RRTConnectConfig(resolution_rad=0.0)
    with pytest.raises(SuiteError, match="simplifier"):
        RRTConnectConfig(simplifier="magic")
    with pytest.raises(SuiteError, match="takes a RRTConnectConfig"):
        make_planner("rrt", AORRTCConfig())


def test_optimizing_planner_records_its_best_cost_over_time(transit):
    # 2 s: slices of about 0.1 s, so that even a slow machine's overrun of each leaves several
    r = make_planner("bitstar").plan(transit.with_(time_limit_s=2.0))
    points = r.stats["progress"]
    assert 5 <= len(points) <= 25  # one per slice of the budget (20 slices)
    times = [t for t, _ in points]
    assert times == sorted(times) and 0 < times[-1] <= r.stats["solve_time_s"]  # within the solve
    costs = [c for _, c in points if c is not None]
    assert r.status is not PlanStatus.SUCCESS or costs  # a success had a solution at some slice
    assert all(b <= a + 1e-9 for a, b in zip(costs, costs[1:]))  # the best cost never worsens
    assert "progress" not in make_planner("rrt").plan(transit).stats  # a feasibility planner has none


def test_aorrtc_returns_the_free_straight_motion(open_transit):
    world = collision_world(open_transit)
    if not world.motion_free(open_transit.q_start, open_transit.q_goal, resolution_rad=0.01):
        pytest.skip("this open transit is not straight-line free")
    # OMPL's AORRTC alone reports "Zero-length path found" (a failure) on such a problem.
    r = make_planner("aorrtc", AORRTCConfig(time_limit_s=0.5)).plan(open_transit)
    assert r.status is PlanStatus.SUCCESS and r.stats["direct"] is True
    assert np.array_equal(r.path, np.stack([open_transit.q_start, open_transit.q_goal]))


def _free_ends_across(world, q0: np.ndarray, q1: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Two free states a, b on the straight motion q0 -> q1 with a blocked stretch between them and
    max |b - a| <= 0.2 rad: the last free sample before its first collision, the first after."""
    n = int(np.ceil(np.max(np.abs(q1 - q0)) / 1e-3))
    Q = q0 + np.linspace(0.0, 1.0, n + 1)[:, None] * (q1 - q0)
    free = np.array([world.is_free(q) for q in Q])
    hit = np.flatnonzero(~free)
    if len(hit) == 0 or hit[0] == 0:
        return None
    after = np.flatnonzero(free[hit[0]:])
    if len(after) == 0:
        return None
    a, b = Q[hit[0] - 1], Q[hit[0] + after[0]]
    return (a, b) if np.max(np.abs(b - a)) <= 0.2 else None


def test_certified_motion_check_rejects_what_the_samples_miss(problems):
    from planners.ompl_adapter import OmplProblem

    found = None
    for p in problems:  # a straight start-goal motion through a thin part of the scene
        world = collision_world(p)
        found = found or (_free_ends_across(world, np.asarray(p.q_start), np.asarray(p.q_goal))
                          if p.pre_status is None else None)
        if found:
            break
    if found is None:
        pytest.skip("no problem's straight motion crosses a blocked stretch of at most 0.2 rad")
    a, b = found
    step = float(np.max(np.abs(b - a)))  # one step: the samples are the two free ends
    checks = {}
    for certify in (False, True):
        op = OmplProblem(world, p.q_start, p.q_goal, resolution_rad=step, optimizing=False, certify=certify)
        checks[certify] = (op.validator.motion_free(a, b), op.validator.certified_calls)
    assert checks[False] == (True, 0)  # the field's rule: both samples free
    assert checks[True] == (False, 1)  # the exact check finds the collision between them


def test_rrt_with_certified_motions_returns_a_certified_path(transit):
    from suite.scoring.validate import certify_path

    r = make_planner("rrt", RRTConnectConfig(motion_check="certified")).plan(transit)
    assert r.status is PlanStatus.SUCCESS and r.stats["motion_check"] == "certified"
    assert r.stats["certified_motion_checks"] > 0 and r.stats["certify_s"] > 0
    assert certify_path(r.path, collision_world(transit))["verdict"] == "certified"
    assert make_planner("rrt").plan(transit).stats["certified_motion_checks"] == 0
    with pytest.raises(SuiteError, match="motion_check must be one of samples, certified, got 'exact'"):
        RRTConnectConfig(motion_check="exact")
