"""Pinhole camera geometry: world points to pixels and depth pixels back to world points.

Drake's camera convention: +z along the optical axis, +x right and +y down in the image;
depth is the distance along +z (not along the ray).
"""

from __future__ import annotations

import math

import numpy as np


def project(p_W: np.ndarray, *, K: np.ndarray, X_WC: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (N, 2) as (u, v) of world points (N, 3), and their depth along the optical axis (N,)."""
    X_CW = np.linalg.inv(X_WC)
    p_C = p_W @ X_CW[:3, :3].T + X_CW[:3, 3]
    z = p_C[:, 2]
    uv = (p_C[:, :2] / z[:, None]) * np.array([K[0, 0], K[1, 1]]) + np.array([K[0, 2], K[1, 2]])
    return uv, z


def back_project_camera(depth_m: np.ndarray, *, K: np.ndarray, origin_px: tuple[int, int] = (0, 0)) -> np.ndarray:
    """Camera-frame points (H, W, 3) of a depth image; non-finite depth gives NaN points.

    Args:
        depth_m: depth along the optical axis (H, W), metres; or a window of a larger image.
        K: the camera's intrinsics (3, 3).
        origin_px: (row, col) of the window's top-left pixel in the full image.
    """
    h, w = depth_m.shape
    d = np.where(np.isfinite(depth_m), depth_m, np.nan).astype(np.float64)
    u = np.arange(origin_px[1], origin_px[1] + w, dtype=np.float64)[None, :]
    v = np.arange(origin_px[0], origin_px[0] + h, dtype=np.float64)[:, None]
    x = (u - K[0, 2]) / K[0, 0] * d
    y = (v - K[1, 2]) / K[1, 1] * d
    return np.stack([x, y, d], axis=-1)


def camera_to_world(p_C: np.ndarray, X_WC: np.ndarray) -> np.ndarray:
    """World points of camera-frame points (..., 3)."""
    return p_C @ X_WC[:3, :3].T + X_WC[:3, 3]


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
