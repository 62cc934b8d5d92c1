"""The robust pipeline (`perceive --pipeline robust`): the paper's steps on a depth image denoised
by an amount measured on the plate, each can's pose re-fitted robustly, and a confidence that
refuses what the fits do not support.

1. Noise: the RMS of the plate's depths about a plane fitted to them (`plate_noise_m`; it holds for
   quantized and correlated noise). A frame noisier than `max_noise_m` gets no grasps at all
   (refused, and logged as such): beyond it the fits were not measured to hold.
2. Edge-preserving smoothing: a bilateral filter whose range sigma is `range_sigmas` times the
   measured noise (a can's top and the plate 10 cm below it do not mix; the top's noise averages
   out over about a hundred pixels), after dropped pixels amid valid ones are filled with their
   neighbourhood's median.
3. The paper's pipeline (geometric segmentation, normals, Algorithm 2, the can model's checks) on
   the smoothed frame.
4. Re-fits, each with a confidence:
   - upright: a circle of the can's radius fitted by RANSAC to the outline of its flat top; the
     centre is the can's; the confidence is the fraction of the rim's 5-degree sectors holding an inlier;
   - lying: the can's upper half (points higher than r above the plate, within r of the axis, on
     its cylinder's surface and in one unbroken run along the axis, so a neighbour off its end is out):
     the middle of its extent along the axis is the can's centre (its ends are the can's ends;
     the strip of vertical normals is not evenly filled), its principal axis the can's axis when
     the noise exceeds `strip_yaw_noise_m` (the strip's line is the better one on clean depth);
     the confidence is the extent's length over the can's.
   A detection below `min_confidence` is refused (logged), never grasped.
5. Given the side cameras' frames, an upright detection whose side they see narrower than a
   can's all round at some height (`perception.side_view`: the seed paper's hourglass) is
   refused as a look-alike. Without them the step is skipped, and logged once per process;
   `robust-top` (`side_check` off, the top camera alone) skips it by design.
"""

from __future__ import annotations

import dataclasses
import logging
import math

import cv2
import numpy as np

from perception.can_model import top_window
from perception.crop import plate_outline_px
from perception.geometry import axis_yaw_tls, back_project_camera, camera_to_world, project
from perception.grasps import CanDetection, FrameAnalysis, PerceptionParams, detect_cans
from perception.plane import ransac_plane
from perception.side_view import SIDE_TOLERANCE_M, looks_alike, side_profile, world_points
from scenes.grasp_rule import make_grasp
from scenes.render import CameraImage
from scenes.spec import SceneSpec

log = logging.getLogger(__name__)

_CROSS = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
#: angular sectors of an upright can's rim in its confidence (5 degrees each)
RIM_SECTORS = 72
#: the plate's noise (`plate_noise_m`): pixels this far inside the plate top's outline; the first inlier
#: band about its known plane (metres: every object on the plate stands higher); the band about the
#: fitted plane, in RMS residuals, and at least this many metres; fit rounds; fewest pixels
PLATE_MARGIN_PX = 4
PLATE_BAND_M = 0.025
PLATE_BAND_SIGMAS = 4.0
PLATE_MIN_BAND_M = 0.001
PLATE_FIT_ROUNDS = 10
PLATE_MIN_PIXELS = 500
#: a lying can's upper-half points lie at least this close to its cylinder (a rendered can's facets)
LYING_SURFACE_TOL_M = 0.002
#: bins along a lying can's axis (a neighbour off its end is left out past one empty bin), and the
#: fraction of the middle's typical count that fills a bin
LYING_RUN_BIN_M = 0.002
LYING_RUN_MIN_FRACTION = 0.2


#: the messages `_log_once` has logged in this process
_LOGGED: set[str] = set()


def _log_once(key: str, message: str) -> None:
    """Log `message` (a warning) the first time `key` is seen in this process."""
    if key not in _LOGGED:
        _LOGGED.add(key)
        log.warning(message)


