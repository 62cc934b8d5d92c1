"""The report's problems: one entry per distinct problem with every planner's trials of it, and the
compact drawing data of its drill-down (scene outlines, gripper paths, joint paths).

Everything comes from the saved records; the scene's geometry comes from the run's dataset (its
stored scenes and problems: which cans were already recycled, which can is held, the reference
path) or, for a run on generated scenes, from generating the scene again as `plots_paths` does.
When neither is possible the drill-down draws the paths alone and says so; nothing is made up.

Drawing data is quantized for size: positions in integer millimetres, joint angles and path
length in integer milliradians, paths thinned (Ramer-Douglas-Peucker) to within 2 mm / 1 mrad.
"""

from __future__ import annotations

import dataclasses
import logging
import re
from collections.abc import Sequence
from typing import Any

import numpy as np

from suite.report.outcomes import family_of
from suite.report.scene_outlines import SIDE, TOP, can_outline, scene_outlines
from suite.run.records import (
    PROBLEM_KINDS,
    TrialRecord,
    joint_path,
    problem_key,
    problem_number,
)

log = logging.getLogger(__name__)

#: Thinning tolerances of the drawn paths.
GRIPPER_TOL_M = 0.002
JOINT_TOL_RAD = 0.001


@dataclasses.dataclass(frozen=True)
class Problem:
    """One distinct problem of the run and every planner's trials of it (usually one each).

    Attributes:
        pid: its identity as shown (the record's problem_id, else seed-variant-can-kind for older runs).
        anchor: pid made safe for an HTML id.
        first: its first record (the problem's fields: family, kind, scene, q_start, q_goal, ...).
        trials: planner -> its records of this problem, in file order.
    """

    pid: str
    anchor: str
    first: TrialRecord
    trials: dict[str, list[TrialRecord]]

    @property
    def family(self) -> str:
        return family_of(self.first)

    @property
    def kind(self) -> str:
        return str(self.first.problem)


def problem_label(key: tuple) -> str:
    """A problem key (`problem_key`) as text: the content hash, or seed-variant-can-kind."""
    if len(key) == 1:
        return str(key[0])
    seed, variant, can, kind = key
    return f"s{seed}-{variant}-c{can}-{kind}"


def group_problems(records: Sequence[TrialRecord]) -> list[Problem]:
    """The run's distinct problems, ordered by family, scene, can and cycle order of the kind."""
    groups: dict[tuple, dict[str, list[TrialRecord]]] = {}
    firsts: dict[tuple, TrialRecord] = {}
    for r in records:
        key = problem_key(r)
        firsts.setdefault(key, r)
        groups.setdefault(key, {}).setdefault(str(r.planner), []).append(r)
    kind_rank = {k: i for i, k in enumerate(PROBLEM_KINDS)}

    def order(key):
        r = firsts[key]
        return (family_of(r), int(r.scene_seed), str(r.scene_key or ""), problem_number(r),
                kind_rank.get(str(r.problem), len(kind_rank)), problem_label(key))

    out = []
    for key in sorted(groups, key=order):
        label = problem_label(key)
        out.append(Problem(label, "p-" + re.sub(r"[^A-Za-z0-9_-]", "_", label), firsts[key], groups[key]))
    return out


# --- geometry ---------------------------------------------------------------------------------------


def thin(points: np.ndarray, tol: float) -> np.ndarray:
    """Indices of the points a polyline keeps within `tol` of itself (Ramer-Douglas-Peucker, any dimension)."""
    n = len(points)
    if n <= 2:
        return np.arange(n)
    keep = np.zeros(n, bool)
    keep[[0, -1]] = True
    stack = [(0, n - 1)]
    while stack:
        i, j = stack.pop()
        if j <= i + 1:
            continue
        a, ab = points[i], points[j] - points[i]
        seg = points[i + 1:j] - a
        den = float(ab @ ab)
        t = np.clip(seg @ ab / den, 0.0, 1.0) if den > 0 else np.zeros(len(seg))
        d = np.linalg.norm(seg - t[:, None] * ab, axis=1)
        k = int(np.argmax(d))
        if d[k] > tol:
            keep[i + 1 + k] = True
            stack += [(i, i + 1 + k), (i + 1 + k, j)]
    return np.flatnonzero(keep)


def _mm(xy_m: np.ndarray) -> list[int]:
    return np.rint(np.asarray(xy_m) * 1000).astype(int).ravel().tolist()


def _outlines_json(outlines) -> list[list]:
    return [[o.kind, o.label, _mm(o.xy_m)] for o in outlines]


def scene_json(scene) -> dict[str, Any]:
    """A scene's fixed parts per view and each can's outline per view (mm), for the browser."""
    spec = scene.spec
    out: dict[str, Any] = {"cans": {}}
    for view, dims in (("top", TOP), ("side", SIDE)):
        out[view] = _outlines_json(scene_outlines(spec, (), dims=dims))
        for can in scene.cans:
            out["cans"].setdefault(str(can.id), {})[view] = _mm(can_outline(spec, can.X_WC(), dims=dims,
                                                                            can_id=can.id).xy_m)
    return out


