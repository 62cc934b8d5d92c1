"""The can model (a cylinder of known radius r and height h) as a test on what the camera sees.

Algorithm 2 finds flat tops: groups of vertical-normal points. Only a can's top is a can's top:
- its height above the plate is 2r (lying) or h (upright), within a tolerance. A bottle's top is
  far higher, a cup's lies between the two, a box's wherever its height puts it;
- an upright can's flat top is a disc of radius r: its pixels at the top's height (the part
  nearer this candidate than any other) cover the disc's area, and their outline lies on a circle
  of radius r about their centroid. A box as tall as a can has a rectangular top: a rectangle
  within the disc covers at most 2/pi of it, and a rectangle's outline follows a circle of
  radius r over a small part of it only;
- a lying can's top is a strip about as long as the can and no wider than its diameter.
Nothing here depends on colour, so the colour-free segmentation tells distractors from cans by it.
Tops that fail the disc test get a second look in `perception.can_discs`.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

from perception.geometry import back_project_camera, camera_to_world, project
from scenes.render import CameraImage
from scenes.spec import SceneSpec

_OPEN_KERNEL = np.ones((3, 3), np.uint8)
_CROSS_KERNEL = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))


def top_bands_m(spec: SceneSpec) -> tuple[tuple[float, float], tuple[float, float]]:
    """Heights above the plate (metres) of the points that may belong to a lying can's top and to
    an upright can's top: each band reaches halfway to the other top, and as far on its other side."""
    lying_top, upright_top = 2 * spec.can.radius_m, spec.can.height_m
    half = abs(upright_top - lying_top) / 2
    return (lying_top - half, lying_top + half), (upright_top - half, upright_top + half)


def top_height_fits(top_above_plate_m: float, *, lying: bool, spec: SceneSpec, tolerance_m: float) -> bool:
    """Whether a flat top's height above the plate is a lying (2r) or an upright (h) can's top."""
    expected = 2 * spec.can.radius_m if lying else spec.can.height_m
    return abs(top_above_plate_m - expected) <= tolerance_m


def lying_strip_fits(xy_pts: np.ndarray, *, xy, axis_yaw_rad: float, spec: SceneSpec, tolerance_m: float,
                     min_length_fraction: float) -> bool:
    """Whether vertical points (N, 2) fit on a lying can's top: a strip no longer than the can
    and no wider than its diameter (about `xy`, along `axis_yaw_rad`), and at least
    `min_length_fraction` of the can's length long (a piece of a strip, broken by depth noise or
    partly hidden, does not give the can's middle)."""
    d = xy_pts - np.asarray(xy)
    a = np.array([math.cos(axis_yaw_rad), math.sin(axis_yaw_rad)])
    length = float(np.ptp(d @ a))
    across = d @ np.array([-a[1], a[0]])
    return (min_length_fraction * spec.can.height_m <= length <= spec.can.height_m + tolerance_m
            and float(np.ptp(across)) <= 2 * spec.can.radius_m + tolerance_m)


def disc_core_fits(xy_pts: np.ndarray, *, xy, spec: SceneSpec, tolerance_m: float) -> bool:
    """Whether vertical points (N, 2) lie within a can's radius (plus `tolerance_m`) of `xy`."""
    return float(np.max(np.linalg.norm(xy_pts - np.asarray(xy), axis=1))) <= spec.can.radius_m + tolerance_m


@dataclasses.dataclass(frozen=True)
class FlatTop:
    """The flat top around one upright candidate, measured on the depth image.

    Attributes:
        area_m2: area of its pixels at the top's height (horizontal area, square metres).
        center_xy_m: the centroid (x, y) of those pixels, metres.
        reach_m: the farthest of those pixels from their centroid, in xy, metres.
        rim_fraction: the fraction of its outline pixels that lie on the can's rim: within
            `rim_tolerance_px` pixels of the can's radius from the centroid.
    """

    area_m2: float
    center_xy_m: tuple[float, float]
    reach_m: float
    rim_fraction: float


