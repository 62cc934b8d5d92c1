"""The person beside the moving bin: the robot's distance to them, the swept check of a timed plan,
and speed and separation monitoring's arithmetic."""

import re

import numpy as np
import pytest

from scenes.generate import generate_scene
from scenes.ik import Q_READY
from scenes.moving_bin import make_scenario
from scenes.robot_model import load_robot
from scenes.scene import HeldCan
from scenes.spec import load_spec
from suite.execution.person import (
    SsmSettings,
    gripper_speed,
    protective_distance,
    robot_person_distance,
    ssm_verdict,
    stopping_motion,
    swept_person_check,
)
from suite.scoring.timing import time_parameterize

SPEC = load_spec(variant="open")
SCENARIO = make_scenario()
ROBOT = load_robot(SPEC.robot)
OPEN = SPEC.grasp.open_width_m
R = SCENARIO.person_radius_m


def distance(q, xy, **kw):
    return robot_person_distance(SPEC.robot, np.atleast_2d(q), np.atleast_2d(xy), SCENARIO, SPEC, opening_m=OPEN, **kw)


def gripper_xy(q):
    return ROBOT.gripper_pose(q)[:2, 3]


# --- the robot's distance to the person -------------------------------------------------------------


def test_far_person_is_far_and_a_person_on_the_gripper_overlaps_it():
    (far,) = distance(Q_READY, (3.0, 0.0))
    assert far == pytest.approx(3.0 - R - 0.14, abs=1e-6)  # the base's cylinder (radius 0.14) is nearest
    (on,) = distance(Q_READY, gripper_xy(Q_READY))
    assert on <= 0.0


def test_straight_up_arm_is_its_base_cylinder_away():
    # every part of the upright arm lies within the base's radius 0.14 of the z axis
    d = distance(np.zeros((3, 7)), [(0.6, 0.0), (0.0, -0.7), (-0.5, 0.5)])
    expected = [0.6 - R - 0.14, 0.7 - R - 0.14, np.hypot(0.5, 0.5) - R - 0.14]
    assert d == pytest.approx(expected, abs=1e-5)  # FCL's GJK between two cylinders: a few micrometres


def test_person_beyond_the_gripper_is_measured_from_the_gripper():
    # the person's axis outward from the base, beyond the gripper: the gripper is the nearest part
    g = gripper_xy(Q_READY)
    u = g / np.linalg.norm(g)
    gap = 0.3
    (d,) = distance(Q_READY, g + (R + gap) * u)
    gripper_size = 0.12  # the gripper body's half diagonal and the fingers' reach from its origin
    assert gap - gripper_size <= d <= gap + 1e-9


def test_a_short_person_under_the_gripper_is_its_height_below_it():
    # a person (a child, say) of 0.5 m standing under the gripper, slim enough to keep off the base
    short = make_scenario({"person_height_m": 0.5, "person_radius_m": 0.1})
    g = ROBOT.gripper_pose(Q_READY)[:3, 3]
    (d,) = robot_person_distance(SPEC.robot, Q_READY[None], g[None, :2], short, SPEC, opening_m=OPEN)
    gap = g[2] - 0.5
    assert gap - 0.12 <= d <= gap  # the finger tips hang up to 0.07 m below the gripper's origin


def test_a_held_can_counts():
    can = generate_scene(SPEC, seed=1).cans[0]
    X_GC = np.eye(4)
    X_GC[:3, :3] = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]  # the can's axis along the fingers
    X_GC[1, 3] = 0.3  # well below the finger tips: nothing else there
    held = HeldCan(can, X_GC)
    c = (ROBOT.gripper_pose(Q_READY) @ X_GC)[:2, 3]
    xy = c + np.array([0.0, -(R + 0.15)])  # beside the can, away from the base
    (with_can,) = distance(Q_READY, xy, held_can=held)
    (without,) = distance(Q_READY, xy)
    r_can = SPEC.can.radius_m + SPEC.grasp.held_margin_m
    assert with_can < without - 0.03
    assert with_can == pytest.approx(0.15 - r_can, abs=0.03)  # the can leans 14 degrees


# --- the swept check ------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def swing():
    """The arm swinging 1 rad about joint 1 from the ready posture, timed from rest."""
    q1 = Q_READY.copy()
    q1[0] += 1.0
    traj = time_parameterize(np.stack([Q_READY, q1]), robot=ROBOT)
    assert traj.ok
    return traj


def test_swept_check_finds_the_person_walking_through_mid_plan(swing):
    t0, T = 10.0, swing.duration_s
    q_mid = swing.sample(T / 2)[0]
    g = gripper_xy(q_mid)
    u = g / np.linalg.norm(g)

    def person_xy_at(t):  # walks past at 2 m over the plan, its side over the gripper at mid-plan
        w = np.array([-u[1], u[0]])
        return g + 0.5 * R * u + w * 2.0 * (t - t0 - T / 2) / T

    ends = distance(np.stack([swing.sample(0.0)[0], swing.sample(T)[0]]), [person_xy_at(t0), person_xy_at(t0 + T)])
    assert np.all(ends > 0.1)  # both ends clear: only the sweep finds it
    reason, d = swept_person_check(SPEC.robot, swing, t0, person_xy_at, SCENARIO, SPEC, opening_m=OPEN,
                                   margin_m=0.05)
    assert reason is not None and d < 0
    assert "margin 0.05 m" in reason
    t_hit = float(re.search(r"t\+([0-9.]+) s", reason).group(1))
    assert abs(t_hit - T / 2) < 0.1
    # the person's path is read on the absolute clock: the same walk ten seconds off misses the plan
    assert swept_person_check(SPEC.robot, swing, 0.0, person_xy_at, SCENARIO, SPEC, opening_m=OPEN,
                              margin_m=0.05)[0] is None


