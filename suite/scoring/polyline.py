"""Joint paths as piecewise-linear curves: simplification and sampling by arc length.

A validated path is the polyline through its waypoints (the validator checks the straight
segments between them). Two waypoint lists that trace the same polyline, such as a path and the
same path with a midpoint inserted in every segment, must score the same. So metrics work on:
- `simplify(path)`: the polyline with zero-length segments and collinear interior points
  dropped (the same points for every waypoint density);
- `arc_samples(path, step_rad)`: points at a fixed arc-length spacing along it (L2, rad), with
  its corners added, and trapezoid weights for means along the path.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

#: Consecutive waypoints closer than this (L2, rad) count as one.
DUPLICATE_TOL_RAD = 1e-9
#: An interior waypoint where the direction turns by less than this (rad) is collinear.
COLLINEAR_TOL_RAD = 1e-6


def as_path(path) -> np.ndarray:
    """The path as a float (N, 7) array, N >= 1; ValueError otherwise."""
    path = np.asarray(path, float)
    if path.ndim != 2 or path.shape[1] != 7 or len(path) == 0:
        raise ValueError(f"path must be an (N, 7) array with N >= 1, got shape {path.shape}")
    return path


def angle_between_rad(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Angles (rad) between unit vectors (..., n): 2 atan2(|u - v|, |u + v|), accurate near 0 and pi."""
    return 2.0 * np.arctan2(np.linalg.norm(u - v, axis=-1), np.linalg.norm(u + v, axis=-1))


def simplify(
    path, *, duplicate_tol_rad: float = DUPLICATE_TOL_RAD, collinear_tol_rad: float = COLLINEAR_TOL_RAD
) -> np.ndarray:
    """The same polyline through as few waypoints as possible.

    A waypoint within duplicate_tol_rad (L2) of the previous one is dropped (the last waypoint
    is kept in place of its predecessor, so the path still ends where it ended); then an interior
    waypoint where the direction turns by less than collinear_tol_rad is dropped. A reversal
    (angle pi) is kept.

    Returns:
        The kept waypoints (K, 7), K >= 1; the first and last are the path's own.
    """
    path = as_path(path)
    keep = np.concatenate([[True], np.linalg.norm(np.diff(path, axis=0), axis=1) > duplicate_tol_rad])
    if len(path) > 1 and not keep[-1] and np.count_nonzero(keep) > 1:
        keep[np.nonzero(keep)[0][-1]] = False  # the end replaces the last kept point near it
        keep[-1] = True
    pts = path[keep]
    if len(pts) < 3:
        return pts.copy()
    d = np.diff(pts, axis=0)
    u = d / np.linalg.norm(d, axis=1, keepdims=True)
    corner = angle_between_rad(u[:-1], u[1:]) >= collinear_tol_rad
    return pts[np.concatenate([[True], corner, [True]])]


def path_length_rad(path) -> float:
    """Joint-space path length: sum_i ||q_{i+1} - q_i||_2 over the waypoints, in rad.

    This is OMPL's PathGeometric::length() in a RealVectorStateSpace (L2 distance). MoveIt's
    path-length metric uses the L1 norm instead; this one is L2.
    """
    path = as_path(path)
    return float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)))


@dataclasses.dataclass(frozen=True, eq=False)
class ArcSamples:
    """Configurations along a path at a fixed arc-length spacing.

    Attributes:
        q: the configurations (M, 7), rad: every multiple of the step, every corner and both ends.
        s_rad: their arc length from the start (M,), increasing.
        weights: trapezoid weights (M,) summing to 1 (a single sample has weight 1), so that
            `weights @ f(q)` is the mean of f along the path by arc length.
    """

    q: np.ndarray
    s_rad: np.ndarray
    weights: np.ndarray

    def mean(self, values: np.ndarray) -> float:
        """The arc-length mean of per-sample values (M,)."""
        return float(self.weights @ np.asarray(values, float))


def arc_samples(path, step_rad: float, *, per_step: int = 1) -> ArcSamples:
    """Samples of the simplified polyline at arc lengths k * L / n, n = per_step * ceil(L / step_rad)
    (spacing at most step_rad / per_step, L2 rad), plus its corners. The samples depend on the
    polyline only, not on how many waypoints describe it; with per_step = m they include (to
    rounding) those of per_step = 1."""
    if not step_rad > 0 or per_step < 1:
        raise ValueError(f"step_rad must be > 0 and per_step >= 1, got {step_rad}, {per_step}")
    poly = simplify(path)
    if len(poly) == 1:
        return ArcSamples(poly.copy(), np.zeros(1), np.ones(1))
    seg = np.linalg.norm(np.diff(poly, axis=0), axis=1)
    s_knots = np.concatenate([[0.0], np.cumsum(seg)])
    total = s_knots[-1]
    n = per_step * max(1, math.ceil(total / step_rad))
    s = np.union1d(np.linspace(0.0, total, n + 1), s_knots)
    j = np.clip(np.searchsorted(s_knots, s, side="right") - 1, 0, len(seg) - 1)
    w = np.clip((s - s_knots[j]) / seg[j], 0.0, 1.0)
    q = poly[j] + w[:, None] * (poly[j + 1] - poly[j])
    q[-1] = poly[-1]
    ds = np.diff(s)
    weights = (np.concatenate([ds, [0.0]]) + np.concatenate([[0.0], ds])) / (2.0 * total)
    return ArcSamples(q, s, weights)


def resample_uniform(path, step_rad: float) -> np.ndarray:
    """Points at equal arc length along the polyline: n = ceil(L / step_rad) equal steps of L / n
    (<= step_rad, L2 rad), (n + 1, 7). A path that does not move gives its single point. Corners
    between samples are cut (OMPL's smoothness is computed on these)."""
    poly = simplify(path)
    if len(poly) == 1:
        return poly.copy()
    seg = np.linalg.norm(np.diff(poly, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    n = max(1, math.ceil(s[-1] / step_rad))
    s_new = np.linspace(0.0, s[-1], n + 1)
    j = np.clip(np.searchsorted(s, s_new, side="right") - 1, 0, len(seg) - 1)
    w = np.clip((s_new - s[j]) / seg[j], 0.0, 1.0)
    out = poly[j] + w[:, None] * (poly[j + 1] - poly[j])
    out[-1] = poly[-1]
    return out


def densify(path, step_rad: float) -> np.ndarray:
    """Every waypoint, with each segment cut into ceil(len / step_rad) equal pieces (L2 rad).

    The samples depend on the waypoints; metrics use `arc_samples`, which does not.
    """
    path = simplify(path, collinear_tol_rad=0.0)
    if len(path) == 1:
        return path.copy()
    d = np.diff(path, axis=0)
    n = np.maximum(1, np.ceil(np.linalg.norm(d, axis=1) / step_rad).astype(int))
    seg = np.repeat(np.arange(len(d)), n)
    frac = np.concatenate([np.arange(k) / k for k in n])
    return np.vstack([path[seg] + frac[:, None] * d[seg], path[-1:]])
