"""Telling a can from a look-alike that only a side view can (the seed paper's hourglass): an
upright detection's side, as the side cameras (`front`, `back`) see it, must stand at the can's
radius from its axis.

For each side camera, the points it sees at heights `SIDE_BAND` of the can's height above the
plate and within r + `OUTSIDE_M` of the detection's axis (a cylinder around the can; neighbours
stay outside it) give the median distance of the side from the axis. A can's is r; an
hourglass's waist is narrower. A camera that sees fewer than `MIN_POINTS` such points (the side
hidden by something in front) has no say. The detection is a look-alike when at least one camera
has a say and every one that has finds the side more than `PerceptionParams.shape_tolerance_m`
inside the can's radius.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from perception.geometry import back_project_camera, camera_to_world
from scenes.render import CameraImage
from scenes.spec import SceneSpec

#: the cameras that look at the plate from the side
SIDE_CAMERAS = ("front", "back")
#: heights (fractions of the can's height above the plate) where the side is measured
SIDE_BAND = (0.3, 0.7)
#: how far beyond the can's radius a side point may lie (depth noise) and still count
OUTSIDE_M = 0.004
MIN_POINTS = 30


@dataclasses.dataclass(frozen=True)
class SideView:
    """One camera's look at an upright detection's side: points seen, and their median distance
    from the detection's axis in metres (NaN without points)."""

    camera: str
    points: int
    median_radius_m: float


def world_points(images: dict[str, CameraImage]) -> dict[str, np.ndarray]:
    """Each side camera's frame back-projected to world points (N, 3), valid depth only."""
    out = {}
    for name in SIDE_CAMERAS:
        if name in images:
            im = images[name]
            p = camera_to_world(back_project_camera(im.depth_m, K=im.K, origin_px=(0, 0)), im.X_WC).reshape(-1, 3)
            out[name] = p[np.isfinite(p).all(axis=1)]
    return out


def side_views(p_xy_m, points: dict[str, np.ndarray], spec: SceneSpec) -> list[SideView]:
    """What every side camera sees of the side of an upright can standing at `p_xy_m`."""
    r, h = spec.can.radius_m, spec.can.height_m
    lo, hi = (spec.plate_top_z_m + f * h for f in SIDE_BAND)
    out = []
    for name, p in points.items():
        z = p[:, 2]
        near = (z > lo) & (z < hi) & (np.abs(p[:, 0] - p_xy_m[0]) < r + OUTSIDE_M) & (np.abs(p[:, 1] - p_xy_m[1]) < r + OUTSIDE_M)
        rho = np.hypot(p[near, 0] - p_xy_m[0], p[near, 1] - p_xy_m[1])
        rho = rho[rho < r + OUTSIDE_M]
        out.append(SideView(name, int(rho.size), float(np.median(rho)) if rho.size else float("nan")))
    return out


def looks_alike(views: list[SideView], *, radius_m: float, tolerance_m: float) -> bool:
    """True when the cameras that see enough of the side all find it inside the can's radius."""
    seen = [v for v in views if v.points >= MIN_POINTS]
    return bool(seen) and all(v.median_radius_m < radius_m - tolerance_m for v in seen)
