"""Detections against ground truth: matching and the accuracy figures.

The cans a detection should find are the scene's cans and its dented cans (`truth_cans`): the
seed paper expects dented cans to be recycled ("cans will also likely have dents"), so a dented
can counts in recall and a detection of one is a correct one. Physics keeps a dented can as the
obstacle the `lookalike` family built it as; only the evaluation counts it.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np
from scipy.optimize import linear_sum_assignment

from perception.grasps import CanDetection
from scenes import lookalikes as la
from scenes.scene import CanPose, Scene
from scenes.spec import Obstacle, SceneSpec

#: obstacles a family stands on the plate among the cans (never recyclable) are named so
DISTRACTOR_PREFIX = "distractor_"
#: the matching's cost of a pair farther apart than the gate (metres; far above any scene's distances)
GATED_COST_M = 1e3


@dataclasses.dataclass(frozen=True)
class SceneMatch:
    """How one scene's detections match its cans.

    Attributes:
        n_truth: cans in the scene; n_detected: detections.
        pairs: (can id, detection id) of the matches.
        xy_error_m: centre error in the xy plane of each match, metres.
        kind_correct: per match, lying/upright judged right.
        yaw_error_rad: per match of a lying can judged lying, axis error modulo pi, radians.
        top_error_m: per match, measured top height minus the true top height, metres.
        n_distractors: distractor objects in the scene.
        distractor_grasps: (detection id, distractor name) of each detection whose grasp lies on
            a distractor (see `on_distractor`): a false positive of its own kind, which would
            send the gripper onto an obstacle.
        n_dented, dented_matched: of the cans in n_truth, the dented ones, and how many of them
            a detection matched.
    """

    n_truth: int
    n_detected: int
    pairs: tuple[tuple[int, int], ...]
    xy_error_m: tuple[float, ...]
    kind_correct: tuple[bool, ...]
    yaw_error_rad: tuple[float, ...]
    top_error_m: tuple[float, ...]
    n_distractors: int = 0
    distractor_grasps: tuple[tuple[int, str], ...] = ()
    n_dented: int = 0
    dented_matched: int = 0

    def record(self, seed: int) -> dict:
        """This scene's evaluation counts as an evaluation JSON stores them (`seed`: the scene's), with
        the grasps on distractors by detection and distractor."""
        return {
            "seed": seed,
            "cans": self.n_truth,
            "detections": self.n_detected,
            "matched": len(self.pairs),
            "distractors": self.n_distractors,
            "distractor_grasps": [{"detection": d, "distractor": name} for d, name in self.distractor_grasps],
        }


def distractors_of(spec: SceneSpec) -> tuple[Obstacle, ...]:
    """The scene's distractors: the obstacles a family stood on the plate (`distractor_N`)."""
    return tuple(o for o in spec.extra if o.name.startswith(DISTRACTOR_PREFIX))


