"""From one top-camera frame to can detections and grasps (the paper's Algorithm 2).

Per separated mask: back-project its (eroded) pixels, estimate normals, keep those that are
nearly vertical and well above the plate. For an upright can they cover its top disc, for a
lying can they form a strip along its highest line. The strip's (or disc's) mean xy is the can's
xy; the height of its top tells lying from upright (known can size); for a lying can, a
total-least-squares line through the strip's xy points (PCA, not a y-on-x regression, which fails
for an axis parallel to y) gives the axis. The grasp itself comes from the shared rule in
`scenes.grasp_rule`.
"""

from __future__ import annotations

import dataclasses
import logging
import math

import cv2
import numpy as np

from perception.crop import crop_rgb, roi_mask, work_volume_corners_W
from perception.geometry import back_project_camera, camera_to_world, project
from perception.normals import estimate_normals
from perception.plane import above_plate_mask
from perception.segment import Components, can_mask, separate
from scenes.grasp_rule import Grasp, make_grasp
from scenes.render import CameraImage
from scenes.spec import SceneSpec

log = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True)
class PerceptionParams:
    """Settings of the pipeline, all relative to the known geometry where possible.

    Attributes:
        erode_px: erosion radius of each mask, pixels (drops silhouette pixels, paper's Fig. 9).
        normal_window_px: side of the plane-fit neighbourhood, pixels (odd).
        min_neighbour_fraction: a normal needs this fraction of its window to be valid points.
        vertical_tilt_deg: a normal within this angle of world +z counts as vertical.
        min_area_fraction: a component smaller than this fraction of the smallest silhouette a
            can may have in the image is a speck, not a can.
        min_vertical_points: fewer vertical normals than this and the component is not a can.
        top_percentile: the can's top height is this percentile of the vertical points' z. The
            paper takes the max, which a noisy depth pushes up by several sigma; the median is
            the top of an upright can's flat disc exactly and lies within 1 mm of a lying can's
            top line (its near-vertical strip drops r (1 - cos 20 deg) = 2 mm at its sides).
        max_overhang_m: a can whose estimated footprint reaches further than this beyond the
            plate's edge is not on the plate (the generator keeps cans 10 mm inside the edge).
        shape_tolerance_m: how far vertical points may reach beyond one can's top (a disc of
            radius r, or a strip of the can's length and diameter) and still be that can's.
        segmentation: "color" (the paper's HSV rule) or "geometric" (colour-free: RANSAC fits
            the plate's plane; what stands `min_height_above_plate_m` above it is can).
        ransac_threshold_m, ransac_iterations, ransac_seed: the plane fit's inlier distance,
            samples, and the seed of its generator (fixed, so that a frame's result is repeatable).
    """

    erode_px: int = 3
    normal_window_px: int = 9
    min_neighbour_fraction: float = 0.5
    vertical_tilt_deg: float = 20.0
    min_area_fraction: float = 0.25
    min_vertical_points: int = 30
    top_percentile: float = 50.0
    max_overhang_m: float = 0.005
    shape_tolerance_m: float = 0.005
    segmentation: str = "color"
    min_height_above_plate_m: float = 0.01
    ransac_threshold_m: float = 0.004
    ransac_iterations: int = 200
    ransac_seed: int = 0


@dataclasses.dataclass(frozen=True)
class CanDetection:
    """One perceived can.

    Attributes:
        id: index of the detection in its frame.
        p_WC_m: estimated centre of the can (middle of its axis) in the world, metres.
        lying: True if the can is judged to lie on its side.
        axis_yaw_rad: direction of a lying can's axis from world +x, in [-pi/2, pi/2) (an axis has
            no sign); 0 for an upright can.
        top_z_m: measured height of the can's highest point, metres.
        grasp: the grasp and pre-grasp the shared rule gives for this estimate.
        n_points: how many vertical-normal points the estimate rests on.
        area_px: the component's area in the image, pixels.
    """

    id: int
    p_WC_m: tuple[float, float, float]
    lying: bool
    axis_yaw_rad: float
    top_z_m: float
    grasp: Grasp
    n_points: int
    area_px: int

    def to_json(self) -> dict:
        return {
            "p_WC_m": [round(float(v), 6) for v in self.p_WC_m],
            "lying": self.lying,
            "axis_yaw_rad": round(float(self.axis_yaw_rad), 6),
            **self.grasp.to_json(),
        }


