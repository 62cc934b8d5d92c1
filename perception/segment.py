"""Colour segmentation (the can mask) and mask separation (the paper's Algorithm 1).

Colour rule, in OpenCV's HSV (H in [0, 180), S and V in [0, 255]): the plate is grey (S near 0,
the seed's "R, G, B about equal"), the cans are bright red. A pixel is can-coloured when its hue is
within `RED_HUE_TOL` of red (0 = 180), it is clearly saturated and not black. The shaded sides of
cylinders are dark red, so V may be low; the cropped-away area is pure black (V = 0) and the
plate's S is about 0, so neither passes.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

RED_HUE_TOL = 10  # OpenCV hue units (2 degrees each): red is H <= 10 or H >= 170
MIN_SATURATION = 120  # grey plate ~0; the brown table is ~115 (and cropped away anyway)
MIN_VALUE = 40  # excludes black (cropped-away space, unlit sides)


def can_mask(rgb: np.ndarray, roi: np.ndarray | None = None) -> np.ndarray:
    """Boolean mask (H, W) of can-coloured pixels inside `roi` (the whole image if None)."""
    hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)
    h, s, v = hsv[..., 0], hsv[..., 1], hsv[..., 2]
    red = (h <= RED_HUE_TOL) | (h >= 180 - RED_HUE_TOL)
    mask = red & (s >= MIN_SATURATION) & (v >= MIN_VALUE)
    if roi is not None:
        mask &= roi
    return mask


@dataclasses.dataclass(frozen=True)
class Components:
    """The separated masks of one image.

    Attributes:
        labels: (H, W) int32, 0 for background, k >= 1 for the k-th kept component.
        eroded: (H, W) int32, the same labels after erosion (edge pixels dropped).
        areas_px: pixel area of each kept component (before erosion), in label order.
    """

    labels: np.ndarray
    eroded: np.ndarray
    areas_px: tuple[int, ...]

    @property
    def count(self) -> int:
        return len(self.areas_px)


def separate(mask: np.ndarray, *, min_area_px: int, erode_px: int) -> Components:
    """Split a mask into connected components (Algorithm 1) and erode each one.

    Algorithm 1's flood fill is 8-connected component labelling. Components below `min_area_px`
    are specks, not cans. Erosion drops each component's outer `erode_px` pixels: at a can's
    silhouette the depth pixel may already lie on the plate behind it (the paper's Fig. 9).

    Args:
        mask: boolean can mask.
        min_area_px: smallest component area that may be a can, pixels.
        erode_px: erosion radius, pixels.
    """
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    keep = [k for k in range(1, n) if stats[k, cv2.CC_STAT_AREA] >= min_area_px]
    lut = np.zeros(n, np.int32)
    for i, k in enumerate(keep, start=1):
        lut[k] = i
    relabelled = lut[labels]
    if erode_px > 0:
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * erode_px + 1, 2 * erode_px + 1))
        inner = cv2.erode((relabelled > 0).astype(np.uint8), kernel).astype(bool)
        eroded = np.where(inner, relabelled, 0).astype(np.int32)
    else:
        eroded = relabelled
    return Components(relabelled, eroded, tuple(int(stats[k, cv2.CC_STAT_AREA]) for k in keep))
