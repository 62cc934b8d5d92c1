"""Joint tables: self pairs proved apart (or touching) over the one joint their distance depends on.

A table covers one joint's range in cells, each proved once per process from FCL signed
distances and a Lipschitz bound; a cell proved apart or touching needs no FCL query at run time.
"""

from __future__ import annotations

import itertools

import fcl
import numpy as np

from scenes.collision.shapes import Prim, bounding_radius, fcl_geometry
from scenes.robot_model import RobotModel

#: Cells of a self-pair table over its one joint.
TABLE_CELLS = 1024
#: A table cell is proved only if the pair's distance bound clears zero by this (FCL's own
#: tolerance is far smaller).
TABLE_MARGIN_M = 1e-4

#: Table cell values: not proved either way (ask FCL), proved apart, proved in collision.
UNKNOWN, APART, TOUCHING = 0, 1, 2


class PairTable:
    """One joint's range in cells, each UNKNOWN, APART or TOUCHING for a self pair."""

    __slots__ = ("joint", "lower_rad", "cells_per_rad", "cells")

    def __init__(self, joint: int, lower_rad: float, cells_per_rad: float, cells: bytearray):
        self.joint, self.lower_rad, self.cells_per_rad, self.cells = joint, lower_rad, cells_per_rad, cells

    @property
    def always_apart(self) -> bool:
        return all(c == APART for c in self.cells)


_TABLES: dict[tuple, PairTable | None] = {}


def on_axis(prim: Prim, X_axis: np.ndarray) -> bool:
    """True if the primitive is round about the z axis of frame X_axis (both in one link frame)."""
    if prim.kind not in ("sphere", "cylinder", "capsule"):
        return False
    d, o = X_axis[:3, 2], X_axis[:3, 3]
    off = prim.X_LS[:3, 3] - o
    if np.linalg.norm(off - d * (off @ d)) > 1e-9:
        return False
    return prim.kind == "sphere" or abs(abs(prim.X_LS[:3, 2] @ d) - 1.0) < 1e-12


def revolved(prim: Prim) -> Prim:
    """A cylinder about its link's z axis enclosing a box in every turn of that link's joint."""
    corners = np.array(list(itertools.product(*[(-d / 2, d / 2) for d in prim.dims])))
    c_L = corners @ prim.X_LS[:3, :3].T + prim.X_LS[:3, 3]
    radius = float(np.max(np.hypot(c_L[:, 0], c_L[:, 1])))
    z0, z1 = float(c_L[:, 2].min()), float(c_L[:, 2].max())
    X = np.eye(4)
    X[2, 3] = (z0 + z1) / 2
    return Prim("cylinder", (radius, z1 - z0), prim.link, X)


def pair_table(robot: RobotModel, a: Prim, b: Prim) -> PairTable | None:
    """A proved table for self pair (a, b), a on the lower link, over the one joint their
    distance depends on, or None when it depends on more. Cached per process."""
    chain = tuple((j.X_origin.tobytes(), j.lower_rad, j.upper_rad) for j in robot.joints)
    key = (chain, a.kind, a.dims, a.link, a.X_LS.round(12).tobytes(), b.kind, b.dims, b.link, b.X_LS.round(12).tobytes())
    if key in _TABLES:
        return _TABLES[key]
    joints = list(range(a.link, b.link))  # q indices of joints a.link + 1 .. b.link
    if joints and on_axis(a, robot.joints[joints[0]].X_origin):
        joints = joints[1:]  # a is round about the first joint: its angle does not matter
    enclosed = False
    if joints and joints[-1] == b.link - 1 and not on_axis(b, np.eye(4)) and len(joints) == 2 and b.kind == "box":
        b, enclosed = revolved(b), True  # bound b over its own joint's turn
    if joints and joints[-1] == b.link - 1 and on_axis(b, np.eye(4)):
        joints = joints[:-1]
    table = build_table(robot, a, b, joints[0] if joints else -1) if len(joints) <= 1 else None
    if table is not None and enclosed:  # the enclosure touching proves nothing about b itself
        table.cells = bytearray(APART if c == APART else UNKNOWN for c in table.cells)
    _TABLES[key] = table
    return table


def build_table(robot: RobotModel, a: Prim, b: Prim, joint: int) -> PairTable:
    """Prove cells apart (or in collision) by the FCL signed distance at a run of cells' centre
    minus (plus) a Lipschitz bound, halving runs only where unproved.

    Turning joint `joint` by dq moves any point p of b by at most |dq| |p - o| (o, the origin of
    the link it turns, lies on its axis); |p - o| is bounded by the joint offsets from o to b's
    link plus b's reach from that link's origin.
    """
    req = fcl.DistanceRequest(enable_signed_distance=True)
    oa = fcl.CollisionObject(fcl_geometry(a.kind, a.dims), fcl.Transform())
    ob = fcl.CollisionObject(fcl_geometry(b.kind, b.dims), fcl.Transform())
    q = np.zeros(7)

    def dist(q_j: float) -> float:
        if joint >= 0:
            q[joint] = q_j
        X = robot.link_poses(q)
        Xa, Xb = X[a.link] @ a.X_LS, X[b.link] @ b.X_LS
        oa.setTransform(fcl.Transform(Xa[:3, :3], Xa[:3, 3]))
        ob.setTransform(fcl.Transform(Xb[:3, :3], Xb[:3, 3]))
        return float(fcl.distance(oa, ob, req, fcl.DistanceResult()))

    if joint < 0:
        return PairTable(-1, 0.0, 0.0, bytearray([APART if dist(0.0) > TABLE_MARGIN_M else UNKNOWN]))
    reach = float(np.linalg.norm(b.X_LS[:3, 3])) + bounding_radius(b.kind, b.dims)
    rho = reach + sum(float(np.linalg.norm(robot.joints[m].X_origin[:3, 3])) for m in range(joint + 1, b.link))
    n = TABLE_CELLS
    lo = robot.joints[joint].lower_rad
    step = (robot.joints[joint].upper_rad - lo) / n
    cells = bytearray(n)
    stack = [(0, n)]
    while stack:
        i0, i1 = stack.pop()
        d = dist(lo + (i0 + i1) / 2 * step)
        bound = rho * (i1 - i0) / 2 * step
        if d - bound > TABLE_MARGIN_M:
            cells[i0:i1] = bytes([APART]) * (i1 - i0)
        elif d + bound < -TABLE_MARGIN_M:
            cells[i0:i1] = bytes([TOUCHING]) * (i1 - i0)
        elif i1 - i0 > 1:  # else one unproved cell
            stack += [(i0, (i0 + i1) // 2), ((i0 + i1) // 2, i1)]
    return PairTable(joint, lo, 1.0 / step, cells)