@dataclasses.dataclass(frozen=True)
class FrameAnalysis:
    """What one frame went through (kept for the debug images).

    Attributes:
        image: the frame.
        roi: (H, W) bool, the work volume's image (calibration crop).
        rgb_cropped: the colour image with everything outside `roi` set to empty space.
        mask: (H, W) bool, can-coloured pixels inside `roi`.
        components: the separated, eroded masks.
        p_W: (N, 3) world points of the pixels that got normals; `labels` (N,) their component,
            `rc` (N, 2) their pixel (row, column).
        n_W: (N, 3) their world-frame normals (facing the camera).
        vertical: (N,) bool, the points Algorithm 2 keeps.
    """

    image: CameraImage
    roi: np.ndarray
    rgb_cropped: np.ndarray
    mask: np.ndarray
    components: Components
    p_W: np.ndarray
    n_W: np.ndarray
    labels: np.ndarray
    vertical: np.ndarray
    rc: np.ndarray


def min_area_px(spec: SceneSpec, image: CameraImage, fraction: float) -> int:
    """`fraction` of the smallest silhouette a can may have in this image (its end disc seen
    from the farthest corner of the work volume), pixels."""
    _, z = project(work_volume_corners_W(spec), K=image.K, X_WC=image.X_WC)
    f = min(image.K[0, 0], image.K[1, 1])
    r_px = f * spec.can.radius_m / float(z.max())
    return max(1, int(fraction * math.pi * r_px * r_px))


def segment_frame(image: CameraImage, spec: SceneSpec, params: PerceptionParams) -> tuple:
    """Crop, colour mask and separate one frame. Returns (roi, rgb_cropped, mask, components)."""
    roi = roi_mask(spec, K=image.K, X_WC=image.X_WC, shape=image.depth_m.shape)
    rgb = crop_rgb(image.rgb, roi)
    if params.segmentation == "color":
        mask = can_mask(rgb, roi)
    elif params.segmentation == "geometric":
        mask, plane = above_plate_mask(
            image, spec, roi,
            min_height_m=params.min_height_above_plate_m,
            threshold_m=params.ransac_threshold_m,
            iterations=params.ransac_iterations,
            rng=np.random.default_rng(params.ransac_seed),
        )
        log.debug("RANSAC plate plane: %s", plane)
    else:
        raise ValueError(f"segmentation must be 'color' or 'geometric', got {params.segmentation!r}")
    comps = separate(mask, min_area_px=min_area_px(spec, image, params.min_area_fraction), erode_px=params.erode_px)
    return roi, rgb, mask, comps


def footprint_overhang_m(spec: SceneSpec, *, xy, lying: bool, axis_yaw_rad: float) -> float:
    """How far (metres) an estimated can's footprint reaches beyond the plate's edge (<= 0: inside)."""
    r, h = spec.can.radius_m, spec.can.height_m
    if lying:
        a = np.array([math.cos(axis_yaw_rad), math.sin(axis_yaw_rad)])
        n = np.array([-a[1], a[0]])
        half = np.abs(a) * h / 2 + np.abs(n) * r  # half extents of the rectangle along x and y
    else:
        half = np.array([r, r])
    cx, cy, _ = spec.plate.center_m
    sx, sy = spec.plate.size_m[:2]
    return float(max(abs(xy[0] - cx) + half[0] - sx / 2, abs(xy[1] - cy) + half[1] - sy / 2))


def axis_yaw_tls(xy: np.ndarray) -> float:
    """Direction of the total-least-squares line through points (N, 2), from +x, in [-pi/2, pi/2).

    The principal axis of the points' covariance: it treats x and y alike, so a line parallel to y
    is as well found as one parallel to x.
    """
    d = xy - xy.mean(axis=0)
    _, vecs = np.linalg.eigh(d.T @ d)
    a = vecs[:, -1]
    yaw = math.atan2(a[1], a[0])
    return (yaw + math.pi / 2) % math.pi - math.pi / 2


def _bbox(mask: np.ndarray, *, pad: int) -> tuple[int, int, int, int]:
    """Rows [r0, r1) and columns [c0, c1) holding all True pixels of `mask`, padded."""
    rows, cols = np.nonzero(mask.any(axis=1))[0], np.nonzero(mask.any(axis=0))[0]
    if rows.size == 0:
        return 0, 0, 0, 0
    h, w = mask.shape
    return max(rows[0] - pad, 0), min(rows[-1] + 1 + pad, h), max(cols[0] - pad, 0), min(cols[-1] + 1 + pad, w)


