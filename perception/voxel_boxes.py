"""The perceived world's voxel boxes: occupied voxels merged into axis-aligned boxes, and each box
kept out of the space a perceived can holds where it stands.

A can that is seen stands where it was seen: the space its held model (its radius and half length
grown by the grasp's held margin) fills there is the can's, whatever voxel lies beside it. A box
reaches past what it holds by up to a voxel (an unseen cube beside the can, or the corner of a
box bounded by points on two sides), and at the lift's start the can in the gripper would strike
it although nothing but the can is there. `clear_of_cans` moves one face of every such box back
to the held model's surface: the face that loses the least volume; a box with no such face left
is dropped. The space given up reaches past the held margin by the goal IK's tolerance, and it is
given up round every perceived can, not only the one lifted: an object standing within it (5-8 mm
from a can, which the judge's margin on the held can alone allows) is erased from the world.
"""

from __future__ import annotations

import math

import numpy as np

from scenes.scene import CanPose


def merge_boxes(occ: np.ndarray, lo: np.ndarray | None = None, hi: np.ndarray | None = None,
                tol_m: float = math.inf) -> list[tuple[tuple[int, int, int], tuple[int, int, int]]]:
    """Occupied voxels (X, Y, Z bool) as axis-aligned boxes of whole voxels, greedily: the longest
    run along x, grown along y while the whole row is occupied, then along z while the whole
    rectangle is. Returns (start index, size in voxels) per box; together they cover exactly `occ`.

    With each voxel's content bounds `lo`, `hi` (X, Y, Z, 3), a box only takes in a slab whose
    faces across the growth lie within `tol_m` of the box's: a box over a round object then follows
    its outline in steps instead of becoming the square around it (whose corners reach past it)."""
    left = occ.copy()
    nx, ny, nz = occ.shape
    out = []

    def fits(box: tuple[slice, slice, slice], slab: tuple[slice, slice, slice], axis: int) -> bool:
        if lo is None or not math.isfinite(tol_m):
            return True
        across = [a for a in range(3) if a != axis]
        b_lo, b_hi = lo[box].reshape(-1, 3).min(axis=0), hi[box].reshape(-1, 3).max(axis=0)
        s_lo, s_hi = lo[slab].reshape(-1, 3).min(axis=0), hi[slab].reshape(-1, 3).max(axis=0)
        return bool(np.all(np.abs(b_lo[across] - s_lo[across]) <= tol_m)
                    and np.all(np.abs(b_hi[across] - s_hi[across]) <= tol_m))

    for k in range(nz):
        for j in range(ny):
            i = 0
            while i < nx:
                if not left[i, j, k]:
                    i += 1
                    continue
                i1 = i
                while (i1 + 1 < nx and left[i1 + 1, j, k]
                       and fits((slice(i, i1 + 1), slice(j, j + 1), slice(k, k + 1)),
                                (slice(i1 + 1, i1 + 2), slice(j, j + 1), slice(k, k + 1)), 0)):
                    i1 += 1
                j1 = j
                while (j1 + 1 < ny and left[i:i1 + 1, j1 + 1, k].all()
                       and fits((slice(i, i1 + 1), slice(j, j1 + 1), slice(k, k + 1)),
                                (slice(i, i1 + 1), slice(j1 + 1, j1 + 2), slice(k, k + 1)), 1)):
                    j1 += 1
                k1 = k
                while (k1 + 1 < nz and left[i:i1 + 1, j:j1 + 1, k1 + 1].all()
                       and fits((slice(i, i1 + 1), slice(j, j1 + 1), slice(k, k1 + 1)),
                                (slice(i, i1 + 1), slice(j, j1 + 1), slice(k1 + 1, k1 + 2)), 2)):
                    k1 += 1
                left[i:i1 + 1, j:j1 + 1, k:k1 + 1] = False
                out.append(((i, j, k), (i1 - i + 1, j1 - j + 1, k1 - k + 1)))
                i = i1 + 1
    return out


def _footprint(can: CanPose, radius_m: float, height_m: float) -> np.ndarray | None:
    """A lying can's held model seen from above: the rectangle (4, 2) its length and diameter
    span about its axis; None for an upright can (a disc)."""
    if not can.lying:
        return None
    a = np.array([math.cos(can.axis_yaw_rad), math.sin(can.axis_yaw_rad)])
    n = np.array([-a[1], a[0]])
    c = np.asarray(can.p_WC_m[:2], float)
    L, R = height_m / 2, radius_m
    return np.array([c + L * a + R * n, c - L * a + R * n, c - L * a - R * n, c + L * a - R * n])


def _slab(poly: np.ndarray, axis: int, lo: float, hi: float) -> np.ndarray:
    """The convex polygon `poly` (k, 2) cut to lo <= coordinate `axis` <= hi (possibly empty)."""
    for bound, keep in ((lo, 1.0), (hi, -1.0)):
        out = []
        n = len(poly)
        for i in range(n):
            p, q = poly[i], poly[(i + 1) % n]
            dp, dq = keep * (p[axis] - bound), keep * (q[axis] - bound)
            if dp >= 0:
                out.append(p)
            if dp * dq < 0:
                out.append(p + (q - p) * (dp / (dp - dq)))
        poly = np.array(out).reshape(-1, 2)
        if len(poly) == 0:
            break
    return poly


def clear_of_cans(lo: np.ndarray, hi: np.ndarray, cans, radius_m: float, height_m: float):
    """The box [lo, hi] with one face moved back off each held model (radius and height already
    grown) it enters: the face that loses the least of the box; None when no face can be moved
    without emptying it. An upright can's model is a disc over its height; a lying can's, the
    rectangle it covers from above over its diameter in height."""
    lo, hi = np.array(lo, float), np.array(hi, float)
    for can in cans:
        c = np.asarray(can.p_WC_m, float)
        rect = _footprint(can, radius_m, height_m)
        half_z = radius_m if can.lying else height_m / 2
        if hi[2] <= c[2] - half_z or lo[2] >= c[2] + half_z:
            continue
        if rect is None:
            near = np.clip(c[:2], lo[:2], hi[:2]) - c[:2]
            if float(near @ near) >= radius_m * radius_m:
                continue
        elif len(_slab(_slab(rect, 0, lo[0], hi[0]), 1, lo[1], hi[1])) == 0:
            continue
        # each axis: its low face raised past the model over the box's span across it, or its high
        # face lowered before it
        options = []
        for a in range(3):
            if a == 2:
                reach_lo, reach_hi = c[2] + half_z, c[2] - half_z
            elif rect is None:
                b = 1 - a
                gap = 0.0 if lo[b] <= c[b] <= hi[b] else min(abs(lo[b] - c[b]), abs(hi[b] - c[b]))
                half = math.sqrt(max(radius_m * radius_m - gap * gap, 0.0))
                reach_lo, reach_hi = c[a] + half, c[a] - half
            else:
                part = _slab(rect, 1 - a, lo[1 - a], hi[1 - a])
                reach_lo, reach_hi = float(part[:, a].max()), float(part[:, a].min())
            span = float(hi[a] - lo[a])
            if reach_lo < hi[a]:
                options.append((float(reach_lo - lo[a]) / span, a, "lo", reach_lo))
            if reach_hi > lo[a]:
                options.append((float(hi[a] - reach_hi) / span, a, "hi", reach_hi))
        fits = [o for o in options if o[0] < 1.0]
        if not fits:
            return None
        _, a, side, at = min(fits)
        if side == "lo":
            lo[a] = max(lo[a], at)
        else:
            hi[a] = min(hi[a], at)
    return lo, hi
