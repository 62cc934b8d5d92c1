"""Primitive shapes of the python-fcl world: FCL geometries, sphere covers and the robot's parts."""

from __future__ import annotations

import math
from typing import NamedTuple

import fcl
import numpy as np

G_INDEX = 8  # index of the gripper body in RobotModel.link_poses


def fcl_geometry(kind: str, dims) -> fcl.CollisionGeometry:
    if kind == "box":
        return fcl.Box(*dims)
    if kind == "cylinder":
        return fcl.Cylinder(dims[0], dims[1])
    if kind == "capsule":
        return fcl.Capsule(dims[0], dims[1])
    if kind == "sphere":
        return fcl.Sphere(dims[0])
    raise ValueError(f"unsupported shape {kind!r}")


def aabb_half_extents(kind: str, dims, R: np.ndarray) -> np.ndarray:
    """Half extents (3,) of the world-axis-aligned box around a primitive turned by R (3, 3)."""
    if kind == "box":
        return np.abs(R) @ (np.asarray(dims, float) / 2)
    if kind == "sphere":
        return np.full(3, float(dims[0]))
    r, length = dims
    axis = R[:, 2]
    half = np.abs(axis) * length / 2 + r * np.sqrt(np.maximum(0.0, 1 - axis**2))
    return half + (np.full(3, r) if kind == "capsule" else 0.0)


def cover_spheres(kind: str, dims, spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Spheres covering a primitive: centres (k, 3) in the shape frame, outer and inner radii (k,).

    The union of the outer spheres encloses the shape; each inner ball (same centre) lies inside
    it. A capsule of radius r is covered by spheres of radius sqrt(r^2 + h^2) centred on its
    segment at most 2h = spacing * r apart, end points included; a cylinder likewise by slices
    of length 2h. A box is cut along its longest side into pieces no longer than spacing times
    its middle side, each enclosed by its half-diagonal.
    """
    if kind == "sphere":
        return np.zeros((1, 3)), np.array([dims[0]]), np.array([dims[0]])
    if kind == "box":
        size = np.asarray(dims, float)
        ax = int(np.argmax(size))
        mid = np.sort(size)[1]
        k = max(1, math.ceil(size[ax] / (2 * spacing * mid)))
        piece = size.copy()
        piece[ax] /= k
        t = -size[ax] / 2 + piece[ax] * (np.arange(k) + 0.5)
        centres = np.zeros((k, 3))
        centres[:, ax] = t
        outer = np.full(k, 0.5 * float(np.linalg.norm(piece)))
        others = [0.5 * size[i] for i in range(3) if i != ax]
        inner = np.minimum(min(others), size[ax] / 2 - np.abs(t))
        return centres, outer, inner
    r, length = dims
    k = max(1, math.ceil(length / (spacing * r)))
    h = length / (2 * k)
    if kind == "capsule":
        z = np.linspace(-length / 2, length / 2, k + 1)
        return np.column_stack([0 * z, 0 * z, z]), np.full(k + 1, math.hypot(r, h)), np.full(k + 1, r)
    if kind == "cylinder":
        z = -length / 2 + h + 2 * h * np.arange(k)
        inner = np.minimum(r, length / 2 - np.abs(z))
        return np.column_stack([0 * z, 0 * z, z]), np.full(k, math.hypot(r, h)), inner
    raise ValueError(f"unsupported shape {kind!r}")


def grown_dims(kind: str, dims, delta_m: float) -> tuple:
    """The dimensions of a primitive grown so that it contains every point within delta_m of it
    (a negative delta_m erodes it: the points at least |delta_m| inside)."""
    if kind == "box":
        return tuple(float(x) + 2 * delta_m for x in dims)
    if kind == "cylinder":
        return (dims[0] + delta_m, dims[1] + 2 * delta_m)
    if kind == "capsule":
        return (dims[0] + delta_m, dims[1])
    if kind == "sphere":
        return (dims[0] + delta_m,)
    raise ValueError(f"unsupported shape {kind!r}")


def bounding_radius(kind: str, dims) -> float:
    """Radius of the smallest sphere about the shape's origin that encloses it."""
    if kind == "box":
        return 0.5 * math.sqrt(sum(d * d for d in dims))
    if kind == "sphere":
        return dims[0]
    r, length = dims
    return r + length / 2 if kind == "capsule" else math.hypot(r, length / 2)


class Prim(NamedTuple):
    """A primitive fixed to chain link `link` (0..7) at pose X_LS."""

    kind: str
    dims: tuple
    link: int
    X_LS: np.ndarray


class Part:
    """One collision primitive of the robot, riding on FK body `body` (0..8)."""

    __slots__ = ("name", "body", "link", "kind", "dims", "X_BS", "X_LS", "obj", "geom")

    def __init__(self, name: str, body: int, X_BS: np.ndarray, kind: str, dims, X_7G: np.ndarray):
        self.name, self.body, self.X_BS, self.kind, self.dims = name, body, X_BS, kind, tuple(dims)
        # The chain link it moves with (the gripper body is welded to link 7) and its pose there.
        self.link = min(body, 7)
        self.X_LS = X_7G @ X_BS if body == G_INDEX else X_BS
        self.geom = fcl_geometry(kind, dims)
        self.obj = fcl.CollisionObject(self.geom, fcl.Transform())

    @property
    def prim(self) -> Prim:
        return Prim(self.kind, self.dims, self.link, self.X_LS)
