"""Detections against ground truth: matching and the accuracy figures."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.optimize import linear_sum_assignment

from perception.grasps import CanDetection
from scenes.scene import CanPose


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
    """

    n_truth: int
    n_detected: int
    pairs: tuple[tuple[int, int], ...]
    xy_error_m: tuple[float, ...]
    kind_correct: tuple[bool, ...]
    yaw_error_rad: tuple[float, ...]
    top_error_m: tuple[float, ...]


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
) -> SceneMatch:
    """Match detections to cans (Hungarian on xy distance; pairs farther than `gate_m` do not match).

    Args:
        detections: the perceived cans.
        cans: the ground truth.
        gate_m: the largest xy distance of a match (e.g. the can radius).
        radius_m, height_m: the can's size (for the true top height).
    """
    pairs, errs, kinds, yaws, tops = [], [], [], [], []
    if detections and cans:
        t = np.array([c.p_WC_m[:2] for c in cans])
        d = np.array([x.p_WC_m[:2] for x in detections])
        cost = np.linalg.norm(t[:, None, :] - d[None, :, :], axis=-1)
        rows, cols = linear_sum_assignment(cost)
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
    return SceneMatch(len(cans), len(detections), tuple(pairs), tuple(errs), tuple(kinds), tuple(yaws), tuple(tops))


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

    def to_json(self) -> dict:
        return {k: (round(v, 4) if isinstance(v, float) else v) for k, v in dataclasses.asdict(self).items()}

    def lines(self) -> list[str]:
        """Human-readable summary lines."""
        return [
            f"scenes {self.scenes}, cans {self.cans}, detections {self.detections}, matched {self.matched}",
            f"recall {100 * self.recall:.1f}%   precision {100 * self.precision:.1f}%",
            f"centre xy error: median {self.xy_error_median_mm:.2f} mm, p95 {self.xy_error_p95_mm:.2f} mm",
            f"lying/upright accuracy {100 * self.kind_accuracy:.1f}%",
            f"lying axis yaw error (mod pi, {self.lying_matched} cans): median {self.yaw_error_median_deg:.2f} deg, "
            f"p95 {self.yaw_error_p95_deg:.2f} deg",
            f"top height error: median {self.top_error_median_mm:+.2f} mm",
        ]


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
    )
