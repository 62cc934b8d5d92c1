"""The robot model: forward kinematics against the published chain and Drake, limits against the facts sheet."""

from __future__ import annotations

import numpy as np
import pytest

from scenes.robot_model import load_robot

# /work/shared/reference/robot-and-scene-facts.md
FACTS_POSITION_LIMIT_RAD = [2.96706, 2.09440, 2.96706, 2.09440, 2.96706, 2.09440, 3.05433]
FACTS_VELOCITY_LIMIT_RAD_S = [1.48353, 1.48353, 1.74533, 1.30900, 2.26893, 2.35619, 2.35619]
FACTS_ACCELERATION_LIMIT_RAD_S2 = [8.57, 8.57, 8.74, 11.36, 12.23, 15.72, 15.72]


@pytest.fixture(scope="module")
def robot():
    return load_robot()


def test_flange_at_zero_is_1306_mm_above_the_base(robot):
    X_WF = robot.flange_pose(np.zeros(7))
    # 0.36 shoulder + 0.42 upper arm + 0.40 forearm + 0.126 wrist to flange, straight up.
    np.testing.assert_allclose(X_WF[:3, 3], [0.0, 0.0, 1.306], atol=1e-9)
    np.testing.assert_allclose(X_WF[:3, 2], [0.0, 0.0, 1.0], atol=1e-9)


def test_limits_equal_the_facts_sheet(robot):
    np.testing.assert_allclose(robot.upper_rad, FACTS_POSITION_LIMIT_RAD, atol=1e-5)
    np.testing.assert_allclose(robot.lower_rad, -np.array(FACTS_POSITION_LIMIT_RAD), atol=1e-5)
    np.testing.assert_allclose(robot.velocity_limits_rad_s, FACTS_VELOCITY_LIMIT_RAD_S, atol=1e-5)
    np.testing.assert_allclose(robot.acceleration_limits_rad_s2, FACTS_ACCELERATION_LIMIT_RAD_S2, atol=1e-9)


def test_link_poses_match_drake(robot, open_scene):
    from scenes.drake_scene import build_drake_scene

    ds = build_drake_scene(open_scene, mode="plan", cameras=False)
    plant = ds.plant
    assert plant.num_positions() == 7
    context = plant.CreateDefaultContext()
    bodies = [plant.GetBodyByName(f"iiwa_link_{i}", ds.iiwa) for i in range(8)]
    bodies.append(plant.GetBodyByName("body", ds.wsg))
    Q = robot.random_configurations(np.random.default_rng(11), 50)
    X_batch = robot.link_poses(Q)
    for q, X_WB in zip(Q, X_batch):
        plant.SetPositions(context, q)
        X_drake = np.array([plant.EvalBodyPoseInWorld(context, b).GetAsMatrix4() for b in bodies])
        np.testing.assert_allclose(robot.link_poses(q), X_drake, rtol=0, atol=1e-9)
        np.testing.assert_allclose(X_WB, X_drake, rtol=0, atol=1e-9)


def test_batched_link_poses_equal_single(robot):
    Q = robot.random_configurations(np.random.default_rng(12), 20)
    X = robot.link_poses(Q)
    assert X.shape == (20, 9, 4, 4)
    for q, X_m in zip(Q, X):
        np.testing.assert_array_equal(robot.link_poses(q), X_m)
    np.testing.assert_array_equal(robot.gripper_pose(Q), X[:, 8])
