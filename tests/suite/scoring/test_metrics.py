"""Metrics: cross-checked against OMPL (length, smoothness) and Drake (clearance), and against
closed forms for the gripper's path, rotation, goal error and jerk; `score` returns every metric
of the registry."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from scenes.collision.world import CollisionWorld
from scenes.generate import generate_scene
from scenes.grasp_rule import truth_grasp
from scenes.ik import Q_READY
from scenes.robot_model import load_robot
from scenes.scene import HeldCan
from scenes.spec import load_spec
from suite.scoring import metrics, polyline, smoothness
from suite.scoring.definitions import METRICS, NOT_FROM_PATH
from suite.scoring.timing import TimedTrajectory, time_parameterize

ROBOT = load_robot()


def random_path(seed: int, n: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return Q_READY + np.cumsum(rng.uniform(-0.3, 0.3, size=(n, 7)), axis=0)


def ompl_path(states: np.ndarray):
    """An OMPL PathGeometric over RealVectorStateSpace(7) holding the given states."""
    from ompl import base as ob
    from ompl import geometric as og

    space = ob.RealVectorStateSpace(7)
    bounds = ob.RealVectorBounds(7)
    bounds.setLow(-10.0)
    bounds.setHigh(10.0)
    space.setBounds(bounds)
    si = ob.SpaceInformation(space)
    path = og.PathGeometric(si)
    # PathGeometric.append clones the state (PathGeometric.cpp), so one scratch state serves for
    # all. It is not freed by hand: the Python wrapper owns it, and si.freeState on it followed by
    # the wrapper's own cleanup crashes (measured with these nanobind bindings).
    scratch = space.allocState()
    for q in states:
        for i, v in enumerate(q):
            scratch[i] = float(v)
        path.append(scratch)
    assert path.getStateCount() == len(states)
    return path


@pytest.mark.parametrize("seed,n", [(0, 3), (1, 12), (2, 50)])
def test_length_and_smoothness_equal_ompl(seed, n):
    path = random_path(seed, n)
    p = ompl_path(path)
    assert polyline.path_length_rad(path) == pytest.approx(p.length(), rel=1e-9)
    assert smoothness.ompl_smoothness(path) == pytest.approx(p.smoothness(), rel=1e-9)
    resampled = polyline.resample_uniform(path, 0.05)
    assert smoothness.ompl_smoothness(resampled) == pytest.approx(ompl_path(resampled).smoothness(), rel=1e-9)
    assert smoothness.ompl_smoothness(resampled) > 0


def test_smoothness_does_not_depend_on_the_waypoint_count():
    path = random_path(3, 4)
    # The same polyline with collinear waypoints added (what OMPL's interpolate() emits).
    fine = np.vstack([np.linspace(a, b, 9)[:-1] for a, b in zip(path[:-1], path[1:])] + [path[-1:]])
    assert len(fine) == 25
    assert polyline.path_length_rad(fine) == pytest.approx(polyline.path_length_rad(path), rel=1e-12)
    a = smoothness.ompl_smoothness(polyline.resample_uniform(path, 0.05))
    b = smoothness.ompl_smoothness(polyline.resample_uniform(fine, 0.05))
    assert b == pytest.approx(a, rel=1e-9)
    # On the raw waypoints OMPL's formula does depend on them.
    assert smoothness.ompl_smoothness(fine) != pytest.approx(smoothness.ompl_smoothness(path), rel=1e-3)


def test_smoothness_of_a_straight_line_is_zero_and_of_a_corner_is_known():
    line = np.linspace(np.zeros(7), np.ones(7), 5)
    assert smoothness.ompl_smoothness(line) == 0.0
    e0, e1 = np.eye(7)[0], np.eye(7)[1]
    corner = np.array([np.zeros(7), e0, e0 + e1])  # a right angle, unit segments
    assert smoothness.ompl_smoothness(corner) == pytest.approx((2 * (math.pi / 2) / 2) ** 2, rel=1e-12)


def test_gripper_path_length_and_rotation_closed_form():
    # Turning joint 1 alone swings the gripper on a horizontal circle about the base's z axis.
    q0 = Q_READY.copy()
    dq = 1.2
    path = np.array([q0, q0 + dq * np.eye(7)[0]])
    X = ROBOT.gripper_pose(polyline.densify(path, 0.001))
    radius = np.linalg.norm(ROBOT.gripper_pose(q0)[:2, 3])
    assert metrics.ee_path_length_m(X) == pytest.approx(radius * dq, rel=1e-6)
    assert metrics.ee_rotation_deg(X) == pytest.approx(math.degrees(dq), rel=1e-9)
    # Turning joint 7 alone spins the gripper in place.
    path7 = np.array([q0, q0 + 0.9 * np.eye(7)[6]])
    X7 = ROBOT.gripper_pose(polyline.densify(path7, 0.05))
    assert metrics.ee_rotation_deg(X7) == pytest.approx(math.degrees(0.9), rel=1e-9)
    assert metrics.ee_path_length_m(X7) < 0.05 * 0.9  # the gripper origin is near joint 7's axis


def test_goal_error():
    X_goal = ROBOT.gripper_pose(Q_READY)
    X = X_goal.copy()
    X[:3, 3] += [0.003, -0.004, 0.0]
    c, s = math.cos(math.radians(2.0)), math.sin(math.radians(2.0))
    X[:3, :3] = X[:3, :3] @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    err_m, err_deg = metrics.goal_error(X, X_goal)
    assert err_m == pytest.approx(0.005, rel=1e-9)
    assert err_deg == pytest.approx(2.0, rel=1e-9)


def test_jerk_of_a_cubic_trajectory():
    t = np.arange(0.0, 2.0 + 1e-12, 0.01)
    q = np.outer(t**3, np.arange(1, 8))  # joint i: (i+1) t^3, jerk 6 (i+1)
    qdd = np.outer(6 * t, np.arange(1, 8))
    tr = TimedTrajectory(status="ok", reason="", duration_s=2.0, t_s=t, q=q, qd=np.gradient(q, t, axis=0),
                         qdd=qdd, dt_s=0.01, velocity_ratio=0.0, acceleration_ratio=0.0, path_deviation_rad=0.0,
                         timing_time_s=0.0, n_gridpoints=0)
    assert smoothness.jerk_max(tr) == pytest.approx(42.0, rel=1e-9)
    assert smoothness.jerk_sq_integral(tr) == pytest.approx(36 * sum(k * k for k in range(1, 8)) * 2.0, rel=1e-9)


@pytest.fixture(scope="module")
def scene():
    return generate_scene(load_spec(variant="wall"), seed=3, check_reachable=False)


def drake_clearances(ds, Q: np.ndarray) -> np.ndarray:
    """Robot-vs-scene signed distance from Drake's scene graph, per configuration.

    Robot geometries belong to the iiwa or WSG model instances or to the held can; scene ones to
    the world body or the cans. Filtered pairs are not reported by Drake. All our shape pairs
    (box, cylinder, capsule, sphere) are supported by this query in double precision.
    """

    plant, sg = ds.plant, ds.scene_graph
    ctx = ds.diagram.CreateDefaultContext()
    pctx = plant.GetMyMutableContextFromRoot(ctx)
    sctx = sg.GetMyContextFromRoot(ctx)
    inspector = sg.model_inspector()
    robot_instances = {ds.iiwa, ds.wsg}

    def is_robot(gid):
        body = plant.GetBodyFromFrameId(inspector.GetFrameId(gid))
        return body.model_instance() in robot_instances or body.name() == "held_can"

    def fixed(gid):  # links whose distance to the scene does not depend on q: not in clearance
        return plant.GetBodyFromFrameId(inspector.GetFrameId(gid)).name() in ("iiwa_link_0", "iiwa_link_1")

    out = []
    for q in Q:
        plant.SetPositions(pctx, q)
        query = sg.get_query_output_port().Eval(sctx)
        best = np.inf
        for pair in query.ComputeSignedDistancePairwiseClosestPoints():
            ra, rb = is_robot(pair.id_A), is_robot(pair.id_B)
            if ra != rb and not fixed(pair.id_A) and not fixed(pair.id_B):
                best = min(best, pair.distance)
        out.append(best)
    return np.array(out)


@pytest.mark.parametrize("holding", [False, True], ids=["empty", "holding"])
def test_clearance_matches_drake(scene, holding):
    from scenes.drake_scene import build_drake_scene

    held = None
    if holding:
        can = scene.cans[0]
        held = HeldCan.from_grasp(can, truth_grasp(scene, can).X_WG)
    opening = 0.07 if holding else None
    world = CollisionWorld(scene, gripper_opening_m=opening, held=held)
    ds = build_drake_scene(scene, mode="plan", cameras=False, gripper_opening_m=opening, held=held)
    # Uniform over the joint limits: many configurations come close to the table, plate, bin,
    # wall or cans (away from the ready pose the constant link-1-to-table gap dominates).
    Q = ROBOT.random_configurations(np.random.default_rng(11), 150)
    theirs = drake_clearances(ds, Q)
    # Free and shallow-contact configurations only: for deep penetration (beyond a few cm) the
    # two engines' penetration depths differ (see the report); validated paths never penetrate.
    keep = theirs > -0.02
    Q, theirs = Q[keep], theirs[keep]
    ours = world.clearances(Q)
    assert len(Q) >= 80 and (theirs < 0.03).sum() >= 10
    np.testing.assert_allclose(ours, theirs, atol=1e-3)


def test_clearance_minimum_equals_the_brute_force_minimum_over_the_fine_samples(scene):
    # A path from the ready pose to a configuration near an obstacle and on: the clearance varies.
    world = CollisionWorld(scene)
    Q = ROBOT.random_configurations(np.random.default_rng(2), 200)
    c = world.clearances(Q)
    q_near = Q[np.argmin(np.where(c > 0.005, c, np.inf))]
    path = np.array([Q_READY, q_near, 0.5 * (q_near + Q_READY) + 0.3])
    coarse = polyline.arc_samples(path, 0.05)
    fine = polyline.arc_samples(path, 0.05, per_step=5)
    brute = world.clearances(fine.q)
    c_min, c_mean = metrics.clearance_stats_m(world, coarse, fine)
    assert np.ptp(brute) > 0.05  # a varied profile, so the bound prunes samples
    assert brute.min() <= c_min <= brute.min() + metrics.CLEARANCE_TOLERANCE_M
    assert c_min <= world.clearances(coarse.q).min()
    # The mean by arc length: the trapezoid rule on the fine samples agrees with it.
    assert c_mean == pytest.approx(fine.mean(brute), abs=2e-3)


#: Metrics undefined for these paths: no reference length, no held upright can.
UNDEFINED_HERE = {"length_ratio", "ee_length_ratio", "can_tilt_max_deg"}


def test_score_returns_every_metric_of_the_registry_as_a_float(scene):
    world = CollisionWorld(scene)
    rng = np.random.default_rng(5)
    via = Q_READY + rng.uniform(-0.5, 0.5, size=(4, 7))
    path = CubicSpline(np.linspace(0, 1, 4), via)(np.linspace(0, 1, 30))
    X_goal = ROBOT.gripper_pose(path[-1])
    m = metrics.score(path=path, world=world, X_WG_goal=X_goal)
    assert set(m) == {d.name for d in METRICS} - NOT_FROM_PATH
    assert all(type(v) is float for v in m.values())
    assert all(math.isfinite(v) for k, v in m.items() if k not in UNDEFINED_HERE)
    assert all(math.isnan(m[k]) for k in UNDEFINED_HERE)
    assert m["goal_error_m"] == pytest.approx(0.0, abs=1e-12)
    assert m["duration_s"] == pytest.approx(time_parameterize(path).duration_s, rel=1e-12)
    assert m["path_length_rad"] == pytest.approx(polyline.path_length_rad(path))
    assert m["length_over_straight"] == pytest.approx(m["path_length_rad"] / np.linalg.norm(path[-1] - path[0]))
    assert m["clearance_min_m"] <= m["clearance_mean_m"]
    m2 = metrics.score(path=path, world=world, X_WG_goal=X_goal, reference_length_rad=0.5 * m["path_length_rad"],
                       reference_ee_length_m=0.25 * m["ee_path_length_m"])
    assert m2["length_ratio"] == pytest.approx(2.0) and m2["ee_length_ratio"] == pytest.approx(4.0)


def test_score_of_a_path_that_does_not_move(scene):
    world = CollisionWorld(scene)
    m = metrics.score(path=np.tile(Q_READY, (3, 1)), world=world, X_WG_goal=ROBOT.gripper_pose(Q_READY))
    assert m["duration_s"] == 0.0 and m["path_length_rad"] == 0.0 and m["smoothness"] == 0.0
    assert m["ee_path_length_m"] == 0.0 and m["ee_rotation_deg"] == 0.0 and m["jerk_max"] == 0.0
    assert m["turning_angle_rad"] == 0.0 and m["sparc"] == 0.0
    assert math.isnan(m["length_over_straight"]) and math.isnan(m["ee_length_over_straight"])
    assert m["posture_distance_mean_rad"] == pytest.approx(0.0, abs=1e-12)
    assert m["clearance_min_m"] == pytest.approx(world.clearance(Q_READY))


def test_record_metrics_stores_nan_as_null():
    assert metrics.record_metrics({"a_m": 1, "b": math.nan, "flag": True, "name": "x"}) == {"a_m": 1.0, "b": None}
