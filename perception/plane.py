"""Colour-free segmentation: RANSAC plane removal (the paper's suggested relaxation of its
colour assumption). The dominant plane in the work volume is the plate's top; what stands clearly
above it, over the plate's footprint, is can.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from perception.geometry import back_project_camera, camera_to_world
from scenes.render import CameraImage
from scenes.spec import SceneSpec


_FILL_KERNEL = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))


@dataclasses.dataclass(frozen=True)
class Plane:
    """The plane n . p = d (unit normal n pointing up, world frame, metres)."""

    n: tuple[float, float, float]
    d_m: float
    inliers: int


def ransac_plane(
    p: np.ndarray, *, threshold_m: float, iterations: int, rng: np.random.Generator
) -> Plane:
    """Fit the plane with most points within `threshold_m` (RANSAC), refined by least squares
    on its inliers.

    Args:
        p: (N, 3) points, N >= 3.
        threshold_m: inlier distance.
        iterations: random 3-point samples to try.
        rng: the sampler's generator.
    """
    best_n, best_d, best_count = np.array([0.0, 0.0, 1.0]), 0.0, -1
    idx = rng.integers(0, p.shape[0], size=(iterations, 3))
    a, b, c = p[idx[:, 0]], p[idx[:, 1]], p[idx[:, 2]]
    normals = np.cross(b - a, c - a)
    norm = np.linalg.norm(normals, axis=1)
    ok = norm > 1e-12
    normals, a = normals[ok] / norm[ok, None], a[ok]
    # Score on a subsample: the counts only need to rank the candidates.
    sub = p[rng.choice(p.shape[0], size=min(p.shape[0], 4000), replace=False)]
    for n, a0 in zip(normals, a):
        d = n @ a0
        count = int(np.count_nonzero(np.abs(sub @ n - d) < threshold_m))
        if count > best_count:
            best_n, best_d, best_count = n, d, count
    inl = p[np.abs(p @ best_n - best_d) < threshold_m]
    centroid = inl.mean(axis=0)
    _, _, vt = np.linalg.svd(inl - centroid, full_matrices=False)
    n = vt[-1]
    if n[2] < 0:
        n = -n
    return Plane(tuple(float(v) for v in n), float(n @ centroid), int(inl.shape[0]))


def above_plate_mask(
    image: CameraImage,
    spec: SceneSpec,
    roi: np.ndarray,
    *,
    min_height_m: float,
    threshold_m: float,
    iterations: int,
    rng: np.random.Generator,
) -> tuple[np.ndarray, Plane | None]:
    """Pixels (H, W) inside `roi` whose point stands at least `min_height_m` above the fitted
    plate plane and over the plate's footprint; also the plane (None if too few points)."""
    mask = np.zeros(roi.shape, bool)
    finite = roi & np.isfinite(image.depth_m)
    rows, cols = np.nonzero(finite)
    if rows.size < 3:
        return mask, None
    r0, r1, c0, c1 = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
    p_C = back_project_camera(image.depth_m[r0:r1, c0:c1], K=image.K, origin_px=(r0, c0))
    p_W = camera_to_world(p_C[rows - r0, cols - c0], image.X_WC)
    plane = ransac_plane(p_W, threshold_m=threshold_m, iterations=iterations, rng=rng)
    height = p_W @ np.asarray(plane.n) - plane.d_m
    cx, cy, _ = spec.plate.center_m
    sx, sy = spec.plate.size_m[:2]
    keep = (height >= min_height_m) & (np.abs(p_W[:, 0] - cx) <= sx / 2) & (np.abs(p_W[:, 1] - cy) <= sy / 2)
    mask[rows[keep], cols[keep]] = True
    # Pixels without depth (dropouts) are holes in a depth-made mask; closing fills them, or the
    # erosion that follows would widen each into a hole the size of the erosion kernel.
    mask = cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_CLOSE, _FILL_KERNEL).astype(bool) & roi
    return mask, plane
