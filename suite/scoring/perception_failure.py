"""Perception-induced failures: a path valid in the world the planner saw (built from the cameras)
that the judge rejects in the true world, and what in the truth it struck."""

from __future__ import annotations

import fcl
import numpy as np

from planners.base import PlanningProblem
from suite.scoring.validate import VALIDATION_RESOLUTION_RAD


def struck(world, q: np.ndarray) -> list[tuple[str, str]]:
    """The (robot part, obstacle) pairs of a python-fcl world in collision at configuration q."""
    rows = world._state_rows(np.asarray(q, float))
    req = fcl.CollisionRequest()
    out = []
    for p, part in enumerate(world.parts):
        if part.name == "iiwa_link_0":
            continue
        obj = world._place(p, rows)
        for name, obs in world.obstacles:
            if part.name == "held_can" and name == "plate":
                continue
            if fcl.collide(obj, obs, req, fcl.CollisionResult()):
                out.append((part.name, name))
    return out


def cause_of(problem: PlanningProblem, pair: tuple[str, str] | None) -> str:
    """A failure's cause in words a reader of a perception table knows."""
    if pair is None:
        return "self_collision"
    part, name = pair
    if name.startswith("can_"):
        truth_id = int(name.split("_", 1)[1])
        can = next(c for c in problem.scene.cans if c.id == truth_id)
        r = problem.scene.spec.can.radius_m
        seen = [c for c in problem.plan_world.scene.cans
                if np.hypot(*(np.asarray(c.p_WC_m[:2]) - np.asarray(can.p_WC_m[:2]))) < r]
        return "can_pose_error" if seen else "can_missed"
    if part == "held_can":
        return "held_can"
    from perception.world import LOOSE_PREFIXES

    if name.startswith(LOOSE_PREFIXES):
        return "object_under_covered"
    return "fixture"


def perception_induced(problem: PlanningProblem, path, judge_world, plan_world) -> dict | None:
    """If a path the judge rejected for a collision is free in the planner's world: where it first
    collides in the truth, with what, and the cause (`cause_of`); else None (the planner's own failure)."""
    path = np.asarray(path, float)
    if plan_world.path_free(path, resolution_rad=VALIDATION_RESOLUTION_RAD) >= 0:
        return None
    dense = judge_world.interpolate(path, VALIDATION_RESOLUTION_RAD)
    i = judge_world.first_collision(dense)
    if i < 0:
        return None
    pairs = struck(judge_world, dense[i])
    pair = pairs[0] if pairs else None
    return {"state": int(i), "part": None if pair is None else pair[0], "object": None if pair is None else pair[1],
            "cause": cause_of(problem, pair)}