@dataclasses.dataclass(frozen=True)
class TopWindow:
    """A window of the depth image around a candidate top, in world coordinates.

    Attributes:
        origin_px: (row, column) of the window's top-left pixel in the image.
        p_C: (h, w, 3) camera-frame points (NaN where no depth), metres; `p_W` the same in the world.
        top: (h, w) bool, points of the candidate's component at the top's height (within the
            tolerance); `above`: points higher than that (whatever is there hides the top).
        pixel_m: the size of one pixel at the top's depth, metres.
    """

    origin_px: tuple[int, int]
    p_C: np.ndarray
    p_W: np.ndarray
    top: np.ndarray
    above: np.ndarray
    pixel_m: float

    def classify(self, p_W: np.ndarray, image: CameraImage) -> tuple[np.ndarray, np.ndarray]:
        """Whether the pixels that world points (N, 3) project to are top, and are above (outside
        the window: neither)."""
        uv, _ = project(p_W, K=image.K, X_WC=image.X_WC)
        rows = np.round(uv[:, 1]).astype(int) - self.origin_px[0]
        cols = np.round(uv[:, 0]).astype(int) - self.origin_px[1]
        h, w = self.top.shape
        inside = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
        top, above = np.zeros(len(p_W), bool), np.zeros(len(p_W), bool)
        top[inside] = self.top[rows[inside], cols[inside]]
        above[inside] = self.above[rows[inside], cols[inside]]
        return top, above


def top_window(
    image: CameraImage, labels: np.ndarray, label: int, *, rows: tuple[int, int], cols: tuple[int, int],
    top_z_m: float, tolerance_m: float,
) -> TopWindow:
    """The window rows [r0, r1) x columns [c0, c1) (clipped to the image) around a top at height
    `top_z_m`, of the candidate's component `label` in `labels` (H, W) (before erosion)."""
    h, w = labels.shape
    r0, r1 = max(rows[0], 0), min(rows[1], h)
    c0, c1 = max(cols[0], 0), min(cols[1], w)
    # A 5x5 median keeps the top's outline but drops the sensor's speckle (and dropped pixels), which
    # would otherwise scatter specks of the can's side into the top's height band.
    depth = image.depth_m[r0:r1, c0:c1].astype(np.float32)
    depth = cv2.medianBlur(np.where(np.isfinite(depth), depth, np.float32(0.0)), 5)
    depth[depth <= 0] = np.nan
    p_C = back_project_camera(depth, K=image.K, origin_px=(r0, c0))
    p_W = camera_to_world(p_C, image.X_WC)
    with np.errstate(invalid="ignore"):
        top = (labels[r0:r1, c0:c1] == label) & (np.abs(p_W[..., 2] - top_z_m) <= tolerance_m)
        above = p_W[..., 2] > top_z_m + tolerance_m
    d = float(np.nanmedian(depth[top])) if top.any() else float(np.nanmedian(depth))
    return TopWindow((r0, c0), p_C, p_W, top, above, d / float(min(image.K[0, 0], image.K[1, 1])))


