"""Calibrate and crop: where the plate (and anything standing on it) can appear in an image.

The paper drew the plate's edges by hand for each camera. Here the outline comes from known
geometry: the plate's top-face corners, and the same corners raised by the tallest extent of a can,
are projected with the camera's pose and intrinsics; their convex hull is the work volume's image.
Everything outside it is empty space (the table, the bin, the robot arm). A can standing at the
plate's edge rises out of the top face's own outline in every view, hence the raised corners.
"""

from __future__ import annotations

import cv2
import numpy as np

from perception.geometry import project
from scenes.spec import SceneSpec

#: colour given to cropped-away pixels (black: neither plate grey nor can red)
EMPTY_RGB = (0, 0, 0)


def work_volume_corners_W(spec: SceneSpec) -> np.ndarray:
    """The 8 corners (8, 3) of the plate's top face extruded up by a can's tallest extent, metres."""
    spec.require("plate", "can", needed_by="perception's plate crop")
    cx, cy, _ = spec.plate.center_m
    sx, sy = spec.plate.size_m[:2]
    z0 = spec.plate_top_z_m
    z1 = z0 + max(spec.can.height_m, 2 * spec.can.radius_m)
    return np.array(
        [[cx + ax * sx / 2, cy + ay * sy / 2, z] for z in (z0, z1) for ax in (-1, 1) for ay in (-1, 1)]
    )


def plate_top_corners_W(spec: SceneSpec) -> np.ndarray:
    """The plate's top-face corners (4, 3) in order around the face, metres."""
    spec.require("plate", needed_by="perception's plate outline")
    cx, cy, _ = spec.plate.center_m
    sx, sy = spec.plate.size_m[:2]
    z0 = spec.plate_top_z_m
    return np.array([[cx + ax * sx / 2, cy + ay * sy / 2, z0] for ax, ay in ((-1, -1), (1, -1), (1, 1), (-1, 1))])


def roi_mask(spec: SceneSpec, *, K: np.ndarray, X_WC: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Boolean image (H, W): True inside the projected work volume.

    Raises:
        ValueError: if part of the work volume is behind the camera (a camera that cannot see
            the whole plate is a calibration error).
    """
    uv, z = project(work_volume_corners_W(spec), K=K, X_WC=X_WC)
    if np.any(z <= 0):
        raise ValueError("part of the plate is behind the camera; the camera cannot see the plate")
    hull = cv2.convexHull(np.round(uv).astype(np.int32))
    mask = np.zeros(shape, np.uint8)
    cv2.fillConvexPoly(mask, hull, 1)
    return mask.astype(bool)


def plate_outline_px(spec: SceneSpec, *, K: np.ndarray, X_WC: np.ndarray) -> np.ndarray:
    """The plate's top-face outline in the image (4, 2) pixels (for drawing)."""
    uv, _ = project(plate_top_corners_W(spec), K=K, X_WC=X_WC)
    return uv


def crop_rgb(rgb: np.ndarray, roi: np.ndarray) -> np.ndarray:
    """A copy of the colour image with everything outside `roi` set to empty space."""
    return np.where(roi[..., None], rgb, np.asarray(EMPTY_RGB, rgb.dtype))
