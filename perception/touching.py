"""Touching cans: one image component's vertical points split into groups that are each one can.

With the paper's gap between cans every component is one can. Dense plates (`clutter`) have
touching cans, merged into one component; `single_cans` splits them by the tops' heights, the
crease between lying cans, and k-means on the count the tops' area or length gives.
"""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np

from perception.can_model import top_bands_m
from perception.geometry import axis_yaw_tls
from scenes.spec import SceneSpec


_CLOSE_KERNEL = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (7, 7))


def single_cans(
    fa: Any, idx: np.ndarray, *, spec: SceneSpec, params: Any
) -> list[tuple[np.ndarray, bool]]:
    """Split one component's vertical points into groups that each belong to one can, each with
    whether it is at an upright can's height.

    With the paper's gap between cans every component is one can and this returns it whole.
    Touching cans merge into one component; their tops still come apart: an upright can's top disc
    and a lying can's top strip lie at different heights; two lying cans' strips are separated by
    the crease where their sides meet (no vertical normals there), unless they touch end to end,
    when the strip's length says how many they are; two upright cans' discs touch at most at a
    point, so their combined area says how many they are. k-means splits them (the discs, and the
    strips in line, are convex and disjoint). Points in neither can top's height band
    (`can_model.top_bands_m`, e.g. a bottle's top) belong to no can.

    `fa` is the frame's `perception.grasps.FrameAnalysis` and `params` its `PerceptionParams`
    (not imported: `perception.grasps` imports this module).
    """
    if idx.size == 0:
        return []
    groups = []
    z = fa.p_W[idx, 2] - spec.plate_top_z_m
    (lying_lo, lying_hi), (upright_lo, upright_hi) = top_bands_m(spec)
    high = (z >= upright_lo) & (z <= upright_hi)
    low = (z >= lying_lo) & (z < lying_hi) & ~high
    shape = fa.image.depth_m.shape
    for part, upright in ((idx[high], True), (idx[low], False)):
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
            else:
                # Lying cans touching end to end (axes in line) have one long strip: a can's strip
                # is at most h long, so its length says how many they are.
                xy = fa.p_W[g, :2]
                a = axis_yaw_tls(xy)
                length = float(np.ptp(xy @ np.array([math.cos(a), math.sin(a)])))
                count = max(1, int(round(length / spec.can.height_m)))
            if count > 1:
                lab_k = _kmeans(fa.p_W[g, :2], count)
                groups.extend((g[lab_k == c], upright) for c in range(count))
                continue
            groups.append((g, upright))
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
