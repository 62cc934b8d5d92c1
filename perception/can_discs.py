"""Find upright cans' top discs of known radius in a flat top that is no single can's top.

When an upright can's top merges with another flat top at the same height (a touching box as tall
as a can, a neighbour split badly), or part of it is hidden by something taller in front of it,
the flat-top test of `perception.can_model` rejects the whole group. Its visible rim still lies on
a circle of the can's radius r: a Hough transform of fixed radius over the top's edge points
(where the top drops to something lower; not where something higher hides it) proposes centres,
and each is kept only if its rim profile fits a can (`RimProfile`):

- just inside the rim the top is there, or hidden by something higher;
- the top ends at the rim (an edge point within a pixel of r) along most of the rim that is open
  to view: neither hidden, nor on a can already found (touching cans share no edge there);
- at least half of the rim is seen at all (a disc wholly hidden is no evidence).

A rectangle's straight edge stays within a pixel of a circle of radius r over a short arc only:
at most about 45% of the rim for a square box of about a can's size, less for any other.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

from perception.can_model import TopWindow, top_window
from scenes.render import CameraImage
from scenes.spec import SceneSpec

_CROSS_KERNEL = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
#: samples of the rim profile
_RIM_SAMPLES = 72
#: a centre needs at least this fraction of a whole rim's edge points to be tried
_MIN_VOTE_FRACTION = 0.25
#: centres tried per group before giving up (each failed one is suppressed and the next tried)
_MAX_TRIES = 8


@dataclasses.dataclass(frozen=True)
class RimProfile:
    """How the top looks along the rim of a proposed disc, sector by sector about its centre.

    Attributes:
        inner: fraction of the sectors where the top is there (or hidden) just inside the rim.
        seen: fraction of the sectors where the top itself is seen just inside the rim.
        rim: of the sectors whose rim is open to view (not hidden by something higher, not on a
            neighbouring can's top), the fraction holding an edge point of the top on the rim
            (within a pixel of the radius). Edge points are back-projected, so they lie where the
            top ends whatever the perspective; a box's straight edge is within a pixel of a circle
            only over a few sectors.
    """

    inner: float
    seen: float
    rim: float

    def fits(self, *, min_inner_fraction: float, min_rim_fraction: float, min_seen_fraction: float) -> bool:
        """Whether the profile is a can's top: the top fills `min_inner_fraction` of the inside of
        the rim, ends at the rim along `min_rim_fraction` of it, and is seen along
        `min_seen_fraction` of it."""
        return (self.inner >= min_inner_fraction and self.rim >= min_rim_fraction
                and self.seen >= min_seen_fraction)


def rim_profile(win: TopWindow, image: CameraImage, *, edges_xy: np.ndarray, center_xy_m, top_z_m: float,
                radius_m: float, offset_m: float, neighbours_xy: np.ndarray) -> RimProfile:
    """The rim profile of a disc of `radius_m` about `center_xy_m` at height `top_z_m`.

    Args:
        win: the window around the top.
        image: the frame.
        edges_xy: (N, 2) the top's edge points (where it drops to something lower), metres.
        center_xy_m, top_z_m, radius_m: the disc.
        offset_m: the inner ring lies this far inside the rim; a sector's rim is hidden, or on a
            neighbour, when its point this far outside the rim is.
        neighbours_xy: (M, 2) centres of the cans found around it, metres.
    """
    t = np.linspace(0.0, 2 * math.pi, _RIM_SAMPLES, endpoint=False)
    u = np.column_stack([np.cos(t), np.sin(t)])
    c = np.asarray(center_xy_m, float)

    def ring(rad: float) -> np.ndarray:
        return np.column_stack([c + rad * u, np.full(len(t), top_z_m)])

    in_top, in_above = win.classify(ring(radius_m - offset_m), image)
    outer = ring(radius_m + offset_m)
    _, out_above = win.classify(outer, image)
    open_ = ~out_above
    for q in np.asarray(neighbours_xy).reshape(-1, 2):
        open_ &= np.linalg.norm(outer[:, :2] - q, axis=1) > radius_m + offset_m
    d = edges_xy - c
    on_rim = np.abs(np.linalg.norm(d, axis=1) - radius_m) <= win.pixel_m
    sector = np.floor(np.mod(np.arctan2(d[on_rim, 1], d[on_rim, 0]), 2 * math.pi) / (2 * math.pi) * _RIM_SAMPLES)
    has_rim = np.zeros(_RIM_SAMPLES, bool)
    has_rim[np.clip(sector.astype(int), 0, _RIM_SAMPLES - 1)] = True
    # sector k spans [t_k, t_k+1): compare with the rings sampled at its start and its end
    open_ = open_ & np.roll(open_, -1)
    return RimProfile(
        inner=float(np.mean(in_top | in_above)),
        seen=float(np.mean(in_top)),
        rim=float(np.mean(has_rim[open_])) if open_.any() else 0.0,
    )


def _fit_center(edges_xy: np.ndarray, c: np.ndarray, radius_m: float, band_m: float) -> np.ndarray:
    """Least-squares centre of a circle of fixed radius through the edge points within `band_m` of
    the circle about `c` (a few Gauss-Newton steps)."""
    for _ in range(5):
        d = edges_xy - c
        rho = np.linalg.norm(d, axis=1)
        near = np.abs(rho - radius_m) <= band_m
        if near.sum() < 3:
            break
        J = -d[near] / rho[near, None]  # d(rho)/d(c)
        res = rho[near] - radius_m
        step, *_ = np.linalg.lstsq(J, -res, rcond=None)
        c = c + step
        if np.linalg.norm(step) < 1e-5:
            break
    return c


def find_can_discs(
    image: CameraImage,
    labels: np.ndarray,
    label: int,
    *,
    core_rc: np.ndarray,
    top_z_m: float,
    taken_xy: np.ndarray,
    spec: SceneSpec,
    tolerance_m: float,
    rim_tolerance_px: float,
    min_inner_fraction: float,
    min_rim_fraction: float,
    min_seen_fraction: float,
) -> list[tuple[np.ndarray, int]]:
    """Upright cans' discs in the flat top around a group of vertical-normal points.

    Args:
        image: the frame.
        labels, label: the components (H, W) (before erosion) and the group's.
        core_rc: (N, 2) pixels (row, column) of the group's vertical-normal points.
        top_z_m: the top's height (world z), metres.
        taken_xy: (M, 2) centres of cans already found (a disc overlapping one of them is none).
        spec: the scene spec (the can's radius).
        tolerance_m: how far from `top_z_m` a point of the top may be.
        rim_tolerance_px: the rim profile's inner ring lies this many pixels inside the rim, and its
            test points for a hidden rim as far outside.
        min_inner_fraction, min_rim_fraction, min_seen_fraction: see `RimProfile.fits`.

    Returns:
        (centre (x, y) in metres, pixels of the top inside the disc) of each disc found.
    """
    r = spec.can.radius_m
    f = float(min(image.K[0, 0], image.K[1, 1]))
    rows, cols = core_rc[:, 0], core_rc[:, 1]
    depth = float(np.nanmedian(image.depth_m[rows, cols]))
    pad = int(math.ceil(2.5 * f * r / depth)) + 4  # a whole disc beyond the core's edge, and its outer ring
    win = top_window(image, labels, label, rows=(int(rows.min()) - pad, int(rows.max()) + pad + 1),
                     cols=(int(cols.min()) - pad, int(cols.max()) + pad + 1), top_z_m=top_z_m,
                     tolerance_m=tolerance_m)
    px = win.pixel_m
    # Edge points of the top: where it drops to something lower (not where something higher hides it).
    other = ~(win.top | win.above)
    edges = win.top & ~cv2.erode(win.top.astype(np.uint8), _CROSS_KERNEL).astype(bool)
    edges &= cv2.dilate(other.astype(np.uint8), _CROSS_KERNEL).astype(bool)
    edges_xy = win.p_W[edges][:, :2]
    if len(edges_xy) < 3:
        return []
    # Hough votes on a grid of one pixel: every edge point votes for the centres at r from it, one
    # vote spread along each pixel of that circle, so a cell collects about one vote per edge point
    # on the circle about it.
    n_angles = int(math.ceil(2 * 2 * math.pi * r / px))
    t = np.linspace(0.0, 2 * math.pi, n_angles, endpoint=False)
    votes_xy = (edges_xy[:, None, :] + r * np.stack([np.cos(t), np.sin(t)], axis=-1)[None]).reshape(-1, 2)
    lo = votes_xy.min(axis=0) - px
    ij = np.floor((votes_xy - lo) / px).astype(int)
    acc = np.zeros(ij.max(axis=0) + 2, np.float32)
    np.add.at(acc, (ij[:, 0], ij[:, 1]), np.float32(2 * math.pi * r / px / n_angles))
    acc = cv2.blur(acc, (3, 3)) * 3  # a centre a pixel off still counts its edge points
    min_votes = _MIN_VOTE_FRACTION * 2 * math.pi * r / px
    gi, gj = np.meshgrid(np.arange(acc.shape[0]), np.arange(acc.shape[1]), indexing="ij")
    offset = rim_tolerance_px * px
    proposals: list[np.ndarray] = []
    for _ in range(_MAX_TRIES):
        i, j = np.unravel_index(int(np.argmax(acc)), acc.shape)
        if acc[i, j] < min_votes:
            break
        c = _fit_center(edges_xy, lo + (np.array([i, j]) + 0.5) * px, r, 2 * offset)
        if all(np.linalg.norm(c - q) > 0.5 * r for q in proposals):
            proposals.append(c)
        for ci, cj in ((i, j), (c - lo) / px - 0.5):
            acc[np.hypot(gi - ci, gj - cj) * px <= 0.5 * r] = 0.0
    # Keep the proposals whose rim profile fits, trying the others again after each one kept: a kept
    # can explains the part of a touching neighbour's rim that has no edge (it lies against its top).
    taken = [np.asarray(q, float) for q in np.asarray(taken_xy).reshape(-1, 2)]
    found: list[tuple[np.ndarray, int]] = []
    top_xy = win.p_W[..., :2]
    pending = list(proposals)
    while pending:
        for c in pending:
            if any(np.linalg.norm(c - q) < 2 * r - 2 * offset for q in taken):
                continue  # discs of cans do not overlap
            prof = rim_profile(win, image, edges_xy=edges_xy, center_xy_m=c, top_z_m=top_z_m, radius_m=r,
                               offset_m=offset, neighbours_xy=np.array(taken).reshape(-1, 2))
            if prof.fits(min_inner_fraction=min_inner_fraction, min_rim_fraction=min_rim_fraction,
                         min_seen_fraction=min_seen_fraction):
                with np.errstate(invalid="ignore"):
                    n = int(np.count_nonzero(win.top & (np.linalg.norm(top_xy - c, axis=-1) <= r)))
                found.append((c, n))
                taken.append(c)
                pending = [q for q in pending if q is not c]
                break
        else:
            break
    return found