@dataclasses.dataclass(frozen=True)
class RobustParams:
    """Settings of the robust pipeline (chosen on `clutter` seeds 9300-9309; see docs/perception.md).

    Attributes:
        base: the paper's pipeline settings it runs with (geometric segmentation by default).
        bilateral_px, bilateral_sigma_space_px, bilateral_range_sigmas: the bilateral filter's
            diameter and spatial sigma (pixels), and its range sigma in measured noise sigmas.
        min_noise_m: the range sigma never assumes less noise than this (a clean render).
        max_noise_m: a frame whose plate noise is above this gets no grasps (refused).
        strip_yaw_noise_m: above this noise a lying can's axis comes from its upper half.
        min_upright_confidence: an upright can's fitted rim must cover this fraction of its circle.
        min_lying_confidence: a lying can's upper half must span this fraction of its length.
        side_check: refuse an upright detection whose side the side cameras see narrower than a
            can's (only when their frames are given; without them it is off, logged once per
            process). False: the top camera alone (`perception.pipeline`'s `robust-top`).
        fill_dropouts: a pixel without depth whose 5x5 neighbourhood mostly has depth takes its
            median before smoothing (`denoise_depth`): a structured-light sensor's dropouts beside
            depth edges otherwise leave a can top's outline ragged beyond the can model's rim
            tolerance (on the tuning seeds under kinect-v1, 3-4% of the cans were lost so).
    """

    base: PerceptionParams = PerceptionParams(segmentation="geometric")
    bilateral_px: int = 9
    bilateral_sigma_space_px: float = 3.0
    bilateral_range_sigmas: float = 3.0
    min_noise_m: float = 0.0005
    max_noise_m: float = 0.010
    strip_yaw_noise_m: float = 0.002
    min_upright_confidence: float = 0.5
    min_lying_confidence: float = 0.8
    side_check: bool = True
    fill_dropouts: bool = True