def analyse_frame(image: CameraImage, spec: SceneSpec, params: PerceptionParams = PerceptionParams()) -> FrameAnalysis:
    """Segment a frame and estimate normals on its cans' pixels."""
    roi, rgb, mask, comps = segment_frame(image, spec, params)
    w = params.normal_window_px
    # Work on the bounding box of the cans' pixels (plus the window) only: it saves most of the time.
    r0, r1, c0, c1 = _bbox(comps.eroded > 0, pad=w // 2 + 1)
    depth = image.depth_m[r0:r1, c0:c1]
    valid = (comps.eroded[r0:r1, c0:c1] > 0) & np.isfinite(depth)
    p_C = back_project_camera(depth, K=image.K, origin_px=(r0, c0))
    (rows, cols), n_C = estimate_normals(
        p_C, valid, window_px=w, min_neighbours=max(3, int(params.min_neighbour_fraction * w * w))
    )
    p_W = camera_to_world(p_C[rows, cols], image.X_WC)
    rows, cols = rows + r0, cols + c0
    n_W = n_C @ image.X_WC[:3, :3].T
    # Algorithm 2's filter: nearly vertical, well above the plate (half the lowest can top), and
    # above the plate's footprint (points off the plate are not on the plate's cans).
    plate = spec.plate
    cx, cy, _ = plate.center_m
    sx, sy = plate.size_m[:2]
    z_min = spec.plate_top_z_m + 0.5 * min(2 * spec.can.radius_m, spec.can.height_m)
    vertical = (
        (n_W[:, 2] >= math.cos(math.radians(params.vertical_tilt_deg)))
        & (p_W[:, 2] >= z_min)
        & (np.abs(p_W[:, 0] - cx) <= sx / 2)
        & (np.abs(p_W[:, 1] - cy) <= sy / 2)
    )
    return FrameAnalysis(
        image, roi, rgb, mask, comps, p_W, n_W, comps.eroded[rows, cols], vertical, np.column_stack([rows, cols])
    )


def detect_cans(
    image: CameraImage, spec: SceneSpec, params: PerceptionParams = PerceptionParams()
) -> tuple[list[CanDetection], FrameAnalysis]:
    """Detect the cans in a top-camera frame and compute their grasps (Algorithm 2).

    Args:
        image: an RGB-D frame looking down on the plate.
        spec: the scene spec (plate, can size, grasp offsets).
        params: pipeline settings.

    Returns:
        The detections (in component order) and the frame's intermediate results.
    """
    fa = analyse_frame(image, spec, params)
    r, h = spec.can.radius_m, spec.can.height_m
    top_plate = spec.plate_top_z_m
    # The top of a lying can is 2r above the plate, of an upright can h: split halfway.
    lying_split_m = (2 * r + h) / 2
    out: list[CanDetection] = []
    for k in range(1, fa.components.count + 1):
        in_comp = np.nonzero(fa.vertical & (fa.labels == k))[0]
        for idx in _single_cans(fa, in_comp, spec=spec, params=params, lying_split_m=lying_split_m):
            n = idx.size
            if n < params.min_vertical_points:
                log.debug("component %d: %d vertical points, not a can", k, n)
                continue
            pts = fa.p_W[idx]
            xy = pts[:, :2].mean(axis=0)
            top_z = float(np.percentile(pts[:, 2], params.top_percentile))
            lying = bool(top_z - top_plate < lying_split_m)
            yaw = axis_yaw_tls(pts[:, :2]) if lying else 0.0
            z = top_plate + (r if lying else h / 2)
            overhang = footprint_overhang_m(spec, xy=xy, lying=lying, axis_yaw_rad=yaw)
            if overhang > params.max_overhang_m:
                # Cans stand wholly on the plate; a footprint beyond its edge is a can partly off
                # the plate (its points beyond the edge were dropped: its estimate would be biased).
                log.info("component %d: footprint %.1f mm beyond the plate edge, not a can on the plate",
                         k, overhang * 1e3)
                continue
            if not _one_can(pts[:, :2], xy=xy, lying=lying, axis_yaw_rad=yaw, spec=spec, params=params):
                # Never a grasp between two cans: a blob that is no single can's top is dropped.
                log.warning("component %d: vertical points do not fit one can's top; no grasp for it", k)
                continue
            det_id = len(out)
            grasp = make_grasp(
                can_id=det_id,
                p_xy_m=xy,
                top_z_m=top_z,
                lying=lying,
                axis_yaw_rad=yaw,
                top_offset_m=spec.grasp.top_offset_m,
                pregrasp_height_m=spec.grasp.pregrasp_height_m,
            )
            out.append(
                CanDetection(
                    id=det_id,
                    p_WC_m=(float(xy[0]), float(xy[1]), float(z)),
                    lying=lying,
                    axis_yaw_rad=float(yaw),
                    top_z_m=top_z,
                    grasp=grasp,
                    n_points=int(n),
                    area_px=fa.components.areas_px[k - 1],
                )
            )
    return out, fa


_CLOSE_KERNEL = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (7, 7))