def pixel_area_m2(p_C: np.ndarray, image: CameraImage) -> np.ndarray:
    """Horizontal area (square metres) each pixel of camera-frame points (N, 3) covers on a
    horizontal surface: (d/fx)(d/fy) across its ray at depth d, grown by cos(ray, optical axis) /
    cos(ray, vertical)."""
    ray = p_C / np.linalg.norm(p_C, axis=1, keepdims=True)
    up_C = image.X_WC[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    return p_C[:, 2] ** 2 / (image.K[0, 0] * image.K[1, 1]) * ray[:, 2] / np.abs(ray @ up_C)


def flat_top(
    image: CameraImage,
    labels: np.ndarray,
    label: int,
    *,
    core_rc: np.ndarray,
    p_WC_xy: np.ndarray,
    top_z_m: float,
    others_xy: np.ndarray,
    spec: SceneSpec,
    tolerance_m: float,
    rim_tolerance_px: float,
) -> FlatTop:
    """Measure the flat top of an upright candidate: the pixels of its component whose point lies
    within `tolerance_m` of the top's height, nearer its centre than any other upright
    candidate's (touching cans share a plateau; the tangent line between equal discs splits it),
    connected to its vertical-normal core, without one-pixel-wide lines (a tall neighbour's side
    crossing the top's height).

    Args:
        image: the frame.
        labels, label: the components (H, W) (before erosion) and the candidate's.
        core_rc: (N, 2) pixels (row, column) of the candidate's vertical-normal points.
        p_WC_xy: the candidate's centre (x, y), metres.
        top_z_m: the height of its top (world z), metres.
        others_xy: (M, 2) the other upright candidates' centres of the frame, metres.
        spec: the scene spec (the can's radius).
        tolerance_m: how far from `top_z_m` a point of the top may be.
        rim_tolerance_px: how far (pixels) from the can's radius an outline pixel may lie and
            still be on the rim.
    """
    r = spec.can.radius_m
    uv, depth = project(np.array([[p_WC_xy[0], p_WC_xy[1], top_z_m]]), K=image.K, X_WC=image.X_WC)
    # a margin beyond the rim: a top reaching past it (a box's corner) must show
    half = int(math.ceil(1.25 * float(min(image.K[0, 0], image.K[1, 1])) * r / float(depth[0]))) + 2
    u, v = int(round(uv[0, 0])), int(round(uv[0, 1]))
    win = top_window(image, labels, label, rows=(v - half, v + half + 1), cols=(u - half, u + half + 1),
                     top_z_m=top_z_m, tolerance_m=tolerance_m)
    r0, c0 = win.origin_px
    x, y = win.p_W[..., 0], win.p_W[..., 1]
    cell = win.top.copy()
    dist = np.hypot(x - p_WC_xy[0], y - p_WC_xy[1])
    for q in others_xy:
        with np.errstate(invalid="ignore"):
            cell &= dist <= np.hypot(x - q[0], y - q[1])
    cell = cv2.morphologyEx(cell.astype(np.uint8), cv2.MORPH_OPEN, _OPEN_KERNEL)
    n, lab = cv2.connectedComponents(cell, connectivity=8)
    rows, cols = core_rc[:, 0] - r0, core_rc[:, 1] - c0
    inside = (rows >= 0) & (rows < cell.shape[0]) & (cols >= 0) & (cols < cell.shape[1])
    keep = np.zeros(n, bool)
    keep[lab[rows[inside], cols[inside]]] = True
    keep[0] = False
    top = keep[lab]
    if not top.any():
        return FlatTop(0.0, (float(p_WC_xy[0]), float(p_WC_xy[1])), 0.0, 0.0)
    px_area = pixel_area_m2(win.p_C[top], image)
    # The centroid, not the candidate's centre: the vertical-normal core's mean moves by millimetres
    # under depth noise, the outline of the whole top does not.
    c = np.array([x[top] @ px_area, y[top] @ px_area]) / px_area.sum()
    radius = np.hypot(x - c[0], y - c[1])
    outline = top & ~cv2.erode(top.astype(np.uint8), _CROSS_KERNEL).astype(bool)
    on_rim = np.abs(radius[outline] - r) <= rim_tolerance_px * win.pixel_m
    return FlatTop(float(px_area.sum()), (float(c[0]), float(c[1])), float(radius[top].max()), float(on_rim.mean()))


def upright_top_fits(top: FlatTop, *, spec: SceneSpec, min_area_fraction: float, min_rim_fraction: float) -> bool:
    """Whether a measured flat top is an upright can's: it covers at least `min_area_fraction` of
    the disc of radius r, and at least `min_rim_fraction` of its outline is the disc's rim."""
    r = spec.can.radius_m
    return top.area_m2 >= min_area_fraction * math.pi * r * r and top.rim_fraction >= min_rim_fraction
