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


def test_the_gcs_papers_robot_has_our_chain_its_mount_and_its_spheres(robot):
    """`iiwa14-spheres` (docs/gcs-paper-sources.md): the same iiwa 14 kinematics, the WSG body at
    [0, 0, 0.114] with roll 90 deg on link 7, a cylinder and 12 spheres on the arm, the fingers
    welded whatever the opening, and links 5 and 7 filtered as Drake's `wrist` group."""
    paper = load_robot("iiwa14-spheres")
    q = robot.random_configurations(np.random.default_rng(13), 5)
    np.testing.assert_array_equal(paper.link_poses(q)[:, :8], robot.link_poses(q)[:, :8])
    X_7G = np.array([[1, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0.114], [0, 0, 0, 1.0]])
    np.testing.assert_allclose(paper.X_7G, X_7G, atol=1e-12)
    arm = [s for s in paper.shapes if s.body.startswith("iiwa_")]
    assert [s.kind for s in arm].count("sphere") == 12 and [s.kind for s in arm].count("cylinder") == 1
    assert {name for name, _ in paper.welded_fingers} == {"left_finger", "right_finger"}
    a, b = paper.finger_offsets(0.0), paper.finger_offsets(0.1)
    for name in a:
        np.testing.assert_array_equal(a[name], b[name])
    np.testing.assert_allclose(a["right_finger"][:3, 3], [0.06, 0.077133, 0.0])
    assert frozenset(("iiwa_link_5", "iiwa_link_7")) in paper.filtered_pairs
    assert frozenset(("iiwa_link_5", "iiwa_link_7")) not in robot.filtered_pairs
    with pytest.raises(ValueError, match="'nope' is not a robot variant; allowed: iiwa14-wsg, iiwa14-spheres"):
        load_robot("nope")


def test_the_gcs_papers_robot_matches_drake():
    from scenes.drake_scene import build_drake_scene
    from scenes.generate import generate_scene
    from scenes.spec import load_spec

    scene = generate_scene(load_spec(variant="gcs-arm"), seed=0)
    paper = load_robot("iiwa14-spheres")
    ds = build_drake_scene(scene, mode="plan", cameras=False)
    plant = ds.plant
    assert plant.num_positions() == 7
    context = plant.CreateDefaultContext()
    names = [("body", ds.wsg), ("left_finger", ds.wsg), ("right_finger", ds.wsg)]
    for q in paper.random_configurations(np.random.default_rng(14), 10):
        plant.SetPositions(context, q)
        X_WG = paper.gripper_pose(q)
        for name, instance in names:
            X = plant.EvalBodyPoseInWorld(context, plant.GetBodyByName(name, instance)).GetAsMatrix4()
            X_GF = np.eye(4) if name == "body" else paper.finger_offsets(0.0)[name]
            np.testing.assert_allclose(X, X_WG @ X_GF, rtol=0, atol=1e-6)
