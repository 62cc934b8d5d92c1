"""`prm-roadmap`: OMPL's PRM builds a roadmap once per world, stored as data; queries never change it."""

from __future__ import annotations

import numpy as np
import pytest

from planners.ompl_roadmap import (
    PRMRoadmapConfig,
    PRMRoadmapPlanner,
    Roadmap,
    ShortcutPRMRoadmapPlanner,
    roadmap_key,
)
from planners.base import PlanStatus
from planners.worlds import collision_world
from scenes.errors import SuiteError
from suite.scoring.validate import validate_path


@pytest.fixture(scope="module")
def task():
    """The GCS paper's task RB -> AS (right bin to above the shelves: the open side of the scene)."""
    from suite.paper.gcs_arm import task_problems

    return dict(task_problems(reverses=False))["RB->AS"]


def _length(path) -> float:
    return float(np.sum(np.linalg.norm(np.diff(np.asarray(path), axis=0), axis=1)))


def test_the_roadmap_is_built_once_stored_and_never_changed_by_queries(task, tmp_path):
    cfg = PRMRoadmapConfig(roadmap_size=1500, seed_paths=False, roadmap_dir=str(tmp_path))
    planner = PRMRoadmapPlanner(cfg)
    planner.prepare(task)
    (stored,) = tmp_path.glob("*.npz")
    assert stored.stem == roadmap_key(task, cfg)
    rm = Roadmap.load(stored)
    assert len(rm.milestones) >= 1500 and len(rm.edges) > len(rm.milestones)
    world = collision_world(task)
    assert world.states_free(rm.milestones).all()  # OMPL's milestones are valid states
    a, b = rm.edges[: 50].T
    assert all(world.motion_free(rm.milestones[i], rm.milestones[j], resolution_rad=cfg.resolution_rad)
               for i, j in zip(a, b))
    result = planner.plan(task)
    assert result.status is PlanStatus.SUCCESS, result.stats
    assert validate_path(task, result.path, world) is None
    assert result.stats["offline_s"] == pytest.approx(rm.offline_s)
    # the reverse query and a repeat: the stored roadmap is what every query searches
    again = planner.plan(task)
    np.testing.assert_array_equal(again.path, result.path)
    assert planner.plan(task.with_(q_start=task.q_goal, q_goal=task.q_start)).status is PlanStatus.SUCCESS
    after = Roadmap.load(stored)
    np.testing.assert_array_equal(after.milestones, rm.milestones)
    # another process (a fresh planner) loads it instead of building it
    other = ShortcutPRMRoadmapPlanner(ShortcutPRMRoadmapPlanner.Config(roadmap_size=1500, seed_paths=False,
                                                                       roadmap_dir=str(tmp_path)))
    other.prepare(task)
    short = other.plan(task)
    assert short.stats["roadmap_cache"] == "hit"
    assert short.status is PlanStatus.SUCCESS and validate_path(task, short.path, world) is None
    assert _length(short.path) <= _length(result.path) + 1e-9  # the simplifier only shortens


def test_a_roadmap_that_cannot_link_the_ends_says_so(tmp_path):
    from suite.paper.gcs_arm import task_problems

    shelf = dict(task_problems(reverses=False))["AS->TS"]  # into the shelf's upper slot
    planner = PRMRoadmapPlanner(PRMRoadmapConfig(roadmap_size=10, seed_paths=False, roadmap_dir=str(tmp_path)))
    result = planner.plan(shelf)
    assert result.status is PlanStatus.NO_SOLUTION
    assert result.stats["reason_code"] == "search_failed"
    assert "joins no milestone" in result.stats["reason"] or "does not link" in result.stats["reason"]


def test_bad_settings_name_the_value():
    with pytest.raises(SuiteError, match="roadmap_size=5 must be >= 10"):
        PRMRoadmapConfig(roadmap_size=5)
