"""From one top-camera frame to can detections and grasps (the paper's Algorithm 2).

Per separated mask: back-project its (eroded) pixels, estimate normals, keep those that are
nearly vertical and well above the plate. For an upright can they cover its top disc, for a
lying can they form a strip along its highest line. The strip's (or disc's) mean xy is the can's
xy; the height of its top tells lying from upright (known can size); for a lying can, a
total-least-squares line through the strip's xy points (PCA, not a y-on-x regression, which fails
for an axis parallel to y) gives the axis. The grasp itself comes from the shared rule in
`scenes.grasp_rule`.

Every top is checked against the can model (`perception.can_model`): its height above the plate
(2r or h), an upright top's disc shape, a lying top's strip. Among distractors (bottles, cups,
boxes) that tells them from cans without colour. An upright top that is no single can's disc
(merged with a touching top at the same height, partly hidden) gets a second look for can discs of
the known radius (`perception.can_discs`).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from typing import NamedTuple

import numpy as np

from perception.can_discs import find_can_discs
from perception.can_model import (
    disc_core_fits,
    flat_top,
    lying_strip_fits,
    top_height_fits,
    upright_top_fits,
)
from perception.crop import crop_rgb, roi_mask, work_volume_corners_W
from perception.geometry import axis_yaw_tls, back_project_camera, camera_to_world, project
from perception.normals import estimate_normals
from perception.plane import above_plate_mask
from perception.segment import Components, can_mask, separate
from perception.touching import single_cans
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
        top_height_tolerance_m: a flat top farther than this from a can's top height (2r lying,
            h upright) above the plate is no can's (a cup's, a bottle's, a box's).
        flat_top_tolerance_m: how far from an upright top's height its flat top's points may lie.
        min_top_area_fraction: an upright top's flat top covers at least this fraction of the
            can's disc (a rectangle inside the disc covers at most 2/pi of it).
        rim_tolerance_px, min_rim_fraction: at least this fraction of an upright top's outline
            lies within this many pixels of the can's radius from its centre (a circle of the
            can's size: a rectangle's outline is not, nor a cup's wider rim). The same fraction of
            the ring just inside a disc that `perception.can_discs` proposes must be on the top.
        min_disc_rim_fraction: a proposed disc's top must end at its rim along this fraction of
            the rim open to view (a rectangle's edges follow a circle over at most about 45% of
            it; a touching box takes about 10% from a can's).
        min_seen_rim_fraction: a proposed disc's rim must be seen (not hidden by something higher)
            along at least this fraction of it.
        min_strip_length_fraction: a lying can's strip of vertical normals spans at least this
            fraction of the can's length (its rounded ends lose a few millimetres); a shorter
            piece (broken by depth noise, partly hidden) would put the grasp off the can's middle.
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
    top_height_tolerance_m: float = 0.01
    flat_top_tolerance_m: float = 0.005
    min_top_area_fraction: float = 0.85
    rim_tolerance_px: float = 2.0
    min_rim_fraction: float = 0.85
    min_disc_rim_fraction: float = 0.75
    min_seen_rim_fraction: float = 0.5
    min_strip_length_fraction: float = 0.75


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
        confidence: the robust pipeline's support for the estimate in [0, 1] (the fraction of an
            upright can's rim its circle fit covers, or of a lying can's length its upper half
            spans); 1.0 from the paper's pipeline, which has no such measure.
    """

    id: int
    p_WC_m: tuple[float, float, float]
    lying: bool
    axis_yaw_rad: float
    top_z_m: float
    grasp: Grasp
    n_points: int
    area_px: int
    confidence: float = 1.0

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


class _Top(NamedTuple):
    """A group of vertical-normal points that may be one can's top."""

    component: int
    points: np.ndarray  # indices into the frame's points
    upright: bool  # at an upright can's height
    xy: np.ndarray
    top_z: float


class _Found(NamedTuple):
    """A can's top that passed the can model."""

    component: int
    xy: np.ndarray
    top_z: float
    lying: bool
    yaw: float
    n_points: int


