"""The cycle's goal IK: the bin goal warm-started from the previous cycle's, and how a dataset records it."""

from __future__ import annotations

import numpy as np
import pytest

from scenes.grasp_rule import truth_grasp
from suite.problems.cycle import build_problems
from suite.run.build_dataset import BuildSettings, pose_settings


def _bin_goals(scene, *, warm: bool):
    problems = build_problems(scene, [truth_grasp(scene, c) for c in scene.cans[:3]], time_limit_s=1.0, seed=11,
                              bin_warm_start=warm)
    return [p for p in problems if p.kind == "transit"]


@pytest.mark.parametrize("warm", [True, False])
def test_every_bin_goal_reaches_the_bin_pose_collision_free(wall_scene, warm):
    from planners.worlds import collision_world

    transits = _bin_goals(wall_scene, warm=warm)
    assert len(transits) == 3 and all(p.pre_status is None for p in transits)
    for p in transits:
        world = collision_world(p)
        assert world.is_free(p.q_goal)
        X = world.robot.gripper_pose(p.q_goal)
        assert np.linalg.norm(X[:3, 3] - p.X_WG_goal[:3, 3]) < 2e-3  # the IK's 1 mm box


def test_a_warm_started_bin_goal_stays_on_the_previous_cycles_branch(wall_scene):
    warm = _bin_goals(wall_scene, warm=True)
    cold = _bin_goals(wall_scene, warm=False)
    assert np.allclose(warm[0].q_goal, cold[0].q_goal)  # the first cycle has nothing to start from
    for before, now in zip(warm, warm[1:]):
        # the same gripper pose with another can in the hand: a nearby configuration, no branch flip
        assert np.max(np.abs(now.q_goal - before.q_goal)) < 0.5


def test_a_dataset_built_before_the_setting_is_posed_without_it():
    assert pose_settings({"build": {"settings": {"name": "old"}}}) == {"bin_warm_start": False, "goal_clearance_m": 0.001}
    assert pose_settings({"build": {"settings": {"bin_warm_start": True, "goal_clearance_m": 0.002}}}) == {
        "bin_warm_start": True, "goal_clearance_m": 0.002}
    assert BuildSettings(name="new").bin_warm_start and BuildSettings(name="new").goal_clearance_m == 0.002