def plate_pixels(image: CameraImage, spec: SceneSpec, *,
                 margin_px: int = PLATE_MARGIN_PX) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pixels (rows, cols) inside the plate top's outline, `margin_px` in from it, and the depth
    (metres, along the optical axis) the plate's known plane has at each (the plate is a fixture of
    the cell, calibrated like the camera; nothing on it is assumed)."""
    h, w = image.depth_m.shape
    mask = np.zeros((h, w), np.uint8)
    cv2.fillConvexPoly(mask, np.round(plate_outline_px(spec, K=image.K, X_WC=image.X_WC)).astype(np.int32), 1)
    if margin_px > 0:
        mask = cv2.erode(mask, np.ones((2 * margin_px + 1, 2 * margin_px + 1), np.uint8))
    rows, cols = np.nonzero(mask)
    R, t = image.X_WC[:3, :3], image.X_WC[:3, 3]
    # the plane z_W = plate top in the camera frame: n_C . p_C = d_C; a pixel's ray q = (x, y, 1)
    # meets it at depth d_C / (n_C . q)
    n_C, d_C = R.T @ np.array([0.0, 0.0, 1.0]), spec.plate_top_z_m - t[2]
    q = np.column_stack([(cols - image.K[0, 2]) / image.K[0, 0], (rows - image.K[1, 2]) / image.K[1, 1],
                         np.ones(rows.size)])
    with np.errstate(divide="ignore"):
        return rows, cols, d_C / (q @ n_C)


def plate_noise_m(image: CameraImage, spec: SceneSpec, *, rng: np.random.Generator | None = None) -> float:
    """The depth noise's standard deviation (metres) measured on the plate: the RMS of the plate's
    depths about a plane fitted to them.

    The plate's pixels (`plate_pixels`) within `PLATE_BAND_M` of its known plane (every object on
    it stands higher) seed the fit; the plane (linear in inverse depth over the pixel grid, as a
    plane seen by a pinhole camera is) is then fitted by least squares to the pixels within
    `PLATE_BAND_SIGMAS` of the RMS residual of the last fit, until the set stops changing (a
    trimmed fit: an object's foot or a noise outlier does not pull it). The residual is in depth,
    so the figure is the RMS of measured less true depth over the plate, which is how the true
    sigma is defined. Unlike a spread of neighbouring pixels' differences it survives a
    quantized sensor (most neighbours of a structured-light depth image differ by exactly 0) and
    correlated noise (neighbours share their error). NaN with fewer than `PLATE_MIN_PIXELS`
    pixels. `rng` is unused (kept for a sampled variant)."""
    rows, cols, z_plane = plate_pixels(image, spec)
    z = image.depth_m[rows, cols].astype(np.float64)
    ok = np.isfinite(z) & (z > 0) & np.isfinite(z_plane)
    z = np.where(ok, z, np.nan)
    with np.errstate(invalid="ignore"):
        inl = ok & (np.abs(z - z_plane) < PLATE_BAND_M)
    if inl.sum() < PLATE_MIN_PIXELS:
        return float("nan")
    A = np.column_stack([(cols - image.K[0, 2]) / image.K[0, 0], (rows - image.K[1, 2]) / image.K[1, 1],
                         np.ones(rows.size)])
    band, sigma = PLATE_BAND_M, float("nan")
    for _ in range(PLATE_FIT_ROUNDS):
        coef, *_ = np.linalg.lstsq(A[inl], 1.0 / z[inl], rcond=None)
        with np.errstate(invalid="ignore", divide="ignore"):
            resid = z - 1.0 / (A @ coef)
        sigma = untruncated_sigma(float(np.sqrt(np.mean(resid[inl] ** 2))), band_m=band)
        band = min(max(PLATE_BAND_SIGMAS * sigma, PLATE_MIN_BAND_M), PLATE_BAND_M)
        with np.errstate(invalid="ignore"):
            nxt = ok & (np.abs(resid) < band)
        if nxt.sum() < PLATE_MIN_PIXELS or np.array_equal(nxt, inl):
            break
        inl = nxt
    return sigma


def untruncated_sigma(rms_m: float, *, band_m: float) -> float:
    """The sigma of a zero-mean Gaussian whose samples within +-`band_m` have the RMS `rms_m` (the
    band cuts the tails: at 4 sigmas the RMS is 0.9993 sigma, at 2.5 sigmas 0.955). Infinite when
    the samples fill the band as evenly as a uniform distribution or more."""
    if not rms_m > 0:
        return rms_m
    if rms_m >= band_m / math.sqrt(3.0):
        return float("inf")
    sigma = rms_m
    for _ in range(50):
        k = band_m / sigma
        phi = math.exp(-0.5 * k * k) / math.sqrt(2.0 * math.pi)
        ratio = math.sqrt(max(1.0 - 2.0 * k * phi / math.erf(k / math.sqrt(2.0)), 1e-12))
        nxt = rms_m / ratio
        if abs(nxt - sigma) < 1e-9 * nxt:
            return nxt
        sigma = nxt
    return sigma


def denoise_depth(depth_m: np.ndarray, *, sigma_m: float, d_px: int, sigma_space_px: float, range_sigmas: float,
                  fill_dropouts: bool = True) -> np.ndarray:
    """Edge-preserving smoothing (bilateral) of a depth image. A pixel without depth stays NaN,
    unless `fill_dropouts` and most of its 5x5 neighbourhood has depth: it then takes their median
    (one surface's depth, never a mix of two across an edge)."""
    valid = np.isfinite(depth_m)
    d = np.where(valid, depth_m, 0.0).astype(np.float32)
    fill = cv2.medianBlur(d, 5)
    d = np.where(valid, d, fill)
    out = cv2.bilateralFilter(d, d_px, range_sigmas * sigma_m, sigma_space_px)
    out[~valid & ~(fill > 0 if fill_dropouts else False)] = np.nan
    return out


def circle_ransac(xy: np.ndarray, *, radius_m: float, near_xy, max_shift_m: float, tol_m: float,
                  rng: np.random.Generator, samples: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """RANSAC of a circle of known radius through points (N, 2): two points give two centres;
    candidates farther than `max_shift_m` from `near_xy` are dropped. Returns the centre refined by
    least squares on its inliers (within `tol_m` of the circle) and the inlier mask."""
    near = np.asarray(near_xy, float)
    n = len(xy)
    if n < 3:
        return near, np.zeros(n, bool)
    i = rng.integers(0, n, size=(samples, 2))
    a, b = xy[i[:, 0]], xy[i[:, 1]]
    mid, half = (a + b) / 2, (b - a) / 2
    L = np.linalg.norm(half, axis=1)
    ok = (L > 1e-4) & (L < radius_m)
    mid, half, L = mid[ok], half[ok], L[ok]
    perp = np.column_stack([-half[:, 1], half[:, 0]]) / L[:, None]
    t = np.sqrt(radius_m ** 2 - L ** 2)[:, None]
    cands = np.vstack([mid + t * perp, mid - t * perp, near[None]])
    cands = cands[np.linalg.norm(cands - near, axis=1) <= max_shift_m]
    resid = np.abs(np.linalg.norm(xy[None] - cands[:, None], axis=-1) - radius_m)
    best = cands[int(np.argmax((resid < tol_m).sum(axis=1)))]
    c = best
    for _ in range(5):  # Gauss-Newton on the inliers
        d = xy - c
        rho = np.linalg.norm(d, axis=1)
        inl = np.abs(rho - radius_m) < tol_m
        if inl.sum() < 3:
            break
        J = -d[inl] / rho[inl, None]
        step, *_ = np.linalg.lstsq(J, -(rho[inl] - radius_m), rcond=None)
        c = c + step
        if np.linalg.norm(step) < 1e-5:
            break
    inl = np.abs(np.linalg.norm(xy - c, axis=1) - radius_m) < tol_m
    return c, inl


def rim_coverage(d_xy: np.ndarray, *, sectors: int = RIM_SECTORS) -> float:
    """The fraction of `sectors` equal angular sectors about a centre that hold at least one of the
    points (N, 2) given relative to it (a ragged or partly dropped outline still covers its sector)."""
    if len(d_xy) == 0:
        return 0.0
    k = np.floor(np.mod(np.arctan2(d_xy[:, 1], d_xy[:, 0]), 2 * math.pi) / (2 * math.pi) * sectors).astype(int)
    return float(np.unique(np.clip(k, 0, sectors - 1)).size) / sectors


def _top_outline_xy(fa: FrameAnalysis, det: CanDetection, spec: SceneSpec, tol_m: float) -> np.ndarray:
    """World xy (N, 2) of the outline of the flat top around an upright detection (pixels of its
    component within `tol_m` of the top's height, the connected part under its centre)."""
    image = fa.image
    r = spec.can.radius_m
    uv, z = project(np.array([[det.p_WC_m[0], det.p_WC_m[1], det.top_z_m]]), K=image.K, X_WC=image.X_WC)
    half = int(math.ceil(1.4 * image.K[0, 0] * r / float(z[0]))) + 2
    u, v = int(round(uv[0, 0])), int(round(uv[0, 1]))
    win = top_window(image, fa.components.labels, int(fa.components.labels[min(max(v, 0), image.depth_m.shape[0] - 1),
                                                                            min(max(u, 0), image.depth_m.shape[1] - 1)]),
                     rows=(v - half, v + half + 1), cols=(u - half, u + half + 1), top_z_m=det.top_z_m, tolerance_m=tol_m)
    top = cv2.morphologyEx(win.top.astype(np.uint8), cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
    n, lab = cv2.connectedComponents(top, connectivity=8)
    cr, cc = v - win.origin_px[0], u - win.origin_px[1]
    if n < 2 or not (0 <= cr < lab.shape[0] and 0 <= cc < lab.shape[1]) or lab[cr, cc] == 0:
        return np.zeros((0, 2))
    keep = lab == lab[cr, cc]
    outline = keep & ~cv2.erode(keep.astype(np.uint8), _CROSS).astype(bool)
    return win.p_W[outline][:, :2]


def _contiguous_run(along_m: np.ndarray, *, half_span_m: float, bin_m: float, min_fraction: float) -> np.ndarray:
    """The points (a mask) of the run of filled bins along the axis that holds the middle (0): a bin is
    filled with at least `min_fraction` of the median count of the bins in the middle half of the
    can's length. A neighbour standing off a lying can's end is past an empty bin and is left out."""
    edges = np.arange(-half_span_m, half_span_m + bin_m, bin_m)
    counts, _ = np.histogram(along_m, edges)
    mid = np.abs(0.5 * (edges[:-1] + edges[1:])) < half_span_m / 2
    filled = counts >= max(1.0, min_fraction * float(np.median(counts[mid])))
    i0 = int(np.clip(np.searchsorted(edges, 0.0) - 1, 0, len(counts) - 1))
    if not filled[i0]:
        return np.zeros(len(along_m), bool)
    lo = hi = i0
    while lo > 0 and filled[lo - 1]:
        lo -= 1
    while hi < len(counts) - 1 and filled[hi + 1]:
        hi += 1
    return (along_m >= edges[lo]) & (along_m < edges[hi + 1])


def _lying_fit(fa: FrameAnalysis, det: CanDetection, spec: SceneSpec) -> tuple[np.ndarray, float, float]:
    """A lying can's centre (x, y), axis yaw and the length (metres) its upper half spans.

    The upper half's points: higher than r above the plate, within r of the detection's axis, on
    the cylinder's surface (height r + sqrt(r^2 - d^2) at a distance d from the axis, within three
    robust sigmas of its residual on the can's middle half, at least `LYING_SURFACE_TOL_M`), and
    in the run of the axis that holds the detection's centre (`_contiguous_run`). Without the last
    two, the side of a can or box standing beyond the can's end, seen obliquely in the same height
    band, lengthened the span and moved the centre by up to 7 mm along the axis (docs/perception.md).
    """
    yaw = det.axis_yaw_rad
    image = fa.image
    r, h = spec.can.radius_m, spec.can.height_m
    c0 = np.asarray(det.p_WC_m[:2], float)
    a = np.array([math.cos(yaw), math.sin(yaw)])
    ends = np.array([[*(c0 + s * (h / 2 + 0.02) * a + t * r * np.array([-a[1], a[0]])), spec.plate_top_z_m + 2 * r]
                     for s in (-1, 1) for t in (-1, 1)])
    uv, _ = project(ends, K=image.K, X_WC=image.X_WC)
    hgt, wid = image.depth_m.shape
    c_lo = int(max(np.floor(uv[:, 0].min()) - 2, 0)); c_hi = int(min(np.ceil(uv[:, 0].max()) + 3, wid))
    r_lo = int(max(np.floor(uv[:, 1].min()) - 2, 0)); r_hi = int(min(np.ceil(uv[:, 1].max()) + 3, hgt))
    if c_hi <= c_lo or r_hi <= r_lo:
        return c0, yaw, 0.0
    p_W = camera_to_world(back_project_camera(image.depth_m[r_lo:r_hi, c_lo:c_hi], K=image.K, origin_px=(r_lo, c_lo)),
                          image.X_WC).reshape(-1, 3)
    with np.errstate(invalid="ignore"):
        z = p_W[:, 2] - spec.plate_top_z_m
        d = p_W[:, :2] - c0
        along, across = d @ a, d @ np.array([-a[1], a[0]])
        sel = (z > r + 0.004) & (z < 2 * r + 0.01) & (np.abs(across) < r) & (np.abs(along) < h / 2 + 0.015)
        resid = z - (r + np.sqrt(np.clip(r * r - across * across, 0.0, None)))
    core = sel & (np.abs(along) < h / 4)
    if core.sum() < 20:
        return c0, yaw, 0.0
    rc = resid[core]
    tol = max(LYING_SURFACE_TOL_M, 3.0 * 1.4826 * float(np.median(np.abs(rc - np.median(rc)))))
    sel &= np.abs(resid) < tol
    if sel.sum() < 20:
        return c0, yaw, 0.0
    idx = np.flatnonzero(sel)
    run = _contiguous_run(along[idx], half_span_m=h / 2 + 0.015, bin_m=LYING_RUN_BIN_M, min_fraction=LYING_RUN_MIN_FRACTION)
    idx = idx[run]
    if idx.size < 20:
        return c0, yaw, 0.0
    lo, hi = np.percentile(along[idx], [1, 99])
    return c0 + 0.5 * (lo + hi) * a, axis_yaw_tls(p_W[idx, :2]), float(hi - lo)


def detect_cans_robust(
    image: CameraImage, spec: SceneSpec, params: RobustParams = RobustParams(),
    side_images: dict[str, CameraImage] | None = None,
) -> tuple[list[CanDetection], FrameAnalysis, float]:
    """Detect the cans in a top-camera frame with the robust pipeline (see the module docstring).

    `side_images` (camera name -> frame, e.g. `front` and `back`) enable the side check.

    Returns:
        The detections kept (each with its confidence), the smoothed frame's analysis, and the
        noise measured on the plate (metres).
    """
    rng = np.random.default_rng(params.base.ransac_seed)
    measured = plate_noise_m(image, spec, rng=rng)
    sigma = max(measured if measured == measured else params.min_noise_m, params.min_noise_m)
    depth = denoise_depth(image.depth_m, sigma_m=sigma, d_px=params.bilateral_px,
                          sigma_space_px=params.bilateral_sigma_space_px, range_sigmas=params.bilateral_range_sigmas,
                          fill_dropouts=params.fill_dropouts)
    dets, fa = detect_cans(dataclasses.replace(image, depth_m=depth), spec, params.base)
    if not measured <= params.max_noise_m:
        log.warning("plate depth noise %.1f mm is above the robust pipeline's limit %.1f mm: all %d detections "
                    "refused", 1e3 * measured, 1e3 * params.max_noise_m, len(dets))
        return [], fa, measured
    r, h = spec.can.radius_m, spec.can.height_m
    side_points = world_points(side_images) if side_images and params.side_check else {}
    if params.side_check and not side_images:
        _log_once("no-side-camera", "robust pipeline: no side camera frame given; its side check (look-alikes) is "
                  "off, so it runs top-only (as `robust-top`)")
    out: list[CanDetection] = []
    for det in dets:
        if det.lying:
            xy, yaw, span = _lying_fit(fa, det, spec)
            if sigma <= params.strip_yaw_noise_m:
                yaw = det.axis_yaw_rad
            conf, floor = min(1.0, span / h), params.min_lying_confidence
        else:
            edges = _top_outline_xy(fa, det, spec, params.base.flat_top_tolerance_m)
            pixel_m = (image.X_WC[2, 3] - det.top_z_m) / image.K[0, 0]
            xy, inl = circle_ransac(edges, radius_m=r, near_xy=det.p_WC_m[:2], max_shift_m=0.5 * r,
                                    tol_m=1.5 * pixel_m, rng=rng)
            yaw = 0.0
            conf, floor = rim_coverage(edges[inl] - xy), params.min_upright_confidence
        if conf < floor:
            log.warning("%s can at (%.3f, %.3f): confidence %.2f below %.2f; refused, no grasp",
                        "lying" if det.lying else "upright", xy[0], xy[1], conf, floor)
            continue
        if side_points and not det.lying:
            profile = side_profile(xy, side_points, spec)
            if looks_alike(profile, radius_m=r):
                log.warning("upright can at (%.3f, %.3f): its side narrows to %.1f mm from the axis at %.0f%% of its "
                            "height (r = %.1f mm, tolerance %.1f mm; %s): a look-alike, refused, no grasp", xy[0], xy[1],
                            1e3 * profile.waist_m, 100 * profile.waist_height, 1e3 * r, 1e3 * SIDE_TOLERANCE_M,
                            ", ".join(profile.cameras))
                continue
        grasp = make_grasp(can_id=len(out), p_xy_m=xy, top_z_m=det.top_z_m, lying=det.lying, axis_yaw_rad=yaw,
                           top_offset_m=spec.grasp.top_offset_m, pregrasp_height_m=spec.grasp.pregrasp_height_m)
        out.append(dataclasses.replace(det, id=len(out), p_WC_m=(float(xy[0]), float(xy[1]), det.p_WC_m[2]),
                                       axis_yaw_rad=float(yaw), grasp=grasp, confidence=conf))
    return out, fa, measured


