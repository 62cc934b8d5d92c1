"""Telling a can from a look-alike that only a side view can (the seed paper's hourglass): an
upright detection's side, as the side cameras (`front`, `back`) see it, must reach the can's
radius from its axis at every height.

A can is a cylinder of radius r about its axis. A look-alike that matches its top (the
hourglass) is narrower all round at some height; a dented can is narrower on one side only. So
the side is measured as a profile about an axis:

- The side cameras' points around the axis (within r + `OUTSIDE_M` of it: neighbours stay
  outside) are cut into height bands (`BAND_EDGES`, fractions of the can's height above the
  plate; the plate's contact and the top's rim are left out) and azimuth sectors about the axis
  (`SECTOR_DEG`, both cameras pooled).
- A band's radius is the widest the side is seen there: the largest median distance from the
  axis over its sectors with at least `MIN_SECTOR_POINTS` points. A dent pulls in the sectors
  that face it; the far side still reaches r.
- The profile's waist is its narrowest band.

Two axes are tried, and the side is a can's if it reaches r about either (the benefit of the
doubt goes to the can): the axis the top view found (its rim's circle), and the side's own axis
(`refit_axis`: the common centre of the side's circles, one free radius per band, within
`MAX_AXIS_SHIFT_M` of the top's). The top's axis is off by up to 2-3 mm under a noisy sensor, and
a can seen from one side only then looks that much narrower; the side's own axis removes that
error but is pulled towards a dent's band, which the top's axis is not.

The detection is a look-alike when the waist lies more than `SIDE_TOLERANCE_M` inside r about
both axes. The profile holds only the bands some sector sees; a detection whose side no camera
sees (hidden by its neighbours) has none and is kept: the top view cannot tell. A dented can seen
from its dent's side only is refused: nothing shows its far side.

`SIDE_TOLERANCE_M` comes from the spread of real cans' waists, not from the look-alike's shape.
On `lookalike` seeds 9400-9439 (221 upright cans, 56 hourglasses), with a perfect sensor and under
`kinect-v1`, no can's waist lay more than 1.1 mm inside r, and every hourglass at 0.8 r whose
middle (30-70% of its height) the side cameras saw lay at least 3.0 mm inside r (one, its middle
hidden under `kinect-v1`, 1.5 mm). The tolerance sits about midway, at 2.25 mm
(docs/perception.md).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from perception.geometry import back_project_camera, camera_to_world
from scenes.render import CameraImage
from scenes.spec import SceneSpec

#: the cameras that look at the plate from the side
SIDE_CAMERAS = ("front", "back")
#: edges of the height bands the side is measured in, as fractions of the can's height above the plate
BAND_EDGES = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)
#: width of the azimuth sectors about the axis (degrees)
SECTOR_DEG = 30.0
#: how far beyond the can's radius a side point may lie (depth noise) and still count
OUTSIDE_M = 0.004
#: points a sector of a band needs for its median to count
MIN_SECTOR_POINTS = 8
#: how far the side's own axis may lie from the top's (the top fit's error is within it)
MAX_AXIS_SHIFT_M = 0.004
#: a detection whose side's narrowest band lies further inside the can's radius is a look-alike
SIDE_TOLERANCE_M = 0.00225


@dataclasses.dataclass(frozen=True)
class SideProfile:
    """The side cameras' look at an upright detection's side, about one axis.

    Attributes:
        cameras: the side cameras with points on the side.
        points: side points in the bands, all cameras.
        band_radius_m: per height band (between consecutive `BAND_EDGES`), the widest the side is
            seen from the axis in metres (the largest median of its sectors); NaN where no sector
            has `MIN_SECTOR_POINTS` points.
        axis_xy_m: the axis (x, y) in the world, metres.
        axis: `top` (the top view's) or `side` (`refit_axis`).
    """

    cameras: tuple[str, ...]
    points: int
    band_radius_m: tuple[float, ...]
    axis_xy_m: tuple[float, float] = (float("nan"), float("nan"))
    axis: str = "top"

    @property
    def seen_bands(self) -> int:
        return sum(1 for v in self.band_radius_m if v == v)

    @property
    def waist_m(self) -> float:
        """The narrowest band's radius (metres); NaN when no band is seen."""
        seen = [v for v in self.band_radius_m if v == v]
        return min(seen) if seen else float("nan")

    @property
    def waist_height(self) -> float:
        """The middle of the narrowest band, as a fraction of the can's height (NaN when unseen)."""
        if not self.seen_bands:
            return float("nan")
        k = int(np.nanargmin(np.asarray(self.band_radius_m)))
        return 0.5 * (BAND_EDGES[k] + BAND_EDGES[k + 1])


def world_points(images: dict[str, CameraImage]) -> dict[str, np.ndarray]:
    """Each side camera's frame back-projected to world points (N, 3), valid depth only."""
    out = {}
    for name in SIDE_CAMERAS:
        if name in images:
            im = images[name]
            p = camera_to_world(back_project_camera(im.depth_m, K=im.K, origin_px=(0, 0)), im.X_WC).reshape(-1, 3)
            out[name] = p[np.isfinite(p).all(axis=1)]
    return out


def _around(p_xy_m, points: dict[str, np.ndarray], spec: SceneSpec) -> dict[str, np.ndarray]:
    """Each camera's points in the bands' heights within reach of any axis `refit_axis` may find."""
    reach = spec.can.radius_m + OUTSIDE_M + MAX_AXIS_SHIFT_M
    lo, hi = (spec.plate_top_z_m + f * spec.can.height_m for f in (BAND_EDGES[0], BAND_EDGES[-1]))
    out = {}
    for name, p in points.items():
        near = (np.abs(p[:, 0] - p_xy_m[0]) < reach) & (np.abs(p[:, 1] - p_xy_m[1]) < reach) & (p[:, 2] > lo) & (p[:, 2] < hi)
        out[name] = p[near]
    return out


def _bands(z_m: np.ndarray, spec: SceneSpec) -> np.ndarray:
    return np.searchsorted(spec.plate_top_z_m + spec.can.height_m * np.asarray(BAND_EDGES), z_m) - 1


def _profile(axis_xy, near: dict[str, np.ndarray], spec: SceneSpec, *, axis: str) -> SideProfile:
    """The profile about `axis_xy` of the points `_around` gave."""
    reach = spec.can.radius_m + OUTSIDE_M
    n_sectors = int(round(360 / SECTOR_DEG))
    cams, rhos, bands, sectors = [], [], [], []
    for name, p in near.items():
        dx, dy = p[:, 0] - axis_xy[0], p[:, 1] - axis_xy[1]
        rho = np.hypot(dx, dy)
        keep = rho < reach
        if not keep.any():
            continue
        cams.append(name)
        rhos.append(rho[keep])
        bands.append(_bands(p[keep, 2], spec))
        az = np.mod(np.arctan2(dy[keep], dx[keep]), 2 * math.pi)
        sectors.append(np.minimum((az / math.radians(SECTOR_DEG)).astype(int), n_sectors - 1))
    n_bands = len(BAND_EDGES) - 1
    xy = (float(axis_xy[0]), float(axis_xy[1]))
    if not cams:
        return SideProfile((), 0, (float("nan"),) * n_bands, xy, axis)
    rho, band, sector = np.concatenate(rhos), np.concatenate(bands), np.concatenate(sectors)
    out = []
    for k in range(n_bands):
        in_band = band == k
        widest = float("nan")
        for s in np.unique(sector[in_band]):
            cell = rho[in_band & (sector == s)]
            if cell.size >= MIN_SECTOR_POINTS:
                m = float(np.median(cell))
                widest = m if not widest >= m else widest
        out.append(widest)
    return SideProfile(tuple(cams), int(rho.size), tuple(out), xy, axis)


def refit_axis(p_xy_m, near: dict[str, np.ndarray], spec: SceneSpec, *, iterations: int = 10) -> np.ndarray:
    """The side's own axis (x, y): the common centre of its height bands' circles, each band with
    its own radius (an hourglass's bands are concentric circles of different radii), fitted by
    Gauss-Newton from `p_xy_m` with Huber weights (a dent's points count less) and kept within
    `MAX_AXIS_SHIFT_M` of it. `near`: the points `_around` gave."""
    c0 = np.asarray(p_xy_m, float)
    p = np.concatenate(list(near.values())) if near else np.zeros((0, 3))
    if len(p) < 3 * MIN_SECTOR_POINTS:
        return c0
    band_all = _bands(p[:, 2], spec)
    n_bands = len(BAND_EDGES) - 1
    reach = spec.can.radius_m + OUTSIDE_M
    c = c0.copy()
    for _ in range(iterations):
        d = p[:, :2] - c
        rho = np.hypot(d[:, 0], d[:, 1])
        sel = (rho < reach) & (rho > 1e-6)
        if sel.sum() < 3 * MIN_SECTOR_POINTS:
            break
        d, rho, band = d[sel], rho[sel], band_all[sel]
        radius = np.array([np.median(rho[band == k]) if np.any(band == k) else 0.0 for k in range(n_bands)])
        res = rho - radius[band]
        scale = 1.4826 * float(np.median(np.abs(res))) + 1e-4
        w = 1.0 / np.maximum(1.0, np.abs(res) / (2.0 * scale))
        J = -d / rho[:, None]  # d rho / d c
        for k in range(n_bands):  # each band's radius is free: take out its mean direction
            m = band == k
            if m.any():
                J[m] -= np.average(J[m], axis=0, weights=w[m])
        A = (J * w[:, None]).T @ J
        if np.linalg.cond(A) > 1e8:
            break
        step = -np.linalg.solve(A, (J * w[:, None]).T @ res)
        c = c + step
        shift = np.linalg.norm(c - c0)
        if shift > MAX_AXIS_SHIFT_M:
            c = c0 + (c - c0) * (MAX_AXIS_SHIFT_M / shift)
        if np.linalg.norm(step) < 1e-5:
            break
    return c


def side_profile(p_xy_m, points: dict[str, np.ndarray], spec: SceneSpec) -> SideProfile:
    """The profile of the side of an upright can whose top the top view found at `p_xy_m`, from
    the side cameras' world points (`world_points`): about the top's axis or the side's own
    (`refit_axis`), whichever reaches wider (see the module docstring)."""
    near = _around(p_xy_m, points, spec)
    top = _profile(p_xy_m, near, spec, axis="top")
    if not top.seen_bands:
        return top
    side = _profile(refit_axis(p_xy_m, near, spec), near, spec, axis="side")
    return side if side.waist_m > top.waist_m else top


def looks_alike(profile: SideProfile, *, radius_m: float, tolerance_m: float = SIDE_TOLERANCE_M) -> bool:
    """True when the side's narrowest band lies more than `tolerance_m` inside the can's radius
    (False when no band is seen)."""
    return bool(profile.waist_m < radius_m - tolerance_m)
