"""TOPP-RA timing: limits, degenerate paths, failure as a status, staying on the validated path,
and the duration against Drake's own TOPP-RA."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from scenes.ik import Q_READY
from scenes.robot_model import load_robot
from suite.scoring.timing import TIMING_FAILED, TimingOptions, time_parameterize

ROBOT = load_robot()
V_LIM = ROBOT.velocity_limits_rad_s
A_LIM = ROBOT.acceleration_limits_rad_s2


def sparse_path(seed: int, n: int = 3) -> np.ndarray:
    """A few far-apart waypoints around the ready configuration, like an RRT result."""
    rng = np.random.default_rng(seed)
    return Q_READY + rng.uniform(-0.9, 0.9, size=(n, 7))


def smooth_path(seed: int, n: int = 50) -> np.ndarray:
    """Many waypoints on a smooth curve, like a trajectory optimizer's result."""
    rng = np.random.default_rng(seed)
    via = Q_READY + rng.uniform(-0.8, 0.8, size=(4, 7))
    return CubicSpline(np.linspace(0, 1, 4), via)(np.linspace(0, 1, n))


def distance_to_polyline(Q: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Exact L2 distance of each row of Q to the polyline P (brute force over all segments)."""
    A, D = P[:-1], np.diff(P, axis=0)
    w = np.clip(np.einsum("mij,ij->mi", Q[:, None, :] - A[None], D) / np.einsum("ij,ij->i", D, D), 0, 1)
    return np.min(np.linalg.norm(Q[:, None, :] - A[None] - w[..., None] * D[None], axis=2), axis=1)


@pytest.mark.parametrize("path", [sparse_path(0), sparse_path(1, n=5), smooth_path(2)], ids=["rrt3", "rrt5", "smooth50"])
def test_limits_hold_on_a_fine_independent_resampling(path):
    tr = time_parameterize(path)
    assert tr.ok, tr.reason
    assert tr.velocity_ratio <= 1.01 and tr.acceleration_ratio <= 1.01
    # Independent of the dense check inside: sample at 0.5 ms and differentiate positions numerically.
    t = np.arange(0.0, tr.duration_s, 5e-4)
    q, qd, qdd = tr.sample(t)
    qd_fd = np.gradient(q, t, axis=0)
    assert np.max(np.abs(qd_fd[1:-1]) / V_LIM) <= 1.01
    assert np.max(np.abs(qd) / V_LIM) <= 1.01 and np.max(np.abs(qdd) / A_LIM) <= 1.01
    assert np.max(np.abs(qd_fd[2:-2] - qd[2:-2])) < 0.01  # sampled qd is q's derivative
    # Time-optimal: some joint runs at a limit somewhere.
    assert max(tr.velocity_ratio, tr.acceleration_ratio) > 0.99
    # Rest to rest, from the first waypoint to the last.
    np.testing.assert_allclose(tr.q[0], path[0], atol=1e-12)
    np.testing.assert_allclose(tr.q[-1], path[-1], atol=1e-9)
    np.testing.assert_allclose(tr.qd[[0, -1]], 0.0, atol=1e-9)
    # The fixed-dt arrays.
    assert np.allclose(np.diff(tr.t_s)[:-1], tr.dt_s) and tr.t_s[-1] == pytest.approx(tr.duration_s)


def test_sparse_path_stays_near_the_validated_segments():
    path = sparse_path(3)
    step = TimingOptions().densify_step_rad
    tr = time_parameterize(path)
    t = np.linspace(0, tr.duration_s, 4000)
    dev = distance_to_polyline(tr.sample(t)[0], path).max()
    # The reported figure (measured at the dense check points) matches a brute-force measurement.
    assert dev == pytest.approx(tr.path_deviation_rad, rel=0.01)
    assert tr.path_deviation_rad < 0.15 * step
    # Why densify: a spline through the three waypoints alone leaves the segments by far more.
    s = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
    raw = CubicSpline(s, path)(np.linspace(0, s[-1], 4000))
    assert distance_to_polyline(raw, path).max() > 10 * tr.path_deviation_rad


def test_duplicate_waypoints_are_dropped():
    path = sparse_path(4)
    dup = np.vstack([path[:1], path[:1], path[1:2], path[1:2] + 1e-12, path[1:]])
    a, b = time_parameterize(path), time_parameterize(dup)
    assert a.ok and b.ok
    assert b.duration_s == pytest.approx(a.duration_s, rel=1e-9)


@pytest.mark.parametrize("n", [1, 4])
def test_a_path_that_does_not_move_takes_no_time(n):
    tr = time_parameterize(np.tile(Q_READY, (n, 1)))
    assert tr.ok and tr.duration_s == 0.0
    q, qd, qdd = tr.sample(0.7)
    np.testing.assert_array_equal(q, Q_READY)
    assert not qd.any() and not qdd.any()


def test_toppra_failure_is_a_status():
    frail = dataclasses.replace(
        ROBOT, joints=tuple(dataclasses.replace(j, acceleration_rad_s2=1e-12) for j in ROBOT.joints)
    )
    tr = time_parameterize(sparse_path(5), robot=frail)
    assert tr.status == TIMING_FAILED and "TOPP-RA" in tr.reason
    assert np.isnan(tr.duration_s)
    with pytest.raises(ValueError):
        tr.sample(0.0)


def test_malformed_path_is_rejected():
    with pytest.raises(ValueError, match="shape"):
        time_parameterize(np.zeros((3, 6)))


def drake_toppra_duration(tr, *, plant) -> float:
    """Drake's TOPP-RA on the same spline (as a cubic Hermite with the same knots, values and
    slopes, hence the same cubics), the same gridpoints and the same limits."""
    from pydrake.multibody.optimization import Toppra, ToppraDiscretization
    from pydrake.trajectories import PiecewisePolynomial

    spline = tr.spline
    s = spline.x
    path = PiecewisePolynomial.CubicHermite(s, spline(s).T, spline(s, 1).T)
    toppra = Toppra(path, plant, tr.s_grid)
    toppra.AddJointVelocityLimit(-V_LIM, V_LIM)
    toppra.AddJointAccelerationLimit(-A_LIM, A_LIM, ToppraDiscretization.kInterpolation)
    s_of_t = toppra.SolvePathParameterization()
    assert s_of_t is not None
    return s_of_t.end_time()


@pytest.fixture(scope="module")
def plan_plant():
    from scenes.drake_scene import build_drake_scene
    from scenes.generate import generate_scene
    from scenes.spec import load_spec

    scene = generate_scene(load_spec(), seed=1, check_reachable=False)
    ds = build_drake_scene(scene, mode="plan", cameras=False)
    assert ds.plant.num_positions() == 7
    np.testing.assert_allclose(ds.plant.GetVelocityUpperLimits(), V_LIM)  # one source: the URDF
    return ds.plant


@pytest.mark.parametrize("path", [sparse_path(6), sparse_path(7, n=6), smooth_path(8)], ids=["rrt3", "rrt6", "smooth50"])
def test_duration_matches_drake_toppra(path, plan_plant):
    tr = time_parameterize(path)
    assert tr.ok, tr.reason
    drake_s = drake_toppra_duration(tr, plant=plan_plant)
    assert tr.duration_s == pytest.approx(drake_s, rel=0.02)


@pytest.mark.parametrize("distance_rad", [1e-6, 1e-3, 0.04, 0.2, 1.5])
def test_single_joint_move_takes_the_closed_form_time(distance_rad):
    """Rest to rest along one joint: a triangle (acceleration-limited) or trapezoid profile."""
    j = 3
    v, a = V_LIM[j], A_LIM[j]
    expected = 2 * math.sqrt(distance_rad / a) if distance_rad <= v * v / a else distance_rad / v + v / a
    tr = time_parameterize(np.array([Q_READY, Q_READY + distance_rad * np.eye(7)[j]]))
    assert tr.ok, tr.reason
    assert tr.duration_s == pytest.approx(expected, rel=0.01)