def detect_cans(
    image: CameraImage, spec: SceneSpec, params: PerceptionParams = PerceptionParams()
) -> tuple[list[CanDetection], FrameAnalysis]:
    """Detect the cans in a top-camera frame and compute their grasps (Algorithm 2).

    Every flat top found is checked against the can model (`perception.can_model`): its height,
    and its shape (an upright can's disc, a lying can's strip). What does not fit is no can and
    gets no grasp: a distractor, or touching objects that could not be told apart.

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
    candidates: list[_Top] = []
    for k in range(1, fa.components.count + 1):
        in_comp = np.nonzero(fa.vertical & (fa.labels == k))[0]
        for idx, upright in single_cans(fa, in_comp, spec=spec, params=params):
            if idx.size < params.min_vertical_points:
                log.debug("component %d: %d vertical points, not a can", k, idx.size)
                continue
            pts = fa.p_W[idx]
            top_z = float(np.percentile(pts[:, 2], params.top_percentile))
            candidates.append(_Top(k, idx, upright, pts[:, :2].mean(axis=0), top_z))
    upright_xy = np.array([c.xy for c in candidates if c.upright]).reshape(-1, 2)
    found: list[_Found] = []
    second_look: list[_Top] = []  # upright groups that are no single can's top
    for k, idx, upright, xy, top_z in candidates:
        pts = fa.p_W[idx]
        lying = not upright
        if not top_height_fits(top_z - top_plate, lying=lying, spec=spec, tolerance_m=params.top_height_tolerance_m):
            log.info("component %d: a flat top %.0f mm above the plate is no can's top; no grasp for it",
                     k, (top_z - top_plate) * 1e3)
            continue
        yaw = axis_yaw_tls(pts[:, :2]) if lying else 0.0
        if not _on_plate(spec, params, k=k, xy=xy, lying=lying, yaw=yaw):
            continue
        if lying:
            if not lying_strip_fits(pts[:, :2], xy=xy, axis_yaw_rad=yaw, spec=spec,
                                    tolerance_m=params.shape_tolerance_m,
                                    min_length_fraction=params.min_strip_length_fraction):
                # Never a grasp between two cans: a blob that is no single can's top is dropped.
                log.warning("component %d: vertical points do not fit one can's top; no grasp for it", k)
                continue
        elif not _single_upright_top(fa, idx, k=k, xy=xy, top_z=top_z, upright_xy=upright_xy, spec=spec, params=params):
            second_look.append(_Top(k, idx, True, xy, top_z))
            continue
        found.append(_Found(k, xy, top_z, lying, yaw, idx.size))
    # Upright groups that are no single can's top (merged with a touching top at the same height,
    # partly hidden): look for can discs in them, away from the cans found so far.
    for k, idx, _, _, top_z in second_look:
        taken = np.array([f.xy for f in found if not f.lying]).reshape(-1, 2)
        discs = find_can_discs(image, fa.components.labels, k, core_rc=fa.rc[idx], top_z_m=top_z, taken_xy=taken,
                               spec=spec, tolerance_m=params.flat_top_tolerance_m,
                               rim_tolerance_px=params.rim_tolerance_px, min_inner_fraction=params.min_rim_fraction,
                               min_rim_fraction=params.min_disc_rim_fraction,
                               min_seen_fraction=params.min_seen_rim_fraction)
        if not discs:
            # Never a grasp between two cans or on a distractor: a top that is no can's is dropped.
            log.info("component %d: no can's top disc in a flat top at a can's height; no grasp for it", k)
        for xy, n in discs:
            if _on_plate(spec, params, k=k, xy=xy, lying=False, yaw=0.0):
                found.append(_Found(k, xy, top_z, False, 0.0, n))
    out: list[CanDetection] = []
    for k, xy, top_z, lying, yaw, n in found:
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
                p_WC_m=(float(xy[0]), float(xy[1]), float(top_plate + (r if lying else h / 2))),
                lying=lying,
                axis_yaw_rad=float(yaw),
                top_z_m=top_z,
                grasp=grasp,
                n_points=int(n),
                area_px=fa.components.areas_px[k - 1],
            )
        )
    return out, fa


def _single_upright_top(fa: FrameAnalysis, idx: np.ndarray, *, k: int, xy: np.ndarray, top_z: float,
                        upright_xy: np.ndarray, spec: SceneSpec, params: PerceptionParams) -> bool:
    """Whether an upright group's vertical points and flat top are one can's top disc (see
    `perception.can_model`); `upright_xy` (M, 2) holds every upright group's centre in the frame."""
    r = spec.can.radius_m
    if not disc_core_fits(fa.p_W[idx, :2], xy=xy, spec=spec, tolerance_m=params.shape_tolerance_m):
        return False
    near = np.linalg.norm(upright_xy - xy, axis=1)
    others = upright_xy[(near > 0) & (near < 4 * r)]  # farther ones claim no pixel of this top
    top = flat_top(fa.image, fa.components.labels, k, core_rc=fa.rc[idx], p_WC_xy=xy, top_z_m=top_z,
                   others_xy=others, spec=spec, tolerance_m=params.flat_top_tolerance_m,
                   rim_tolerance_px=params.rim_tolerance_px)
    if upright_top_fits(top, spec=spec, min_area_fraction=params.min_top_area_fraction,
                        min_rim_fraction=params.min_rim_fraction):
        return True
    log.info("component %d: a flat top covering %.0f%% of a can's disc, %.0f%% of its outline on a can's rim, "
             "is no single can's top", k, 100 * top.area_m2 / (math.pi * r * r), 100 * top.rim_fraction)
    return False


def _on_plate(spec: SceneSpec, params: PerceptionParams, *, k: int, xy, lying: bool, yaw: float) -> bool:
    """Whether an estimated can's footprint stays on the plate (within `params.max_overhang_m`)."""
    overhang = footprint_overhang_m(spec, xy=xy, lying=lying, axis_yaw_rad=yaw)
    if overhang > params.max_overhang_m:
        # Cans stand wholly on the plate; a footprint beyond its edge is a can partly off
        # the plate (its points beyond the edge were dropped: its estimate would be biased).
        log.info("component %d: footprint %.1f mm beyond the plate edge, not a can on the plate", k, overhang * 1e3)
        return False
    return True
