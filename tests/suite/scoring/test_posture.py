"""Natural-pose metrics on hand-made paths with known answers: a joint-limit graze, the distance
from the comfortable posture, the Jacobian and manipulability, and a carried can's tilt."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scenes.collision.world import CollisionWorld
from scenes.generate import generate_scene
from scenes.ik import Q_READY
from scenes.robot_model import load_robot
from scenes.scene import CanPose, HeldCan
from scenes.spec import load_spec
from suite.scoring import metrics, posture
from suite.scoring.polyline import arc_samples

ROBOT = load_robot()
E = np.eye(7)


def rx(angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def test_comfortable_posture_is_the_projects_ready_configuration():
    np.testing.assert_array_equal(posture.Q_COMFORT, Q_READY)


def test_joint_limit_graze_gives_a_margin_near_zero():
    hi = ROBOT.upper_rad[1]
    graze = Q_READY.copy()
    graze[1] = hi - 0.002  # joint 2 passes 2 mrad from its upper limit
    path = np.array([Q_READY, graze, Q_READY + 0.1 * E[0]])
    margin = np.min(posture.joint_limit_margins(arc_samples(path, 0.01).q, ROBOT))
    assert margin == pytest.approx(0.002 / (hi - ROBOT.lower_rad[1]), rel=1e-9)
    # At the ready pose the tightest joint is joint 6 at 1.6 of [-2.0944, 2.0944].
    assert posture.joint_limit_margins(Q_READY, ROBOT)[0] == pytest.approx((2.0944 - 1.6) / 4.1888, rel=1e-4)


def test_mean_distance_from_the_comfortable_posture():
    # Straight away from it: the distance grows linearly from 0 to 0.4, its mean is 0.2.
    away = np.array([Q_READY, Q_READY + 0.4 * E[0]])
    s = arc_samples(away, 0.01)
    assert s.mean(posture.posture_distances_rad(s.q)) == pytest.approx(0.2, rel=1e-12)
    # Offset by a = 0.3 on joint 2, moving 0.5 on joint 1: mean of sqrt(a^2 + t^2) over t in [0, 0.5].
    a, b = 0.3, 0.5
    offset = np.array([Q_READY + a * E[1], Q_READY + a * E[1] + b * E[0]])
    s = arc_samples(offset, 0.01)
    exact = 0.5 * (b * math.hypot(a, b) + a * a * math.asinh(b / a)) / b
    assert s.mean(posture.posture_distances_rad(s.q)) == pytest.approx(exact, rel=1e-4)


def numerical_jacobian(q: np.ndarray, h: float = 1e-6) -> np.ndarray:
    J = np.zeros((6, 7))
    for i in range(7):
        Xp, Xm = ROBOT.gripper_pose(q + h * E[i]), ROBOT.gripper_pose(q - h * E[i])
        J[:3, i] = (Xp[:3, 3] - Xm[:3, 3]) / (2 * h)
        W = (Xp[:3, :3] @ Xm[:3, :3].T - Xm[:3, :3] @ Xp[:3, :3].T) / 2  # skew(omega) * 2h
        J[3:, i] = np.array([W[2, 1], W[0, 2], W[1, 0]]) / (2 * h)
    return J


def test_geometric_jacobian_matches_finite_differences():
    qs = ROBOT.random_configurations(np.random.default_rng(0), 5)
    J = posture.gripper_jacobians(qs, ROBOT)
    for q, Jq in zip(qs, J):
        np.testing.assert_allclose(Jq, numerical_jacobian(q), atol=1e-7)


def test_manipulability_vanishes_at_a_singularity():
    straight_up = np.zeros(7)  # joints 1, 3, 5 and 7 share one vertical axis
    assert posture.manipulability(straight_up, ROBOT)[0] < 1e-9
    assert posture.manipulability(Q_READY, ROBOT)[0] > 0.01
    # Along a path through it, the smallest value is that of the singular sample.
    path = np.array([Q_READY, straight_up, Q_READY + 0.2])
    assert np.min(posture.manipulability(arc_samples(path, 0.01).q, ROBOT)) < 1e-9


def test_tilt_of_a_carried_can():
    X_WG0 = ROBOT.gripper_pose(Q_READY)
    upright = np.eye(4)
    upright[:3, 3] = X_WG0[:3, 3]
    X_GC = np.linalg.solve(X_WG0, upright)  # upright at the ready pose
    # Joint 6's axis is horizontal at the ready pose and perpendicular to the can's axis:
    # turning it by 0.3 rad tilts the can by exactly 0.3 rad.
    assert abs(ROBOT.link_poses(Q_READY)[6, 2, 2]) < 1e-9  # z of joint 6's axis
    tip = np.array([Q_READY, Q_READY + 0.3 * E[5], Q_READY - 0.1 * E[5]])
    q = arc_samples(tip, 0.01).q
    assert posture.tilt_max_deg(q, ROBOT, X_GC) == pytest.approx(math.degrees(0.3), rel=1e-6)
    # Turning the whole arm about the vertical joint 1 keeps the tilt: a can held at 20 degrees stays at 20.
    tilted = upright.copy()
    tilted[:3, :3] = rx(math.radians(20))
    X_GC20 = np.linalg.solve(X_WG0, tilted)
    swing = np.array([Q_READY, Q_READY + 1.0 * E[0]])
    tilts = posture.can_tilts_deg(arc_samples(swing, 0.01).q, ROBOT, X_GC20)
    np.testing.assert_allclose(tilts, 20.0, rtol=1e-9)


def test_score_reports_the_tilt_only_for_a_carried_upright_can():
    scene = generate_scene(load_spec(variant="open"), seed=1, check_reachable=False)
    X_WG0 = ROBOT.gripper_pose(Q_READY)
    tip = np.array([Q_READY, Q_READY + 0.3 * E[5]])
    X_goal = ROBOT.gripper_pose(tip[-1])
    for lying, expected in ((False, math.degrees(0.3)), (True, None)):
        can = CanPose(0, tuple(X_WG0[:3, 3]), lying, 0.0)
        held = HeldCan(can, np.linalg.solve(X_WG0, can.X_WC()))
        m = metrics.score(path=tip, world=CollisionWorld(scene, held=held, gripper_opening_m=0.066), X_WG_goal=X_goal)
        if expected is None:
            assert math.isnan(m["can_tilt_max_deg"])
        else:
            assert m["can_tilt_max_deg"] == pytest.approx(expected, rel=1e-6)
    assert math.isnan(metrics.score(path=tip, world=CollisionWorld(scene), X_WG_goal=X_goal)["can_tilt_max_deg"])
