"""Where a rejected path collides, and how deeply: for an external planner whose collision model
disagrees with the validator's.

The validator only says "collision at dense sample k". Here every densely checked state of the
path (the validator's samples) that collides is measured: its signed distance to the scene
(python-fcl, negative in penetration, as `CollisionWorld.clearance`) and, the robot's own pairs that
overlap and by how much, naming every colliding pair.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import TYPE_CHECKING

import fcl
import numpy as np

if TYPE_CHECKING:
    from suite.run.records import TrialRecord


@dataclasses.dataclass(frozen=True)
class Penetration:
    """The collisions along one path.

    Attributes:
        colliding_samples: how many of the validator's dense samples collide.
        samples: how many samples there are.
        scene_depth_m: deepest penetration of the robot (and held can) into the scene, m (0 if
            it collides only with itself).
        self_depth_m: deepest penetration between two robot parts, m (0 if none).
        pairs: the colliding pairs, e.g. "iiwa_link_5|iiwa_link_7" or "held_can|can_2".
    """

    colliding_samples: int
    samples: int
    scene_depth_m: float
    self_depth_m: float
    pairs: tuple[str, ...]

    def line(self) -> str:
        what = ", ".join(self.pairs)
        return (f"{self.colliding_samples}/{self.samples} samples collide ({what}); deepest "
                f"{1000 * self.scene_depth_m:.1f} mm into the scene, {1000 * self.self_depth_m:.1f} mm self")


def _part_pose(world, part, X_WB: np.ndarray) -> fcl.CollisionObject:
    X = X_WB[part.body] @ part.X_BS
    return fcl.CollisionObject(part.geom, fcl.Transform(X[:3, :3], X[:3, 3]))


def penetration(path: np.ndarray, world) -> Penetration:
    """Measure the collisions of a path at the validator's dense samples.

    Args:
        path: the (N, 7) joint path, rad.
        world: the problem's python-fcl world.
    """
    from suite.scoring.validate import VALIDATION_RESOLUTION_RAD

    dense = world.interpolate(np.asarray(path, float), VALIDATION_RESOLUTION_RAD)
    bad = np.flatnonzero(~world.states_free(dense))
    scene = self_depth = 0.0
    pairs: set[str] = set()
    req = fcl.DistanceRequest(enable_signed_distance=True)
    for q in dense[bad]:
        d = world.clearance(q)
        X_WB = world.robot.link_poses(q)
        if d <= 0:
            scene = max(scene, -d)
            for part in world.parts:
                if part.name == "iiwa_link_0":  # welded to the static world, never checked
                    continue
                obj = _part_pose(world, part, X_WB)
                for name, ob in world.obstacles:
                    if not (part.name == "held_can" and name == "plate") and fcl.collide(
                            obj, ob, fcl.CollisionRequest(), fcl.CollisionResult()):
                        pairs.add(f"{part.name}|{name}")
        for i, j in world.self_pairs:
            a, b = world.parts[i], world.parts[j]
            oa, ob = _part_pose(world, a, X_WB), _part_pose(world, b, X_WB)
            if fcl.collide(oa, ob, fcl.CollisionRequest(), fcl.CollisionResult()):
                depth = -float(fcl.distance(oa, ob, req, fcl.DistanceResult()))
                self_depth = max(self_depth, depth)
                pairs.add(f"{a.name}|{b.name}")
    return Penetration(len(bad), len(dense), scene, self_depth, tuple(sorted(pairs)))


def explain_rejections(results, dataset: str, records: Sequence[TrialRecord]) -> list[str]:
    """One line per imported path the validator rejected for collision, then a summary line.

    Args:
        results: the results file that was imported.
        dataset: its dataset `NAME[:TIER]`.
        records: the import's records.
    """
    from planners.worlds import collision_world
    from suite.exchange.results import read_results
    from suite.problems.dataset import load_dataset

    ds = load_dataset(dataset)
    problems = dict(zip(ds.ids, ds.problems))
    paths = {ln.problem_id: ln.path_array for ln in read_results(results, known=set(ds.ids), dataset=dataset)}
    out, depths = [], []
    for rec in records:
        reason = (rec.stats or {}).get("invalid_reason") or ""
        if rec.status != "invalid_solution" or not reason.startswith("collision"):
            continue
        pid = rec.problem_id
        p = penetration(paths[pid], collision_world(problems[pid]))
        depths.append(max(p.scene_depth_m, p.self_depth_m))
        out.append(f"  {pid} {rec.family or ''} {rec.problem}: {p.line()}")
    claimed = sum(1 for r in records if (r.stats or {}).get("reported_status") is not None
                  and r.status in ("success", "invalid_solution", "timing_failed"))
    if depths:
        d = np.asarray(depths) * 1000
        out.append(f"{len(depths)} of {claimed} claimed paths collide at the validator's samples; deepest "
                   f"penetration per path: median {np.median(d):.1f} mm, max {d.max():.1f} mm")
    else:
        out.append(f"none of {claimed} claimed paths collides at the validator's samples")
    return out
