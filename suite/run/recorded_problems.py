"""The planning problem of a saved trial record, rebuilt without planning or IK.

A run on a dataset (its manifest names `dataset: {name, tier, hash}`) takes each record's problem
from the dataset by `problem_id` (any tier; a changed dataset hash is only a warning, since the
problem is matched by its content hash). A run on generated scenes regenerates each scene from the
manifest's spec, can count and seed (checking the record's `scene_key`), takes the grasps as the run
took them, and rebuilds each motion's world (held can and its pose in the gripper, gripper
opening, cans already recycled) as `suite.problems.cycle.build_problems` poses it, with `q_start`
and `q_goal` from the record. Where the record has a `problem_id`, the rebuilt problem must hash
to it.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Sequence
from typing import Any

import numpy as np

from planners.base import PlanningProblem
from scenes.scene import HeldCan, Scene
from suite.run.records import TrialRecord

log = logging.getLogger(__name__)

class Unrebuildable(Exception):
    """A record whose problem cannot be rebuilt; the message is the reason (a short phrase)."""


class RecordedProblems:
    """Rebuilds the problems of a run's records (scenes, grasps and datasets loaded once).

    Args:
        records: every record of the run (the removal of recycled cans is read from them).
        manifest: the run's manifest.json as a dict (may be empty).
    """

    def __init__(self, records: Sequence[TrialRecord], manifest: dict[str, Any]) -> None:
        self.records = records
        self.manifest = manifest
        self.config = manifest.get("config") or {}
        self._dataset = None
        self._dataset_problems: dict[str, PlanningProblem] = {}
        self._dataset_error: str | None = None
        #: per (variant, scene seed): the scene's motions by (can id, kind), or why there are none
        self._cycles: dict[tuple[str, int], dict[tuple[int, str], PlanningProblem] | str] = {}

    def problem(self, rec: TrialRecord) -> PlanningProblem:
        """The record's problem. Raises Unrebuildable with the reason."""
        problem = self._from_dataset(rec) if self.manifest.get("dataset") else self._from_scene(rec)
        pid = rec.problem_id
        if pid:
            from suite.problems.identity import problem_id

            if problem_id(problem, rule=self._identity_rule()) != pid:
                raise Unrebuildable("rebuilt problem does not hash to its problem_id")
        return problem

    def _identity_rule(self) -> str:
        """The rule the records' problem_ids were made with: the dataset's, else the run manifest's
        (a run written before rules had names: `round9`)."""
        from suite.problems.dataset import identity_rule

        return identity_rule(self._dataset.manifest if self._dataset is not None else self.manifest)

    def reference(self, rec: TrialRecord, field: str) -> float | None:
        """A reference figure of the record's problem (`reference_length_rad`, ...): the record's own,
        else its dataset's."""
        value = getattr(rec, field)
        if value is None and self._dataset is not None:
            value = (self._dataset.meta.get(rec.problem_id) or {}).get(field)
        return None if value is None else float(value)

    # --- runs on a dataset ------------------------------------------------------------------------

    def _from_dataset(self, rec: TrialRecord) -> PlanningProblem:
        if self._dataset is None and self._dataset_error is None:
            from scenes.errors import SuiteError
            from suite.problems.dataset import load_dataset

            info = self.manifest["dataset"]
            try:  # the whole dataset: its problems are found by content, whatever the run's tier
                self._dataset = load_dataset(info["name"])
            except (SuiteError, KeyError, TypeError, OSError) as exc:
                self._dataset_error = f"dataset not loadable ({exc})"
            else:
                self._dataset_problems = dict(zip(self._dataset.ids, self._dataset.problems))
                if info.get("hash") and info["hash"] != self._dataset.hash:
                    log.warning("dataset %s: hash %s differs from the run's %s; problems are matched by "
                                "content (problem_id)", info["name"], self._dataset.hash, info["hash"])
        if self._dataset_error is not None:
            raise Unrebuildable(self._dataset_error)
        pid = rec.problem_id
        if not pid:
            raise Unrebuildable("record has no problem_id")
        if pid not in self._dataset_problems:
            raise Unrebuildable("problem_id not in the dataset")
        return self._dataset_problems[pid]

    # --- runs on generated scenes -----------------------------------------------------------------

    def _from_scene(self, rec: TrialRecord) -> PlanningProblem:
        key = (str(rec.variant), int(rec.scene_seed))
        if key not in self._cycles:
            try:
                self._cycles[key] = self._scene_problems(*key)
            except Unrebuildable as exc:
                self._cycles[key] = str(exc)
        cycle = self._cycles[key]
        if isinstance(cycle, str):
            raise Unrebuildable(cycle)
        problem = cycle.get((int(rec.can_id), str(rec.problem)))
        if problem is None:
            raise Unrebuildable("no such can or motion in the regenerated scene")
        if rec.scene_key and rec.scene_key != problem.scene.key():
            raise Unrebuildable("regenerated scene differs from the run's")
        if rec.held is not None and bool(rec.held) != (problem.held is not None):
            raise Unrebuildable("held can differs from the run's")
        if rec.q_start is None or rec.q_goal is None:
            raise Unrebuildable("record has no q_start or q_goal")
        return problem.with_(q_start=np.asarray(rec.q_start, float), q_goal=np.asarray(rec.q_goal, float),
                             time_limit_s=float(rec.time_limit_s or 1.0))

    def _scene(self, variant: str, seed: int) -> Scene:
        """The run's scene regenerated as the run generated it, checked against the records' key."""
        from scenes.errors import SuiteError
        from scenes.generate import generate_scene
        from scenes.spec import load_spec

        mine = [r for r in self.records if str(r.variant) == variant and int(r.scene_seed) == seed]
        keys = Counter(r.scene_key for r in mine if r.scene_key)
        want = keys.most_common(1)[0][0] if keys else None
        try:
            spec = load_spec(self.config.get("spec"), variant=variant)
            count = self.config.get("cans")
            if not isinstance(count, int):
                count = 1 + max(int(r.can_id) for r in mine)
            spec = spec.with_can_count(count)
            # Without the reachability check (no IK) first: on most plates it gives the run's scene,
            # which the key confirms. Without a key, generate exactly as the run did.
            scene = generate_scene(spec, seed=seed, check_reachable=want is None)
            if want is not None and scene.key() != want:
                scene = generate_scene(spec, seed=seed)
        except (SuiteError, OSError, ValueError) as exc:
            raise Unrebuildable(f"scene not regenerable ({exc})") from None
        if want is not None and scene.key() != want:
            raise Unrebuildable("regenerated scene differs from the run's")
        return scene

    def _scene_problems(self, variant: str, seed: int) -> dict[tuple[int, str], PlanningProblem]:
        """Every motion of the scene's cycles by (can id, kind), with q_start/q_goal still unset."""
        from scenes.errors import SuiteError
        from scenes.grasp_rule import waypoint_pose
        from suite.problems.cycle import match_truth
        from suite.run.runner import scene_grasps

        scene = self._scene(variant, seed)
        spec = scene.spec
        spec.require("waypoints", "can", needed_by="posing a run's cycle problems again")
        wp = spec.waypoints
        X_plate, X_bin = waypoint_pose(wp.above_plate_m), waypoint_pose(wp.above_bin_m)
        opening, closed = spec.grasp.open_width_m, 2 * spec.can.radius_m
        mine = [r for r in self.records if str(r.variant) == variant and int(r.scene_seed) == seed]
        out: dict[tuple[int, str], PlanningProblem] = {}
        removed: tuple[int, ...] = ()
        try:
            grasps = scene_grasps(scene, grasps=self.config.get("grasps") or "truth")
        except SuiteError as exc:
            raise Unrebuildable(f"grasps not reproducible ({exc})") from None
        for grasp in grasps:
            truth = match_truth(scene.without_cans(removed), grasp)
            can_id = truth.id if truth is not None else -1 - grasp.can_id
            held = HeldCan.from_grasp(truth, grasp.X_WG) if truth is not None else None
            removed_after = removed + ((truth.id,) if truth is not None else ())
            worlds = {
                "approach": (grasp.X_WGpre, None, opening, removed),
                "descend": (grasp.X_WG, None, opening, removed),
                "lift": (X_plate, held, closed, removed),
                "transit": (X_bin, held, closed, removed_after),
                "return": (X_plate, None, opening, removed_after),
            }
            for kind, (X_goal, held_, opening_, removed_) in worlds.items():
                out[(can_id, kind)] = PlanningProblem(
                    kind=kind, scene=scene, can_id=can_id, q_start=np.full(7, np.nan), q_goal=None,
                    X_WG_goal=X_goal, waypoints=(), held=held_, gripper_opening_m=opening_,
                    removed_can_ids=tuple(removed_), time_limit_s=1.0, seed=seed,
                )
            # build_problems counts a can as recycled once its transit had a goal configuration.
            transits = [r for r in mine if int(r.can_id) == can_id and r.problem == "transit"]
            if not transits or any(r.q_goal is not None for r in transits):
                removed = removed_after
        return out