def test_swept_check_samples_the_plans_end(swing):
    # the person just past where the gripper comes to rest: only the last instants reach them
    T = swing.duration_s
    g_end, g_before = gripper_xy(swing.sample(T)[0]), gripper_xy(swing.sample(T - 0.05)[0])
    ahead = (g_end - g_before) / np.linalg.norm(g_end - g_before)
    xy = g_end + (R + 0.03) * ahead
    reason, d = swept_person_check(SPEC.robot, swing, 0.0, lambda t: xy, SCENARIO, SPEC, opening_m=OPEN,
                                   margin_m=0.0, dt_s=0.3)  # samples at 0, 0.3, 0.6 s and the end
    assert reason is not None and f"t+{T:.2f} s" in reason
    assert d == pytest.approx(distance(swing.sample(T)[0], xy)[0])


def test_swept_check_passes_a_far_person(swing):
    reason, d = swept_person_check(SPEC.robot, swing, 0.0, lambda t: np.array([3.0, 0.0]), SCENARIO, SPEC,
                                   opening_m=OPEN, margin_m=0.05)
    assert reason is None and d > 2.0


# --- speed and separation monitoring ----------------------------------------------------------------


def test_protective_distance_adds_its_terms():
    s_p = protective_distance(human_speed_m_s=1.6, reaction_s=0.2, stop_time_s=0.3, robot_speed_m_s=0.5,
                              stop_distance_m=0.1, intrusion_m=0.05, uncertainty_m=0.01)
    assert s_p == pytest.approx(1.6 * 0.5 + 0.5 * 0.2 + 0.1 + 0.05 + 0.01)


def test_ssm_verdict_holds_inside_the_protective_distance():
    kw = dict(human_speed_m_s=0.5, robot_speed_m_s=1.0, stop_time_s=0.3, stop_distance_m=0.15)
    s = SsmSettings()
    expected = 0.5 * (0.2 + 0.3) + 1.0 * 0.2 + 0.15 + 0.0 + 0.01
    assert ssm_verdict(s, separation_m=expected - 0.01, **kw) == ("hold", pytest.approx(expected))
    assert ssm_verdict(s, separation_m=expected + 0.01, **kw)[0] == "go"
    assert ssm_verdict(s, separation_m=expected + 0.01, holding=True, **kw)[0] == "hold"  # hysteresis
    assert ssm_verdict(s, separation_m=expected + 0.06, holding=True, **kw)[0] == "go"
    fixed = SsmSettings(human_speed_m_s=1.6)  # the settings' speed overrides the estimate
    assert ssm_verdict(fixed, separation_m=1.0, **kw)[1] == pytest.approx(expected + 1.1 * 0.5)
    assert ssm_verdict(s, separation_m=5.0, **{**kw, "stop_time_s": np.inf})[0] == "hold"


def test_stopping_motion_at_rest_is_nothing():
    assert stopping_motion(SPEC.robot, Q_READY, np.zeros(7), np.zeros(7)) == (0.0, 0.0)


def test_stopping_motion_grows_with_speed():
    out = []
    for share in (0.05, 0.2, 0.5):
        v = share * ROBOT.velocity_limits_rad_s
        T, S = stopping_motion(SPEC.robot, Q_READY, v, np.zeros(7))
        # the blend's speed profile v0 (1 - 3u^2 + 2u^3) covers v0 T / 2; the gripper origin is one
        # of the points tracked, the elbow and finger tips may travel further
        assert S >= 0.9 * gripper_speed(SPEC.robot, Q_READY, v) * T / 2
        out.append((T, S))
    assert 0 < out[0][0] < out[1][0] < out[2][0]
    assert 0 < out[0][1] < out[1][1] < out[2][1]


def test_robot_speed_is_the_fastest_point_of_the_arm():
    from suite.execution.person import robot_speed

    rng = np.random.default_rng(3)
    for _ in range(5):
        v = rng.uniform(-1.0, 1.0, 7)
        assert robot_speed(SPEC.robot, Q_READY, v) >= gripper_speed(SPEC.robot, Q_READY, v) - 1e-9
    v = np.zeros(7)
    v[3] = 1.0  # the elbow turns: the gripper moves, the base does not
    assert robot_speed(SPEC.robot, Q_READY, v) > 0.1


def test_gripper_speed_about_the_base_axis():
    v = np.zeros(7)
    v[0] = 0.5  # joint 1 spins the whole arm about the vertical axis
    assert gripper_speed(SPEC.robot, Q_READY, v) == pytest.approx(0.5 * np.linalg.norm(gripper_xy(Q_READY)), rel=1e-3)
    assert gripper_speed(SPEC.robot, Q_READY, np.zeros(7)) == 0.0
