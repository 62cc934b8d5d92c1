"""A problem's identity (content hash), and whether its straight joint-space segment already solves it.

A problem is what a planner is asked: its collision world (every obstacle, the cans on the plate,
the held can with its pose in the gripper and padding, the gripper opening, the robot model),
`q_start` and `q_goal`. Two problems with the same content are the same problem, whatever scene
seed, can id or kind produced them: they are planned once per planner and counted once.

A problem is *trivial* when the straight joint-space segment from start to goal passes the
independent validator. Its *difficulty* here is the fraction of that segment's densely checked
states that collide (0 for a trivial problem).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json

import numpy as np

from planners.base import PlanningProblem
from scenes.identity_rule import CURRENT_RULE, hashed_list, hashed_scalar
from scenes.robot_model import DEFAULT_ROBOT


@functools.lru_cache(maxsize=None)
def robot_hash(robot: str = DEFAULT_ROBOT) -> str:
    """Hash of a robot variant's arm and gripper model files (part of every problem's world)."""
    from scenes.robot_model import robot_variant

    v = robot_variant(robot)
    h = hashlib.sha256()
    for path in (v.iiwa_urdf, v.wsg_urdf):
        h.update(path.read_bytes())
    return h.hexdigest()[:16]


def world_content(problem: PlanningProblem, *, rule: str = CURRENT_RULE) -> dict:
    """The collision world of a problem as plain values (what its identity hashes), its floats
    written by identity rule `rule` (`scenes.identity_rule`)."""
    def r(values):
        return hashed_list(values, rule=rule)

    spec = problem.scene.spec
    gone = set(problem.removed_can_ids) | ({problem.held.can.id} if problem.held is not None else set())
    cans = sorted(r(c.X_WC()) for c in problem.scene.cans if c.id not in gone)
    held = None
    if problem.held is not None:
        held = {"X_GC": r(problem.held.X_GC), "margin_m": spec.grasp.held_margin_m}
    return {
        "robot": robot_hash(spec.robot),
        "obstacles": [{"shape": o.shape, "size_m": r(o.size_m), "X_WO": r(o.X_WO),
                       "rests_held_can": o.name == "plate"} for o in spec.obstacles()],
        "can": None if spec.can is None else [spec.can.radius_m, spec.can.height_m],  # None: a world without cans
        "cans": cans,
        "held": held,
        "gripper_opening_m": hashed_scalar(problem.gripper_opening_m, rule=rule),
    }


def problem_id(problem: PlanningProblem, *, rule: str = CURRENT_RULE) -> str:
    """The problem's content hash (20 hex digits): its world, q_start and q_goal.

    Args:
        problem: the problem.
        rule: the identity rule (`scenes.identity_rule.RULES`): the current one for problems posed
            now; a frozen dataset's own (its manifest's `identity_rule`) to check its stored ids.
    """
    blob = {
        "world": world_content(problem, rule=rule),
        "q_start": None if problem.q_start is None else hashed_list(problem.q_start, rule=rule),
        "q_goal": None if problem.q_goal is None else hashed_list(problem.q_goal, rule=rule),
    }
    if problem.plan_world is not None:  # planned in another world than the judge's
        blob["plan_world"] = world_content(problem.for_planner(), rule=rule)
    return hashlib.sha256(json.dumps(blob, sort_keys=True).encode()).hexdigest()[:20]


@dataclasses.dataclass(frozen=True)
class StraightLine:
    """The straight joint-space segment of a problem, checked as the validator checks a path.

    Attributes:
        trivial: the segment passes the validator.
        collision_fraction: fraction of its states (at the validator's resolution) in collision.
        length_rad: its joint-space length (the shortest any path can be).
    """

    trivial: bool
    collision_fraction: float
    length_rad: float


def straight_line(problem: PlanningProblem, world=None) -> StraightLine:
    """Check the straight segment from q_start to q_goal with the problem's python-fcl world."""
    from planners.worlds import collision_world
    from suite.scoring.validate import VALIDATION_RESOLUTION_RAD, validate_path

    world = world or collision_world(problem)
    q0, q1 = np.asarray(problem.q_start, float), np.asarray(problem.q_goal, float)
    segment = np.stack([q0, q1])
    trivial = validate_path(problem, segment, world) is None
    dense = world.interpolate(segment, VALIDATION_RESOLUTION_RAD)
    fraction = 0.0 if trivial else float(np.mean(~world.states_free(dense)))
    return StraightLine(trivial, fraction, float(np.linalg.norm(q1 - q0)))
