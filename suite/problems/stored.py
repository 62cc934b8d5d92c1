"""A dataset's lines: how a scene and a planning problem are stored (one JSON line each, in
`scenes.jsonl` and `problems.jsonl`), how they are read back into a `Scene` and a
`PlanningProblem`, and the hashes over them (a line's `record_hash`, the whole dataset's hash).

A stored problem keeps every pose at full precision, so that a loaded problem hashes (its
`problem_id`) as the built one. Where the lines live and how a dataset is loaded, selected and
verified is `suite.problems.dataset`'s.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from typing import Any

import numpy as np

from planners.base import PlanningProblem, TaskWaypoint
from scenes.errors import SuiteError
from scenes.scene import CanPose, HeldCan, Scene
from scenes.schema import load
from suite.problems.identity import problem_id


def _pose(X) -> list:
    # full precision: JSON round-trips floats exactly, so a loaded problem hashes as the built one
    return np.asarray(X, float).tolist()


def scene_record(scene: Scene, *, split: str) -> dict[str, Any]:
    """A scene as stored: its concrete spec, seed, family, split and cans."""
    return {"scene_key": scene.key(), "family": scene.variant, "seed": scene.seed, "split": split,
            "spec": json.loads(json.dumps(scene.spec.to_dict(), default=list)),
            "cans": [dataclasses.asdict(c) for c in scene.cans]}


def scene_from_record(rec: dict[str, Any]) -> Scene:
    from scenes.spec import spec_from_dict

    cans = tuple(CanPose(int(c["id"]), tuple(c["p_WC_m"]), bool(c["lying"]), float(c["axis_yaw_rad"]))
                 for c in rec["cans"])
    return Scene(spec_from_dict(rec["spec"]), int(rec["seed"]), cans)


Pose = tuple[tuple[float, float, float, float], tuple[float, float, float, float],
             tuple[float, float, float, float], tuple[float, float, float, float]]
Q = tuple[float, float, float, float, float, float, float]


@dataclasses.dataclass(frozen=True)
class StoredWaypoint:
    """A task waypoint: its time in the cycle's schedule and the gripper pose (4x4, m)."""

    t: float
    X_WG: Pose


@dataclasses.dataclass(frozen=True)
class StoredHeld:
    """The can in the gripper: which, and its pose in the gripper frame (4x4, m)."""

    can_id: int
    X_GC: Pose


@dataclasses.dataclass(frozen=True)
class StoredProblem:
    """A problem as a line of problems.jsonl holds it (written by `problem_record`, read by
    `problem_from_record`); the line's other fields (trivial, split, reference, witness, ...) are
    the build's `meta`, kept as they are."""

    problem_id: str
    scene_key: str
    family: str
    scene_seed: int
    kind: str
    #: the can of a cycle's motion; None for a free transit (`planners.base.FREE_TRANSIT`)
    can_id: int | None
    q_start: Q
    q_goal: Q
    X_WG_goal: Pose
    waypoints: tuple[StoredWaypoint, ...]
    held: StoredHeld | None
    gripper_opening_m: float
    removed_can_ids: tuple[int, ...]
    #: a free transit's number among its scene's tasks; left out of a cycle motion's line (None),
    #: so those lines, and their record hashes, are as before free transits existed
    task_index: int | None = None


def problem_record(problem: PlanningProblem, meta: dict[str, Any], *, rule: str) -> dict[str, Any]:
    """A problem as stored, its id made with identity rule `rule`; `meta` adds trivial,
    difficulty, split and the reference."""
    stored = StoredProblem(
        problem_id=problem_id(problem, rule=rule), scene_key=problem.scene.key(), family=problem.scene.variant,
        scene_seed=problem.scene.seed, kind=problem.kind, can_id=problem.can_id,
        q_start=np.asarray(problem.q_start, float).tolist(), q_goal=np.asarray(problem.q_goal, float).tolist(),
        X_WG_goal=_pose(problem.X_WG_goal),
        waypoints=[StoredWaypoint(w.t, _pose(w.X_WG)) for w in problem.waypoints],
        held=None if problem.held is None else StoredHeld(problem.held.can.id, _pose(problem.held.X_GC)),
        gripper_opening_m=problem.gripper_opening_m, removed_can_ids=list(problem.removed_can_ids),
        task_index=problem.task_index)
    rec = {**dataclasses.asdict(stored), **meta}
    if rec["task_index"] is None:
        del rec["task_index"]
    rec["record_hash"] = record_hash(rec)
    return rec


def record_hash(rec: dict[str, Any]) -> str:
    """Hash of a stored problem line without its own `record_hash` field."""
    body = {k: v for k, v in rec.items() if k != "record_hash"}
    return hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()[:20]


def problem_from_record(rec: dict[str, Any], scene: Scene, *, time_limit_s: float, seed: int = 0,
                        where: str = "stored problem: ") -> PlanningProblem:
    """The problem of a problems.jsonl line, loaded into `StoredProblem` (one SuiteError line,
    starting with `where`, for a bad field)."""
    sp = load(StoredProblem, rec, where=where, ignore_unknown=True)
    held = None
    if sp.held is not None:
        can = next((c for c in scene.cans if c.id == sp.held.can_id), None)
        if can is None:
            raise SuiteError(f"{where}field 'held.can_id' = {sp.held.can_id}: no such can in scene {sp.scene_key}")
        held = HeldCan(can, np.asarray(sp.held.X_GC, float))
    return PlanningProblem(
        kind=sp.kind, scene=scene, can_id=sp.can_id,
        q_start=np.asarray(sp.q_start, float), q_goal=np.asarray(sp.q_goal, float),
        X_WG_goal=np.asarray(sp.X_WG_goal, float),
        waypoints=tuple(TaskWaypoint(w.t, np.asarray(w.X_WG, float)) for w in sp.waypoints),
        held=held, gripper_opening_m=sp.gripper_opening_m,
        removed_can_ids=sp.removed_can_ids, time_limit_s=time_limit_s, seed=seed, task_index=sp.task_index,
    )


def dataset_hash(scene_lines: list[str], records: list[dict]) -> str:
    h = hashlib.sha256()
    for line in sorted(scene_lines):
        h.update(hashlib.sha256(line.encode()).digest())
    for rec in sorted(records, key=lambda r: r["problem_id"]):
        h.update(rec["record_hash"].encode())
    return h.hexdigest()[:20]
