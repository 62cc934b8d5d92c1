"""Problem identity (content hash) and the straight-segment triviality test."""

from __future__ import annotations

import numpy as np
import pytest

from scenes.grasp_rule import truth_grasp
from suite.problems.cycle import build_problems
from suite.problems.identity import problem_id, straight_line


@pytest.fixture(scope="module")
def cycle(wall_scene):
    return {p.kind: p for p in build_problems(wall_scene, [truth_grasp(wall_scene, wall_scene.cans[0])],
                                              time_limit_s=1.0, seed=5)}


def test_descend_is_trivial_and_the_wall_transit_is_not(cycle):
    down = straight_line(cycle["descend"])
    assert down.trivial and down.collision_fraction == 0.0
    over = straight_line(cycle["transit"])  # straight through the wall
    assert not over.trivial and 0.0 < over.collision_fraction < 1.0
    assert over.length_rad == pytest.approx(np.linalg.norm(cycle["transit"].q_goal - cycle["transit"].q_start))


def test_same_content_same_id_whatever_the_labels(cycle):
    p = cycle["transit"]
    assert problem_id(p) == problem_id(p.with_(can_id=7, kind="return", seed=99, time_limit_s=30.0))


def test_any_change_of_world_or_configuration_changes_the_id(cycle):
    p = cycle["transit"]
    base = problem_id(p)
    q = p.q_goal.copy()
    q[3] += 1e-6
    assert problem_id(p.with_(q_goal=q)) != base
    assert problem_id(p.with_(gripper_opening_m=p.gripper_opening_m + 0.001)) != base
    assert problem_id(p.with_(removed_can_ids=(0, 1))) != base  # another can gone from the plate
    assert problem_id(p.with_(removed_can_ids=())) == base  # the held can is never on the plate anyway
    assert problem_id(p.with_(held=None)) != base
    # a different held can pose in the gripper (another can) misses
    X = p.held.X_GC.copy()
    X[2, 3] += 0.01
    assert problem_id(p.with_(held=type(p.held)(p.held.can, X))) != base
