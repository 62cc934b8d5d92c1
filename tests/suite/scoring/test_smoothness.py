"""Smoothness on hand-made paths with known answers: the total turning angle (straight, corner,
zigzag, reversal, densified), SPARC on speed profiles of known shape, and SPARC's stability where
jerk is not (TOPP-RA's grid)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scenes.ik import Q_READY
from suite.scoring import smoothness
from suite.scoring.polyline import simplify
from suite.scoring.timing import TimingOptions, time_parameterize

E = np.eye(7)


def plane_path(points_2d, *, scale: float = 0.3) -> np.ndarray:
    """Waypoints around the ready pose moving joints 1 and 2 through the given (x, y) points."""
    p = np.asarray(points_2d, float) * scale
    return Q_READY + p[:, :1] * E[0] + p[:, 1:] * E[1]


def with_midpoints(path: np.ndarray) -> np.ndarray:
    """The same polyline with a midpoint inserted in every segment."""
    mids = 0.5 * (path[:-1] + path[1:])
    out = np.empty((2 * len(path) - 1, path.shape[1]))
    out[0::2], out[1::2] = path, mids
    return out


def test_straight_segment_turns_zero_however_many_waypoints():
    line = np.linspace(Q_READY, Q_READY + 0.8, 17)
    assert smoothness.turning_angle_rad(line[[0, -1]]) == 0.0
    assert smoothness.turning_angle_rad(line) == 0.0
    assert len(simplify(line)) == 2


def test_right_angle_corner_turns_half_pi():
    corner = plane_path([(0, 0), (1, 0), (1, 1)])
    assert smoothness.turning_angle_rad(corner) == pytest.approx(math.pi / 2, rel=1e-12)
    assert smoothness.turning_angle_rad(with_midpoints(with_midpoints(corner))) == pytest.approx(math.pi / 2, rel=1e-12)


def test_zigzag_turns_twice_its_slope_at_every_corner():
    # Slope 30 degrees up and down: the direction turns by 60 degrees at each of the 4 corners.
    h = math.tan(math.radians(30))
    zigzag = plane_path([(0, 0), (1, h), (2, 0), (3, h), (4, 0), (5, h)])
    assert smoothness.turning_angle_rad(zigzag) == pytest.approx(4 * math.pi / 3, rel=1e-12)
    # The straight segment between the same ends turns 0: the zigzag is worse.
    assert smoothness.turning_angle_rad(zigzag[[0, -1]]) == 0.0


def test_reversal_turns_pi_and_duplicates_are_ignored():
    out_and_back = plane_path([(0, 0), (1, 0), (1, 0), (0.5, 0)])
    assert smoothness.turning_angle_rad(out_and_back) == pytest.approx(math.pi, rel=1e-12)


def test_turning_angle_of_a_finely_sampled_arc_is_nearly_its_angle():
    # A quarter circle as a polyline of 200 chords: the chords' directions run from 1/2 to 199/2
    # steps of pi/400, so the direction turns by 199 steps (the arc's pi/2, less one step).
    t = np.linspace(0.0, math.pi / 2, 201)
    arc = plane_path(np.column_stack([np.sin(t), 1 - np.cos(t)]))
    assert smoothness.turning_angle_rad(arc) == pytest.approx(199 * math.pi / 400, rel=1e-9)


def min_jerk_speed(n: int) -> np.ndarray:
    s = np.linspace(0.0, 1.0, n)
    return 30 * s**2 * (1 - s) ** 2


@pytest.mark.parametrize("duration_s,peak", [(0.5, 1.0), (2.0, 1.0), (2.0, 7.0)])
def test_sparc_of_a_minimum_jerk_profile_is_known_and_scale_free(duration_s, peak):
    # The minimum-jerk (bell-shaped) speed profile, at any duration and amplitude.
    v = peak * min_jerk_speed(round(duration_s * 100) + 1)
    assert smoothness.sparc(v, sample_hz=100.0) == pytest.approx(-1.4058, abs=1e-3)


def test_sparc_is_lower_for_a_profile_that_stops_midway():
    t = np.linspace(0.0, 1.0, 201)
    one = np.sin(math.pi * t) ** 2
    two = np.sin(2 * math.pi * t) ** 2  # speeds up and slows down twice
    assert smoothness.sparc(two, sample_hz=200.0) < smoothness.sparc(one, sample_hz=200.0) - 0.5
    assert smoothness.sparc(np.zeros(50), sample_hz=100.0) == 0.0


def test_sparc_barely_moves_with_the_toppra_grid_where_jerk_does():
    # A 12-waypoint polyline along an arc (like an IK planner's path): TOPP-RA's gridpoints are
    # multiplied by ~3.5, which moves jerk_max by ~25% and SPARC by ~0.2% (the measurement behind
    # choosing SPARC as the timed smoothness).
    t = np.linspace(0.0, 1.5, 12)
    path = np.tile(Q_READY, (12, 1))
    path[:, 0] += 0.6 * np.sin(t)
    path[:, 1] += 0.6 * (1 - np.cos(t))
    path[:, 3] += 0.3 * t
    runs = [time_parameterize(path, options=TimingOptions(grid_curvature_gain=g)) for g in (1.0, 32.0)]
    assert all(r.ok for r in runs)
    assert runs[1].n_gridpoints > 3 * runs[0].n_gridpoints
    jerk = [smoothness.jerk_max(r) for r in runs]
    sparc = [smoothness.joint_speed_sparc(r) for r in runs]
    assert abs(jerk[1] - jerk[0]) / jerk[0] > 0.15
    assert abs(sparc[1] - sparc[0]) / abs(sparc[0]) < 0.01


def test_joint_speed_sparc_of_degenerate_trajectories():
    still = time_parameterize(np.tile(Q_READY, (2, 1)))
    assert smoothness.joint_speed_sparc(still) == 0.0
    moving = time_parameterize(np.array([Q_READY, Q_READY + 0.5]))
    assert -3.0 < smoothness.joint_speed_sparc(moving) < -1.0
