"""The independent validator: every planner's path is accepted or rejected here, identically."""

from __future__ import annotations

import numpy as np

from planners.base import PlanningProblem

#: The validator's resolution: at most this much motion of any joint between two checked states.
VALIDATION_RESOLUTION_RAD = 0.01
ENDPOINT_TOLERANCE_RAD = 1e-6


def validate_path(problem: PlanningProblem, path: np.ndarray | None, world) -> str | None:
    """The independent check of a claimed solution; None if valid, else the reason.

    The path must be finite (N, 7), start at q_start and end at q_goal, stay within the joint
    limits, and be collision-free when its straight segments are checked with at most
    VALIDATION_RESOLUTION_RAD of joint motion between states (python-fcl world).
    """
    if path is None:
        return "no path"
    path = np.asarray(path, float)
    if path.ndim != 2 or path.shape[1] != 7 or len(path) < 1 or not np.all(np.isfinite(path)):
        return f"path must be a finite (N, 7) array, got shape {path.shape}"
    if np.max(np.abs(path[0] - problem.q_start)) > ENDPOINT_TOLERANCE_RAD:
        return "path does not start at q_start"
    if np.max(np.abs(path[-1] - problem.q_goal)) > ENDPOINT_TOLERANCE_RAD:
        return "path does not end at q_goal"
    lo, hi = world.robot.lower_rad, world.robot.upper_rad
    if np.any(path < lo - 1e-9) or np.any(path > hi + 1e-9):
        return "path leaves the joint limits"
    bad = world.path_free(path, resolution_rad=VALIDATION_RESOLUTION_RAD)
    if bad >= 0:
        return f"collision at dense sample {bad}"
    return None
