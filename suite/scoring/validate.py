"""The independent validator: every planner's path is accepted or rejected here, identically."""

from __future__ import annotations

import numpy as np

from planners.base import PlanningProblem

#: The validator's resolution: at most this much motion of any joint between two checked states.
VALIDATION_RESOLUTION_RAD = 0.01
ENDPOINT_TOLERANCE_RAD = 1e-6


#: The largest claimed path the judge takes on (its reason: time and memory grow with both; a
#: path over either is `invalid_solution`, `stats.reason` = "path_over_limit", and is not checked,
#: timed or scored). Corners: waypoints left after dropping duplicate and collinear ones
#: (`polyline.simplify`), what TOPP-RA works on (about 0.25 MB each); checked states: the
#: validator's 0.01 rad states. Real paths are far below (references: at most a few hundred
#: corners and a few thousand states); 2,000 corners keep a judged trial under 1 GB.
MAX_PATH_CORNERS = 2_000
MAX_CHECKED_STATES = 200_000


def over_limit(path: np.ndarray) -> dict | None:
    """None if the judge takes the claimed path on, else which limit it passes: {limit, value, max}."""
    from scenes.collision.world import CollisionWorld
    from suite.scoring.polyline import simplify

    path = np.atleast_2d(np.asarray(path, float))
    states = 1 + int(np.sum(CollisionWorld.segment_steps(path, VALIDATION_RESOLUTION_RAD)))
    if states > MAX_CHECKED_STATES:
        return {"limit": "checked_states", "value": states, "max": MAX_CHECKED_STATES}
    corners = len(simplify(path)) if len(path) > 2 else len(path)
    if corners > MAX_PATH_CORNERS:
        return {"limit": "corners", "value": corners, "max": MAX_PATH_CORNERS}
    return None


def structure_reason(problem: PlanningProblem, path: np.ndarray | None, world) -> str | None:
    """None if a claimed path is a finite (N, 7) array from q_start to q_goal within the joint
    limits, else the reason: everything the validator asks but collision."""
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
    return None


def validate_path(problem: PlanningProblem, path: np.ndarray | None, world) -> str | None:
    """The independent check of a claimed solution; None if valid, else the reason.

    The path must pass `structure_reason` and be collision-free when its straight segments are
    checked with at most VALIDATION_RESOLUTION_RAD of joint motion between states (python-fcl
    world): steps = max(1, ceil(max_j |dq_j| / 0.01)) per segment, both ends checked. This is the
    field's rule and the suite's success; `certify_path` gives the exact verdict beside it.
    """
    reason = structure_reason(problem, path, world)
    if reason is not None:
        return reason
    bad = world.path_free(np.asarray(path, float), resolution_rad=VALIDATION_RESOLUTION_RAD)
    if bad >= 0:
        return f"collision at dense sample {bad}"
    return None


def certify_path(path: np.ndarray, world) -> dict:
    """The exact verdict of a path on the validator's world and pairs (`scenes.collision.certify`), as
    stored in a trial record's `certification`: verdict (certified, collision or unproved), the
    states and exact distance queries it took, seconds, and where a collision or an unproved
    segment lies."""
    from scenes.collision.certify import certifier

    return certifier(world).certify(np.asarray(path, float)).as_record()