def _single_cans(
    fa: FrameAnalysis, idx: np.ndarray, *, spec: SceneSpec, params: PerceptionParams, lying_split_m: float
) -> list[np.ndarray]:
    """Split one component's vertical points into groups that each belong to one can.

    With the paper's gap between cans every component is one can and this returns it whole.
    Touching cans merge into one component; their tops still come apart: an upright can's top
    disc and a lying can's top strip lie at different heights; two lying cans' strips are
    separated by the crease where their sides meet (no vertical normals there); two upright
    cans' discs touch at most at a point, so their combined area says how many they are and
    k-means splits them (the discs are convex and disjoint).
    """
    if idx.size == 0:
        return []
    groups = []
    high = fa.p_W[idx, 2] - spec.plate_top_z_m >= lying_split_m
    shape = fa.image.depth_m.shape
    for part, upright in ((idx[high], True), (idx[~high], False)):
        if part.size == 0:
            continue
        img = np.zeros(shape, np.uint8)
        img[fa.rc[part, 0], fa.rc[part, 1]] = 1
        # Closing fills the holes a noisy depth leaves among the vertical normals (it cannot
        # bridge the crease between two lying cans, which is several can radii of pixels wide).
        img = cv2.morphologyEx(img, cv2.MORPH_CLOSE, _CLOSE_KERNEL)
        n, lab = cv2.connectedComponents(img, connectivity=8)
        labels = lab[fa.rc[part, 0], fa.rc[part, 1]]
        for j in range(1, n):
            g = part[labels == j]
            if g.size < params.min_vertical_points:
                continue
            if upright:
                # Each pixel covers (depth / f)^2 of the top face; one eroded disc covers
                # pi (r - erosion)^2.
                f = fa.image.K[0, 0]
                depth_m = float(np.median((fa.p_W[g] - fa.image.X_WC[:3, 3]) @ fa.image.X_WC[:3, 2]))
                area = float(np.count_nonzero(lab == j)) * (depth_m / f) ** 2
                erosion_m = params.erode_px * depth_m / f
                disc = math.pi * max(spec.can.radius_m - erosion_m, 0.5 * spec.can.radius_m) ** 2
                count = max(1, int(round(area / disc)))
                if count > 1:
                    lab_k = _kmeans(fa.p_W[g, :2], count)
                    groups.extend(g[lab_k == c] for c in range(count))
                    continue
            groups.append(g)
    return groups


def _kmeans(xy: np.ndarray, k: int, iterations: int = 20) -> np.ndarray:
    """Labels (N,) of k-means on points (N, 2), started deterministically from farthest points."""
    centres = [xy[np.argmax(np.linalg.norm(xy - xy.mean(axis=0), axis=1))]]
    while len(centres) < k:
        d = np.min(np.linalg.norm(xy[:, None, :] - np.array(centres)[None], axis=-1), axis=1)
        centres.append(xy[np.argmax(d)])
    c = np.array(centres)
    for _ in range(iterations):
        lab = np.argmin(np.linalg.norm(xy[:, None, :] - c[None], axis=-1), axis=1)
        new = np.array([xy[lab == j].mean(axis=0) if np.any(lab == j) else c[j] for j in range(k)])
        if np.allclose(new, c):
            break
        c = new
    return lab


def _one_can(xy_pts: np.ndarray, *, xy, lying: bool, axis_yaw_rad: float, spec: SceneSpec,
             params: PerceptionParams) -> bool:
    """Whether vertical points (N, 2) fit on one can's top: a disc of radius r (upright), or a
    strip no longer than the can and no wider than its diameter (lying)."""
    tol = params.shape_tolerance_m
    d = xy_pts - np.asarray(xy)
    if not lying:
        return float(np.max(np.linalg.norm(d, axis=1))) <= spec.can.radius_m + tol
    a = np.array([math.cos(axis_yaw_rad), math.sin(axis_yaw_rad)])
    along = d @ a
    across = d @ np.array([-a[1], a[0]])
    return (float(np.ptp(along)) <= spec.can.height_m + tol) and (float(np.ptp(across)) <= 2 * spec.can.radius_m + tol)