def footprint_xy(obstacle: Obstacle, *, samples: int = 32) -> np.ndarray:
    """The obstacle's footprint on the xy plane as a convex polygon (M, 2), metres: the convex hull
    of its outline (a box's corners, a cylinder's end circles, a sphere's equator) at its pose."""
    size = obstacle.size_m
    t = np.linspace(0.0, 2 * math.pi, samples, endpoint=False)
    if obstacle.shape == "box":
        p_O = np.array([[sx * size[0] / 2, sy * size[1] / 2, sz * size[2] / 2]
                        for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    elif obstacle.shape == "cylinder":
        ring = np.column_stack([size[0] * np.cos(t), size[0] * np.sin(t)])
        p_O = np.vstack([np.column_stack([ring, np.full(samples, z)]) for z in (-size[1] / 2, size[1] / 2)])
    elif obstacle.shape == "sphere":
        p_O = np.column_stack([size[0] * np.cos(t), size[0] * np.sin(t), np.zeros(samples)])
    else:
        raise ValueError(f"obstacle {obstacle.name!r} has shape {obstacle.shape!r}; allowed: box, cylinder, sphere")
    X = obstacle.pose()
    p_W = p_O @ X[:3, :3].T + X[:3, 3]
    return cv2.convexHull(p_W[:, :2].astype(np.float32)).reshape(-1, 2)


def on_distractor(p_xy_m, obstacle: Obstacle, *, margin_m: float) -> bool:
    """Whether a point (x, y) lies within `margin_m` of the obstacle's footprint (or inside it)."""
    hull = footprint_xy(obstacle)
    d = cv2.pointPolygonTest(hull.reshape(-1, 1, 2), (float(p_xy_m[0]), float(p_xy_m[1])), True)
    return d >= -margin_m  # positive inside, negative outside: minus the distance to the outline


def axis_error_rad(a_rad: float, b_rad: float) -> float:
    """Angle between two axes (directions without sign), in [0, pi/2]."""
    d = (a_rad - b_rad) % math.pi
    return min(d, math.pi - d)


def match(
    detections: list[CanDetection] | tuple[CanDetection, ...],
    cans: tuple[CanPose, ...],
    *,
    gate_m: float,
    radius_m: float,
    height_m: float,
    distractors: tuple[Obstacle, ...] = (),
    distractor_margin_m: float = 0.0,
) -> SceneMatch:
    """Match detections to cans (Hungarian on xy distance, as many pairs within `gate_m` as there
    can be; pairs farther apart do not match) and find the grasps on distractors.

    Args:
        detections: the perceived cans.
        cans: the ground truth.
        gate_m: the largest xy distance of a match (e.g. the can radius).
        radius_m, height_m: the can's size (for the true top height).
        distractors: obstacles standing among the cans that must never be grasped.
        distractor_margin_m: a grasp this close to a distractor's footprint (or inside it) is on
            the distractor. Below the can radius, a grasp of a can standing against a distractor
            (its centre a radius from the footprint) is not counted.
    """
    pairs, errs, kinds, yaws, tops = [], [], [], [], []
    if detections and cans:
        t = np.array([c.p_WC_m[:2] for c in cans])
        d = np.array([x.p_WC_m[:2] for x in detections])
        cost = np.linalg.norm(t[:, None, :] - d[None, :, :], axis=-1)
        # pairs beyond the gate cost more than any set of pairs within it: the assignment makes as
        # many matches as it can (on the raw distances, a can nothing was detected near could take
        # a neighbour's detection when that made the sum of all distances smaller)
        rows, cols = linear_sum_assignment(np.where(cost <= gate_m, cost, GATED_COST_M))
        for i, j in zip(rows, cols):
            if cost[i, j] > gate_m:
                continue
            can, det = cans[i], detections[j]
            pairs.append((can.id, det.id))
            errs.append(float(cost[i, j]))
            kinds.append(can.lying == det.lying)
            tops.append(det.top_z_m - can.top_z_m(radius_m, height_m))
            if can.lying and det.lying:
                yaws.append(axis_error_rad(det.axis_yaw_rad, can.axis_yaw_rad))
    on = []
    for det in detections:
        hit = next((o.name for o in distractors
                    if on_distractor(det.grasp.X_WG[:2, 3], o, margin_m=distractor_margin_m)), None)
        if hit is not None:
            on.append((det.id, hit))
    return SceneMatch(len(cans), len(detections), tuple(pairs), tuple(errs), tuple(kinds), tuple(yaws), tuple(tops),
                      len(distractors), tuple(on))


def dented_cans(scene: Scene) -> tuple[CanPose, ...]:
    """The scene's dented cans (`scenes.lookalikes`) as cans: centre and axis from their parts, ids
    after the scene's cans'."""
    first = max((c.id for c in scene.cans), default=-1) + 1
    out = []
    for k, parts in enumerate(la.groups(scene.spec.extra, la.DENTED_PREFIX).values()):
        centre, axis = la.dented_pose(parts, height_m=scene.spec.can.height_m)
        lying = abs(float(axis[2])) < 0.5
        out.append(CanPose(first + k, tuple(float(v) for v in centre), lying,
                           math.atan2(float(axis[1]), float(axis[0])) if lying else 0.0))
    return tuple(out)


def truth_cans(scene: Scene) -> tuple[CanPose, ...]:
    """The cans perception should find: the scene's cans, then its dented cans (`dented_cans`)."""
    return tuple(scene.cans) + dented_cans(scene)


def match_scene(detections: list[CanDetection] | tuple[CanDetection, ...], scene: Scene) -> SceneMatch:
    """`match` against `truth_cans` (dented cans count as cans) with the scene's own settings: gate
    one can radius, the scene's distractors, and a grasp within half a can radius of a
    distractor's footprint counted as on it."""
    r = scene.spec.can.radius_m
    dented = {c.id for c in dented_cans(scene)}
    m = match(detections, truth_cans(scene), gate_m=r, radius_m=r, height_m=scene.spec.can.height_m,
              distractors=distractors_of(scene.spec), distractor_margin_m=r / 2)
    return dataclasses.replace(m, n_dented=len(dented), dented_matched=sum(1 for c, _ in m.pairs if c in dented))


@dataclasses.dataclass(frozen=True)
class Accuracy:
    """Aggregate figures over scenes (errors in mm and degrees)."""

    scenes: int
    cans: int
    detections: int
    matched: int
    recall: float
    precision: float
    xy_error_median_mm: float
    xy_error_p95_mm: float
    kind_accuracy: float
    lying_matched: int
    yaw_error_median_deg: float
    yaw_error_p95_deg: float
    top_error_median_mm: float
    distractors: int = 0
    distractor_grasps: int = 0
    dented: int = 0
    dented_matched: int = 0

    def to_json(self) -> dict:
        return {k: (round(v, 4) if isinstance(v, float) else v) for k, v in dataclasses.asdict(self).items()}

    def lines(self) -> list[str]:
        """Human-readable summary lines (the distractor line when there were distractors)."""
        lines = [
            f"scenes {self.scenes}, cans {self.cans}, detections {self.detections}, matched {self.matched}",
            f"recall {100 * self.recall:.1f}%   precision {100 * self.precision:.1f}%",
            f"centre xy error: median {self.xy_error_median_mm:.2f} mm, p95 {self.xy_error_p95_mm:.2f} mm",
            f"lying/upright accuracy {100 * self.kind_accuracy:.1f}%",
            f"lying axis yaw error (mod pi, {self.lying_matched} cans): median {self.yaw_error_median_deg:.2f} deg, "
            f"p95 {self.yaw_error_p95_deg:.2f} deg",
            f"top height error: median {self.top_error_median_mm:+.2f} mm",
        ]
        if self.dented:
            lines.append(f"dented cans (counted among the cans): {self.dented_matched} of {self.dented} found")
        if self.distractors or self.distractor_grasps:
            lines.append(f"grasps on distractors: {self.distractor_grasps} ({self.distractors} distractors in the scenes)")
        return lines


def _q(values, q: float, scale: float) -> float:
    return float(np.percentile(values, q) * scale) if len(values) else float("nan")


def aggregate(matches: list[SceneMatch]) -> Accuracy:
    """The figures over many scenes' matches."""
    n_t = sum(m.n_truth for m in matches)
    n_d = sum(m.n_detected for m in matches)
    n_m = sum(len(m.pairs) for m in matches)
    errs = [e for m in matches for e in m.xy_error_m]
    kinds = [k for m in matches for k in m.kind_correct]
    yaws = [y for m in matches for y in m.yaw_error_rad]
    tops = [t for m in matches for t in m.top_error_m]
    return Accuracy(
        scenes=len(matches),
        cans=n_t,
        detections=n_d,
        matched=n_m,
        recall=n_m / n_t if n_t else 1.0,
        precision=n_m / n_d if n_d else 1.0,
        xy_error_median_mm=_q(errs, 50, 1e3),
        xy_error_p95_mm=_q(errs, 95, 1e3),
        kind_accuracy=sum(kinds) / len(kinds) if kinds else 1.0,
        lying_matched=len(yaws),
        yaw_error_median_deg=_q(yaws, 50, 180 / math.pi),
        yaw_error_p95_deg=_q(yaws, 95, 180 / math.pi),
        top_error_median_mm=_q(tops, 50, 1e3),
        distractors=sum(m.n_distractors for m in matches),
        distractor_grasps=sum(len(m.distractor_grasps) for m in matches),
        dented=sum(m.n_dented for m in matches),
        dented_matched=sum(m.dented_matched for m in matches),
    )


@dataclasses.dataclass(frozen=True)
class LookalikeMatch:
    """The grasps on one scene's look-alikes (`scenes.lookalikes`).

    Attributes:
        hourglasses: hourglasses in the scene; hourglass_grasps: detections whose grasp lies on one
            (within half a can radius of its widest section's footprint); hourglasses_grasped:
            the hourglasses with at least one such grasp (the rest were refused or missed).
        dented: dented cans in the scene, and per dented can found (a detection within a can
            radius of its centre): its xy error (metres), lying/upright right, and (lying) the
            axis error in radians.
    """

    hourglasses: int
    hourglass_grasps: int
    dented: int
    dented_xy_error_m: tuple[float, ...]
    dented_kind_correct: tuple[bool, ...]
    dented_yaw_error_rad: tuple[float, ...]
    hourglasses_grasped: int = 0


def match_lookalikes(detections, scene: Scene) -> LookalikeMatch:
    """How the detections fall on the scene's hourglasses and dented cans."""
    r, h = scene.spec.can.radius_m, scene.spec.can.height_m
    hours = la.groups(scene.spec.extra, la.HOURGLASS_PREFIX)
    widest = [max(parts, key=lambda o: o.size_m[0]) for parts in hours.values()]
    on = [[on_distractor(det.grasp.X_WG[:2, 3], o, margin_m=r / 2) for o in widest] for det in detections]
    on_hour = sum(1 for row in on if any(row))
    grasped = sum(1 for k in range(len(widest)) if any(row[k] for row in on))
    dented = la.groups(scene.spec.extra, la.DENTED_PREFIX)
    errs, kinds, yaws = [], [], []
    for parts in dented.values():
        centre, axis = la.dented_pose(parts, height_m=h)
        lying = abs(axis[2]) < 0.5
        if not detections:
            continue
        d = [float(np.linalg.norm(np.asarray(x.p_WC_m[:2]) - centre[:2])) for x in detections]
        j = int(np.argmin(d))
        if d[j] > r:
            continue
        det = detections[j]
        errs.append(d[j])
        kinds.append(det.lying == lying)
        if lying and det.lying:
            yaws.append(axis_error_rad(det.axis_yaw_rad, math.atan2(axis[1], axis[0])))
    return LookalikeMatch(len(hours), on_hour, len(dented), tuple(errs), tuple(kinds), tuple(yaws), grasped)


def lookalike_lines(matches: list[LookalikeMatch]) -> list[str]:
    """Summary lines over scenes (none when they hold no look-alikes)."""
    n_h = sum(m.hourglasses for m in matches)
    n_d = sum(m.dented for m in matches)
    if not (n_h or n_d):
        return []
    errs = [e for m in matches for e in m.dented_xy_error_m]
    yaws = [y for m in matches for y in m.dented_yaw_error_rad]
    kinds = [k for m in matches for k in m.dented_kind_correct]
    return [f"grasps on hourglasses: {sum(m.hourglass_grasps for m in matches)} ({n_h} hourglasses in the scenes)",
            f"dented cans grasped: {len(errs)} of {n_d}, lying/upright right {sum(kinds)}, xy error median "
            f"{_q(errs, 50, 1e3):.2f} / max {1e3 * max(errs, default=float('nan')):.2f} mm, lying axis error max "
            f"{math.degrees(max(yaws, default=float('nan'))):.2f} deg ({len(yaws)} lying)"]