def path_json(q: np.ndarray, robot) -> dict[str, list[int]]:
    """One joint path for the browser: the gripper's positions `g` (x, y, z mm, flattened), and the
    joint path `q` (7 mrad per point, flattened) at path lengths `s` (mrad)."""
    from suite.report.plots_paths import densify_joint_path

    p_WG = robot.gripper_pose(densify_joint_path(q))[:, :3, 3]
    g = p_WG[thin(p_WG, GRIPPER_TOL_M)]
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(q, axis=0), axis=1))])
    keep = thin(q, JOINT_TOL_RAD)
    return {"g": _mm(g), "s": _mm(s[keep]), "q": _mm(q[keep])}


@dataclasses.dataclass(frozen=True)
class World:
    """Where a problem's geometry came from, for the drill-down's note."""

    scenes: dict[str, Any]  # scene_key -> Scene
    stored: dict[str, Any]  # problem_id -> the dataset's PlanningProblem
    references: dict[str, np.ndarray]  # problem_id -> reference path
    note: str  # one sentence: the source, or why the scene is not drawn


def load_world(problems: Sequence[Problem], manifest: dict[str, Any]) -> World:
    """The scenes (and, for a dataset run, the stored problems and references) of the run's problems."""
    selection = (manifest.get("config") or {}).get("dataset")
    dataset = manifest.get("dataset") or {}
    if selection or dataset.get("name"):
        from scenes.errors import SuiteError
        from suite.problems.dataset import load_dataset

        text = selection or dataset["name"]
        try:
            ds = load_dataset(text)
        except SuiteError as exc:
            return World({}, {}, {}, f"The scenes are not drawn: dataset {text!r} cannot be loaded ({exc}).")
        stored = dict(zip(ds.ids, ds.problems))
        scenes = {p.scene.key(): p.scene for p in ds.problems}
        note = f"Scenes, recycled cans, held can and reference paths from dataset {ds.name} (hash {ds.hash})"
        if dataset.get("hash") and dataset["hash"] != ds.hash:
            note += f"; the run used hash {dataset['hash']}: only problems whose content hash matches are drawn"
        return World(scenes, stored, ds.references, note + ".")
    from suite.report.plots_paths import _recorded_scene

    scenes = {}
    for p in problems:
        key = p.first.scene_key
        if key in scenes or key is None:
            continue
        scene = _recorded_scene(manifest, str(p.first.variant), int(p.first.scene_seed), key,
                                cans_seen=1 + max((int(q.first.can_id) for q in problems
                                                   if q.first.can_id is not None), default=-1))
        if scene is not None:
            scenes[key] = scene
    wanted = {p.first.scene_key for p in problems}
    if not scenes:
        note = "The scenes are not drawn: they cannot be generated again as the run recorded them (spec and seed)."
    else:
        note = ("Scenes generated again from the run's spec and seeds, with every can at its starting place (a "
                "generated run does not record which were already recycled)")
        note += "." if len(scenes) == len(wanted) else f"; {len(wanted) - len(scenes)} of {len(wanted)} could not be."
    return World(scenes, {}, {}, note)


def drawing_json(problems: Sequence[Problem], *, planners: Sequence[str], world: World) -> dict[str, Any]:
    """Everything the browser draws: scenes by key, and per problem its cans, held can, endpoints and paths."""
    from scenes.robot_model import load_robot

    default = load_robot()
    used = {p.first.scene_key for p in problems}
    scenes = {k: scene_json(s) for k, s in world.scenes.items() if k in used}
    out: dict[str, Any] = {}
    for p in problems:
        drawn = world.scenes.get(p.first.scene_key)
        robot = load_robot(drawn.spec.robot) if drawn is not None else default  # the gripper's mount differs
        q0, q1 = (np.asarray(q, float) if q else None for q in (p.first.q_start, p.first.q_goal))
        entry: dict[str, Any] = {"scene": p.first.scene_key if p.first.scene_key in scenes else None,
                                 "paths": {}}
        for name, q in (("start", q0), ("goal", q1)):
            if q is not None and q.shape == (7,):
                entry[name] = _mm(robot.gripper_pose(q)[:3, 3])
        stored = world.stored.get(p.pid)
        if stored is not None:
            entry["removed"] = list(stored.removed_can_ids)
            if stored.held is not None:
                entry["removed"].append(stored.held.can.id)
                if q0 is not None:
                    X_WC = robot.gripper_pose(q0) @ stored.held.X_GC
                    entry["held"] = {view: _mm(can_outline(stored.scene.spec, X_WC, dims=dims, can_id=stored.held.can.id,
                                                           held=True).xy_m)
                                     for view, dims in (("top", TOP), ("side", SIDE))}
        if p.pid in world.references:
            entry["ref"] = path_json(world.references[p.pid], robot)
        for planner in planners:
            q = next((joint_path(r) for r in p.trials.get(planner, ()) if joint_path(r) is not None), None)
            if q is not None:
                entry["paths"][planner] = path_json(q, robot)
        out[p.pid] = entry
    return {"scenes": scenes, "problems": out,
            "limits": {"lo": _mm(default.lower_rad), "hi": _mm(default.upper_rad)}}
