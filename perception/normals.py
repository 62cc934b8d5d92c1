"""Surface normals by a local plane fit (PCA), the course notes' method (6.881, Section 5.2.2).

The point cloud is organised (one point per pixel), so a pixel's neighbourhood is a square window
around it. Window sums of the points and of their products are box filters over the image,
which gives every pixel's 3x3 covariance at once; the normal is the eigenvector of the smallest
eigenvalue (closed form for symmetric 3x3 matrices, vectorised), flipped to face the camera.
"""

from __future__ import annotations

import cv2
import numpy as np


def smallest_eigenvectors(cov: np.ndarray) -> np.ndarray:
    """Unit eigenvectors (N, 3) of the smallest eigenvalue of symmetric 3x3 matrices (N, 3, 3).

    Closed form (trigonometric solution of the characteristic cubic), then the eigenvector as the
    largest cross product of two rows of (C - lambda I); much faster than N LAPACK calls.
    """
    a, b, c = cov[:, 0, 0], cov[:, 1, 1], cov[:, 2, 2]
    d, e, f = cov[:, 0, 1], cov[:, 1, 2], cov[:, 0, 2]
    q = (a + b + c) / 3
    p1 = d * d + e * e + f * f
    p2 = (a - q) ** 2 + (b - q) ** 2 + (c - q) ** 2 + 2 * p1
    p = np.sqrt(np.maximum(p2 / 6, 1e-300))
    B = (cov - q[:, None, None] * np.eye(3)) / p[:, None, None]
    r = np.clip(np.linalg.det(B) / 2, -1.0, 1.0)
    phi = np.arccos(r) / 3
    lam = q + 2 * p * np.cos(phi + 2 * np.pi / 3)  # the smallest of the three roots
    M = cov - lam[:, None, None] * np.eye(3)
    cands = np.stack(
        [np.cross(M[:, 0], M[:, 1]), np.cross(M[:, 0], M[:, 2]), np.cross(M[:, 1], M[:, 2])], axis=1
    )
    norms = np.linalg.norm(cands, axis=-1)
    best = np.argmax(norms, axis=1)
    idx = np.arange(cov.shape[0])
    v = cands[idx, best]
    n = norms[idx, best]
    ok = n > 0
    v[ok] /= n[ok, None]
    if not ok.all():  # isotropic or degenerate: fall back to LAPACK
        v[~ok] = np.linalg.eigh(cov[~ok])[1][:, :, 0]
    return v


def estimate_normals(
    p_C: np.ndarray,
    valid: np.ndarray,
    *,
    window_px: int,
    min_neighbours: int,
    where: np.ndarray | None = None,
) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray]:
    """Normals of an organised camera-frame point cloud.

    Args:
        p_C: (H, W, 3) points in the camera frame, metres.
        valid: (H, W) boolean, which points take part in the fits (e.g. the cans' pixels with a
            finite depth). Windows only use valid points, so objects do not blend with the plate.
        window_px: side of the square neighbourhood, pixels (odd).
        min_neighbours: a pixel whose window holds fewer valid points gets no normal.
        where: (H, W) boolean, the pixels that need a normal (default: `valid`).

    Returns:
        (rows, cols) of the pixels that got a normal as an index tuple, and their unit normals
        (N, 3) in the camera frame, each facing the camera (n . p < 0).
    """
    where = valid if where is None else where
    if not valid.any():
        empty = np.zeros(0, np.intp)
        return (empty, empty.copy()), np.zeros((0, 3))
    w = valid.astype(np.float64)
    # Centre the coordinates before forming products, to keep the covariance well conditioned.
    origin = p_C[valid].mean(axis=0)
    p = np.where(valid[..., None], p_C - origin, 0.0)
    k = (window_px, window_px)

    def box(img: np.ndarray) -> np.ndarray:
        return cv2.boxFilter(img, cv2.CV_64F, k, normalize=False, borderType=cv2.BORDER_CONSTANT)

    n = box(w)
    rows, cols = np.nonzero(where & (n >= min_neighbours))
    cnt = n[rows, cols]
    s = np.stack([box(p[..., i])[rows, cols] for i in range(3)], axis=-1) / cnt[:, None]
    cov = np.empty((rows.size, 3, 3))
    for i in range(3):
        for j in range(i, 3):
            cij = box(p[..., i] * p[..., j])[rows, cols] / cnt - s[:, i] * s[:, j]
            cov[:, i, j] = cij
            cov[:, j, i] = cij
    normals = smallest_eigenvectors(cov) if rows.size else np.zeros((0, 3))
    # Face the camera: the camera sits at the origin of its frame, so n . p must be negative.
    flip = np.einsum("ij,ij->i", normals, p_C[rows, cols]) > 0
    normals[flip] *= -1
    return (rows, cols), normals
