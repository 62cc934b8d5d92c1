"""Certified bounds on the signed distance between two convex primitives (box, cylinder, capsule,
sphere): the arbiter of `bench kernel --near-contact`, independent of FCL (whose GJK distances
err by up to 4e-4 m here and whose `collide` misses penetrations of 1e-8 m between a capsule or
a cylinder and a box).

The signed distance sd(A, B) is the distance when A and B are apart and minus the penetration
depth (the shortest translation that separates them) when they overlap. For every unit direction
n, the gap from A to B along n, -(h_A(n) + h_B(-n)) with h the support function, is a lower bound
on it, and equals it at the best n. An upper bound comes from points: apart, the distance from a
point of A to B; overlapping, -2 rho for a point rho deep inside both (a ball of radius rho in
both cannot be separated by a translation shorter than 2 rho). Both bounds are evaluated in
closed form, so they hold whatever the searches that chose n and the points did; where the
searches converge, the lower bound is the signed distance to about 1e-16 m and the upper bound
meets it when apart (within about 30% of it when overlapping at an edge).
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np
from scipy.optimize import minimize

#: |sd| at or below this is contact within rounding (the primitives measure about 1 m; float64).
ROUNDING_M = 1e-13


@dataclasses.dataclass(frozen=True)
class Prim:
    """A convex primitive placed in the world: `kind` (box, cylinder, capsule, sphere), `dims`
    (box: full sizes; cylinder and capsule: radius and length along the shape's z; sphere:
    radius), rotation R_WS (3, 3) and centre p_WS (3,), in metres."""

    kind: str
    dims: tuple
    R_WS: np.ndarray
    p_WS: np.ndarray

    @functools.cached_property
    def _scalars(self) -> tuple:
        R = np.asarray(self.R_WS, float)
        return tuple(map(float, R.T.ravel())), tuple(map(float, self.p_WS)), tuple(map(float, self.dims))


def _local(P: Prim, x: tuple) -> tuple[float, float, float]:
    (r00, r10, r20, r01, r11, r21, r02, r12, r22), (px, py, pz), _ = P._scalars
    vx, vy, vz = x[0] - px, x[1] - py, x[2] - pz
    return r00 * vx + r10 * vy + r20 * vz, r01 * vx + r11 * vy + r21 * vz, r02 * vx + r12 * vy + r22 * vz


def _support1(P: Prim, nx: float, ny: float, nz: float) -> float:
    """h_P(n) for one direction (floats)."""
    (r00, r10, r20, r01, r11, r21, r02, r12, r22), (px, py, pz), d = P._scalars
    mx, my, mz = r00 * nx + r10 * ny + r20 * nz, r01 * nx + r11 * ny + r21 * nz, r02 * nx + r12 * ny + r22 * nz
    base = px * nx + py * ny + pz * nz
    k = P.kind
    if k == "box":
        return base + 0.5 * (d[0] * abs(mx) + d[1] * abs(my) + d[2] * abs(mz))
    if k == "sphere":
        return base + d[0] * math.sqrt(mx * mx + my * my + mz * mz)
    if k == "capsule":
        return base + 0.5 * d[1] * abs(mz) + d[0] * math.sqrt(mx * mx + my * my + mz * mz)
    if k == "cylinder":
        return base + 0.5 * d[1] * abs(mz) + d[0] * math.hypot(mx, my)
    raise ValueError(f"unsupported shape {k!r}")


def support(P: Prim, N: np.ndarray) -> np.ndarray:
    """h_P(n) = max over x in P of n . x, for each row of N (k, 3): (k,)."""
    N = np.atleast_2d(N)
    m = N @ P.R_WS  # the directions in the shape's frame
    base = N @ P.p_WS
    if P.kind == "box":
        return base + np.abs(m) @ (0.5 * np.asarray(P.dims, float))
    if P.kind == "sphere":
        return base + P.dims[0] * np.linalg.norm(m, axis=1)
    r, length = P.dims
    axial = 0.5 * length * np.abs(m[:, 2])
    if P.kind == "capsule":
        return base + axial + r * np.linalg.norm(m, axis=1)
    if P.kind == "cylinder":
        return base + axial + r * np.hypot(m[:, 0], m[:, 1])
    raise ValueError(f"unsupported shape {P.kind!r}")


def point_sd(P: Prim, x) -> float:
    """Signed distance (m) of point x to P: positive outside, minus the depth inside."""
    vx, vy, vz = _local(P, x)
    d = P._scalars[2]
    if P.kind == "box":
        qx, qy, qz = abs(vx) - 0.5 * d[0], abs(vy) - 0.5 * d[1], abs(vz) - 0.5 * d[2]
        out = math.sqrt(max(qx, 0.0) ** 2 + max(qy, 0.0) ** 2 + max(qz, 0.0) ** 2)
        return out + min(max(qx, qy, qz), 0.0)
    if P.kind == "sphere":
        return math.sqrt(vx * vx + vy * vy + vz * vz) - d[0]
    r, half = d[0], 0.5 * d[1]
    if P.kind == "capsule":
        z = min(max(vz, -half), half)
        return math.sqrt(vx * vx + vy * vy + (vz - z) ** 2) - r
    dr, dz = math.hypot(vx, vy) - r, abs(vz) - half
    return math.hypot(max(dr, 0.0), max(dz, 0.0)) + min(max(dr, dz), 0.0)


def support_point(P: Prim, n: np.ndarray, toward: np.ndarray, *, flat: float = 1e-9) -> np.ndarray:
    """A point of P maximising n . x (n unit); where the maximisers form a face or an edge (a
    component of n in the shape's frame below `flat`), the one nearest `toward` on it."""
    m = P.R_WS.T @ n
    t = P.R_WS.T @ (np.asarray(toward, float) - P.p_WS)
    if P.kind == "box":
        h = 0.5 * np.asarray(P.dims, float)
        v = np.where(np.abs(m) > flat, np.sign(m) * h, np.clip(t, -h, h))
    elif P.kind == "sphere":
        v = P.dims[0] * m / np.linalg.norm(m)
    else:
        r, length = P.dims
        z = np.sign(m[2]) * 0.5 * length if abs(m[2]) > flat else min(max(t[2], -0.5 * length), 0.5 * length)
        if P.kind == "capsule":
            v = np.array([0.0, 0.0, z]) + r * m / np.linalg.norm(m)
        else:
            w = math.hypot(m[0], m[1])
            if w > flat:
                xy = r * m[:2] / w
            else:  # n along the axis: the cap, nearest `toward`
                w = math.hypot(t[0], t[1])
                xy = t[:2] * (r / w if w > r else 1.0)
            v = np.array([xy[0], xy[1], z])
    return P.p_WS + P.R_WS @ v


def _sphere_points(k: int) -> np.ndarray:
    """k unit directions spread evenly (a Fibonacci lattice)."""
    i = np.arange(k) + 0.5
    z = 1 - 2 * i / k
    phi = math.pi * (1 + 5**0.5) * i
    s = np.sqrt(1 - z * z)
    return np.column_stack([s * np.cos(phi), s * np.sin(phi), z])


_SPREAD = _sphere_points(300)


def gaps(A: Prim, B: Prim, N: np.ndarray) -> np.ndarray:
    """The gap from A to B along each unit row of N: lower bounds on sd(A, B), in m."""
    return -(support(A, N) + support(B, -N))


def _gap1(A: Prim, B: Prim, n) -> float:
    return -(_support1(A, n[0], n[1], n[2]) + _support1(B, -n[0], -n[1], -n[2]))


def _refine(A: Prim, B: Prim, n0: np.ndarray) -> tuple[float, np.ndarray]:
    """The best gap near unit direction n0 (Nelder-Mead on its tangent plane): (gap, n)."""
    e1 = np.cross(n0, [1.0, 0.0, 0.0] if abs(n0[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n0, e1)

    def unit(ab):
        n = n0 + ab[0] * e1 + ab[1] * e2
        return n / math.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])

    res = minimize(lambda ab: -_gap1(A, B, unit(ab)), np.zeros(2), method="Nelder-Mead",
                   options={"xatol": 1e-15, "fatol": 1e-18, "maxiter": 1500,
                            "initial_simplex": np.array([[0.0, 0.0], [2e-2, 0.0], [0.0, 2e-2]])})
    n = unit(res.x)
    return _gap1(A, B, n), n


def _axes(P: Prim) -> list[np.ndarray]:
    if P.kind == "box":
        return [P.R_WS[:, i] for i in range(3)]
    if P.kind in ("cylinder", "capsule"):
        return [P.R_WS[:, 2]]
    return []


def candidates(A: Prim, B: Prim, hints=()) -> np.ndarray:
    """Unit directions worth trying: `hints`, the centres' direction, the shapes' axes and face
    normals, both ways, and their cross products (edge against edge)."""
    axes = _axes(A) + _axes(B)
    cand = [np.asarray(h, float) for h in hints if h is not None] + [B.p_WS - A.p_WS]
    cand += axes + [np.cross(a, b) for a in _axes(A) for b in _axes(B)]
    N = np.vstack(cand)
    N = N[np.linalg.norm(N, axis=1) > 1e-12]
    N = N / np.linalg.norm(N, axis=1)[:, None]
    return np.vstack([N, -N])


def lower_bound(A: Prim, B: Prim, hints=(), *, refine: int = 3) -> tuple[float, np.ndarray]:
    """The best gap found: over `candidates` and 300 spread directions, the best `refine` of them
    refined: (a lower bound on sd(A, B) in m, its direction from A to B)."""
    N = np.vstack([candidates(A, B, hints), _SPREAD])
    g = gaps(A, B, N)
    order = np.argsort(-g)
    best, n_best = float(g[order[0]]), N[order[0]]
    tried: list[np.ndarray] = []
    for k in order:
        if len(tried) == refine:
            break
        if any(float(N[k] @ t) > 0.999 for t in tried):
            continue  # the same basin as one refined already
        tried.append(N[k])
        val, n = _refine(A, B, N[k])
        if val > best:
            best, n_best = val, n
    return best, n_best


def upper_bound(A: Prim, B: Prim, n: np.ndarray) -> float:
    """An upper bound on sd(A, B) in m from points, given the best direction n from A to B: apart,
    the distance of A's extreme point along n to B (or B's along -n to A; where an extreme is an
    edge or a face, the points of the two nearest each other); overlapping, -2 rho
    for the point found deepest in both (0: a common point on the boundary)."""
    b = support_point(B, -n, B.p_WS)
    a = support_point(A, n, b)
    for _ in range(200):  # where both extremes are edges or faces: the nearest points on them
        b2 = support_point(B, -n, a)
        a2 = support_point(A, n, b2)
        moved = float(np.abs(a2 - a).max() + np.abs(b2 - b).max())
        a, b = a2, b2
        if moved < 1e-16:
            break
    da, db = point_sd(B, a), point_sd(A, b)
    if min(da, db) > 0:  # a point of A outside B at da, one of B outside A at db
        return min(da, db, float(np.linalg.norm(a - b)))

    def depth(x):  # how deep x lies in both (negative: outside one of them)
        return min(-point_sd(A, x), -point_sd(B, x))

    x0 = 0.5 * (a + b)
    size = max(float(np.linalg.norm(a - b)), 1e-12)
    res = minimize(lambda x: -depth(x), x0, method="Nelder-Mead",
                   options={"xatol": 1e-17, "fatol": 1e-19, "maxiter": 1500,
                            "initial_simplex": x0 + np.vstack([np.zeros(3), size * np.eye(3)])})
    rho = max(depth(res.x), depth(x0))
    return -2.0 * rho if rho > 0 else 0.0  # else a or b is a common point: touching at least


def sd_bounds(A: Prim, B: Prim, hints=()) -> tuple[float, float]:
    """(lo, hi) in m with lo <= sd(A, B) <= hi, both evaluated in closed form."""
    lo, n = lower_bound(A, B, hints)
    return lo, upper_bound(A, B, n)
