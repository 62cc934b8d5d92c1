"""Every metric is invariant to waypoint density: a path and the same polyline with more waypoints
(a midpoint in every segment, or collinear points anywhere) score the same, within 1%."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from scenes.collision.world import CollisionWorld
from scenes.generate import generate_scene
from scenes.ik import Q_READY
from scenes.robot_model import load_robot
from scenes.scene import CanPose, HeldCan
from scenes.spec import load_spec
from suite.scoring import metrics, polyline

ROBOT = load_robot()
#: Not a property of the path: the wall time of the timing computation.
NOT_OF_THE_PATH = {"timing_time_s"}


def with_midpoints(path: np.ndarray) -> np.ndarray:
    mids = 0.5 * (path[:-1] + path[1:])
    out = np.empty((2 * len(path) - 1, 7))
    out[0::2], out[1::2] = path, mids
    return out


def with_random_collinear_points(path: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Between 0 and 4 points at random places on every segment, and a repeated waypoint."""
    pieces = []
    for a, b in itertools.pairwise(path):
        f = np.sort(rng.uniform(0.0, 1.0, rng.integers(0, 5)))
        pieces += [a[None], a + f[:, None] * (b - a)]
    pieces += [path[-1:], path[-1:]]
    return np.vstack(pieces)


def corner_path() -> np.ndarray:
    return Q_READY + np.array([[0, 0, 0, 0, 0, 0, 0], [0.5, 0.2, 0, 0.1, 0, 0, 0], [0.6, -0.2, 0.3, 0, 0.2, 0, 0.4],
                               [1.1, 0.0, 0.3, 0.3, 0.2, -0.3, 0.4]])


def smooth_path() -> np.ndarray:
    via = Q_READY + np.random.default_rng(4).uniform(-0.5, 0.5, size=(4, 7))
    return CubicSpline(np.linspace(0, 1, 4), via)(np.linspace(0, 1, 30))


def zigzag_path() -> np.ndarray:
    k = np.arange(7)
    return Q_READY + np.outer(k, [0.15, 0, 0, 0.05, 0, 0, 0]) + np.outer(k % 2, [0, 0.12, 0, 0, 0, 0.1, 0])


@pytest.fixture(scope="module")
def holding_world():
    """An open scene whose gripper carries an upright can (so every metric is defined)."""
    scene = generate_scene(load_spec(variant="open"), seed=1, check_reachable=False)
    X_WG0 = ROBOT.gripper_pose(Q_READY)
    can = CanPose(0, tuple(X_WG0[:3, 3] + [0.0, 0.0, -0.1]), False, 0.0)
    return CollisionWorld(scene, held=HeldCan(can, np.linalg.solve(X_WG0, can.X_WC())), gripper_opening_m=0.066)


@pytest.mark.parametrize("make_path", [corner_path, smooth_path, zigzag_path], ids=["corner", "smooth", "zigzag"])
def test_every_metric_is_invariant_to_waypoint_density(make_path, holding_world):
    path = make_path()
    X_goal = ROBOT.gripper_pose(path[-1])
    kw = {"world": holding_world, "X_WG_goal": X_goal, "reference_length_rad": 1.0, "reference_ee_length_m": 0.3}
    base = metrics.score(path=path, **kw)
    assert all(math.isfinite(v) for v in base.values())  # every metric defined here
    rng = np.random.default_rng(0)
    for dense in (with_midpoints(path), with_midpoints(with_midpoints(path)), with_random_collinear_points(path, rng)):
        assert len(dense) > len(path)
        m = metrics.score(path=dense, **kw)
        for name, value in base.items():
            if name not in NOT_OF_THE_PATH:
                assert m[name] == pytest.approx(value, rel=0.01, abs=1e-9), name


def test_simplify_recovers_the_corners():
    path = corner_path()
    dense = with_random_collinear_points(with_midpoints(path), np.random.default_rng(1))
    np.testing.assert_allclose(polyline.simplify(dense), path, atol=1e-12)
    # The samples along the path are the same points too.
    a, b = polyline.arc_samples(path, 0.01), polyline.arc_samples(dense, 0.01)
    np.testing.assert_allclose(b.q, a.q, atol=1e-12)
    np.testing.assert_allclose(b.weights, a.weights, atol=1e-12)


def test_arc_samples_spacing_corners_and_weights():
    path = corner_path()
    s = polyline.arc_samples(path, 0.01)
    assert np.max(np.diff(s.s_rad)) <= 0.01 + 1e-12
    assert s.s_rad[-1] == pytest.approx(polyline.path_length_rad(path), rel=1e-12)
    for corner in path:  # every waypoint of a path without collinear points is a sample
        assert np.min(np.linalg.norm(s.q - corner, axis=1)) < 1e-12
    assert s.weights.sum() == pytest.approx(1.0, rel=1e-12)
    # The mean of a linear function of arc length is its value at the middle.
    assert s.mean(s.s_rad) == pytest.approx(s.s_rad[-1] / 2, rel=1e-12)
    # per_step subdivides: five times the samples, coarse ones among them.
    fine = polyline.arc_samples(path, 0.05, per_step=5)
    coarse = polyline.arc_samples(path, 0.05)
    assert np.all(np.min(np.abs(fine.s_rad[None, :] - coarse.s_rad[:, None]), axis=1) < 1e-12)


def test_timing_ignores_collinear_waypoints():
    from suite.scoring.timing import time_parameterize

    path = corner_path()
    a = time_parameterize(path)
    b = time_parameterize(with_random_collinear_points(path, np.random.default_rng(2)))
    assert a.ok and b.ok
    assert b.duration_s == pytest.approx(a.duration_s, rel=1e-12)
    assert b.n_gridpoints == a.n_gridpoints

