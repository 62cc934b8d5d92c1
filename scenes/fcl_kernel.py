"""The python-fcl world's decisions compiled with numba: forward kinematics on the stored rows, the
sphere tiers, the joint tables and the motion proof of `motion_samples_free`.

A state is FREE (no sphere pair overlaps and every tabled pair's cell is proved apart), COLLIDES
(an inner ball meets an obstacle or another part's inner ball, or a tabled pair's cell is proved
touching) or UNDECIDED, with the part-level pairs that FCL's `collide` must decide; that stays in
Python (`scenes.fcl_compiled.CompiledWorld`), counted per trial. The answers are the numpy path's
(`scenes.fcl_world`); the bounds are sharper, which only decides more pairs without FCL:

- a sphere's distance to an obstacle is exact for the obstacle's kind (a box in its own frame, a
  cylinder, a sphere), where the numpy path bounds every obstacle by its axis-aligned box (the
  window's rotated walls and the cans are not their boxes); so every inner ball counts;
- a scene pair the coarse spheres leave open is tried with the part's fine spheres (spaced a
  quarter of its radius: 0.8% above it) before FCL;
- the motion proof reads the same distance bounds, so it proves at least as many samples free.

No `fastmath`; the joint transforms are built from their three non-zero columns. A motion's
samples are evaluated in one call, the coarsest first, resumable where FCL must decide a sample.
The differential check (`python -m suite bench kernel`, `tests/scenes/test_fcl_compiled.py`)
compares the answers with the numpy path's.

Compiled once per machine into numba's disk cache (`cache_dir()`): a user-writable directory,
written atomically by numba, so that worker processes starting together share it; where no
directory is writable the kernels compile in memory. Nothing here needs a C compiler.
"""

from __future__ import annotations

import logging
import os
import tempfile
import time
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)

#: Decisions of a state (and a motion check's request for a larger work array).
FREE, COLLIDES, UNDECIDED, NEED_SPACE = 0, 1, 2, 4
#: Table cell values (as `scenes.fcl_tables`).
_UNKNOWN, _APART, _TOUCHING = 0, 1, 2
#: A scene pair the fine spheres prove apart.
_APART_PAIR = 3
#: Obstacle kinds, each with its exact point distance: an axis-aligned box, a box, a cylinder
#: (axis z of its frame), a sphere.
AABB, OBB, CYLINDER, SPHERE = 0, 1, 2, 3


def cache_candidates() -> list[Path]:
    """Where the kernels' cache may go, in order: NUMBA_CACHE_DIR if set, the user's cache
    (XDG_CACHE_HOME or ~/.cache) under can-recycling-suite/numba, then the temporary directory."""
    env = os.environ.get("NUMBA_CACHE_DIR")
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return [*([Path(env)] if env else []), Path(base) / "can-recycling-suite" / "numba",
            Path(tempfile.gettempdir()) / f"can-recycling-suite-numba-{os.getuid()}"]


def cache_dir(candidates: list[Path] | None = None) -> Path | None:
    """The first writable directory of `candidates` (default `cache_candidates()`), created if
    need be; None if none is writable (the kernels then compile in memory, in every process)."""
    for d in cache_candidates() if candidates is None else candidates:
        try:
            d.mkdir(parents=True, exist_ok=True)
            probe = tempfile.NamedTemporaryFile(dir=d, prefix=".probe", delete=True)
            probe.close()
            return d
        except OSError:
            continue
    return None


_CACHE = cache_dir()
if _CACHE is not None:
    os.environ.setdefault("NUMBA_CACHE_DIR", str(_CACHE))

import numba  # noqa: E402  (after NUMBA_CACHE_DIR is set: numba reads it on import)

if _CACHE is not None and numba.config.CACHE_DIR != str(_CACHE):
    numba.config.CACHE_DIR = str(_CACHE)  # numba was imported before this module

_jit = numba.njit(cache=_CACHE is not None, nogil=True, fastmath=False, error_model="numpy")


#: The world's arrays packed into three buffers (one dispatch argument each: a numba call pays
#: about 60 ns per argument, more than a state's sphere tier with 26 of them).
FLOAT_FIELDS = ("Mc", "Ms", "M1", "rows0", "obs_ctr", "obs_half", "R2", "rho2", "tab_lo", "tab_inv", "tab_n",
                "row_chain", "pair_r", "pair_self", "rows", "d2", "scratch", "lam_pair", "fine_rows0", "fine_out2",
                "fine_in2", "obs_rot", "sph")
INT_FIELDS = ("link_end", "s_row", "ia", "ib", "pp", "tab_j", "tab_k", "pair_b", "pair_counts", "pairs", "is_frame",
              "pp_part", "pp_obs", "part_link", "fine_start", "obs_type")
#: Header of the int buffer: sizes, then (start, length) of every float field, then of every int field.
N_SIZES = 8  # R (robot rows), Rt (world rows), O, P, T, n_env, tab_width, n_pp
HEADER = N_SIZES + 2 * (len(FLOAT_FIELDS) + len(INT_FIELDS))
SCRATCH = 7 * 16 + 2 * 12 + 7 * 12  # LT, W, V, and W_k of every link (for the frame rows, on demand)


def pack(fields: dict, sizes: tuple) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(F, I, C): every float field, every int field (after the header) and the table cells."""
    fl = [np.ascontiguousarray(fields[k], np.float64).ravel() for k in FLOAT_FIELDS]
    il = [np.ascontiguousarray(fields[k], np.int64).ravel() for k in INT_FIELDS]
    F = np.concatenate(fl) if fl else np.zeros(0)
    head = np.zeros(HEADER, np.int64)
    head[:N_SIZES] = sizes
    at = 0
    for f, a in enumerate(fl):
        head[N_SIZES + 2 * f], head[N_SIZES + 2 * f + 1] = at, len(a)
        at += len(a)
    at = HEADER
    base = N_SIZES + 2 * len(FLOAT_FIELDS)
    for f, a in enumerate(il):
        head[base + 2 * f], head[base + 2 * f + 1] = at, len(a)
        at += len(a)
    I = np.concatenate([head, *il])
    C = np.ascontiguousarray(fields["tab_cells"], np.uint8).ravel()
    return F, I, C


def float_field(F: np.ndarray, I: np.ndarray, name: str) -> np.ndarray:
    """A view of float field `name` in F (for Python: the rows FCL places parts by)."""
    f = FLOAT_FIELDS.index(name)
    a, n = I[N_SIZES + 2 * f], I[N_SIZES + 2 * f + 1]
    return F[a : a + n]


def int_field(I: np.ndarray, name: str) -> np.ndarray:
    f = N_SIZES + 2 * len(FLOAT_FIELDS) + 2 * INT_FIELDS.index(name)
    return I[I[f] : I[f] + I[f + 1]]


@_jit
def _f(F, I, f):
    a = I[N_SIZES + 2 * f]
    return F[a : a + I[N_SIZES + 2 * f + 1]]


@_jit
def _i(I, f):
    k = N_SIZES + 2 * len(FLOAT_FIELDS) + 2 * f
    return I[I[k] : I[k] + I[k + 1]]


@_jit
def fk_rows(q, F, I):
    """World rows (x, y, z) of configuration q: the sphere centres' rows into the rows field (the
    rest, link 0's rows and the obstacle centres, is constant); the parts' frame rows, which only
    FCL needs, are left to `fk_frames`.

    Joint k's local transform (transposed: rows multiply from the left) is
    Mc[k] cos q_k + Ms[k] sin q_k + M1[k], the three non-zero columns of the numpy path's M.
    Each link's frame to the world, W_k = LT_k ... LT_1 (x y z columns), then maps its rows."""
    Mc, Ms, M1 = _f(F, I, 0), _f(F, I, 1), _f(F, I, 2)
    rows0, rows, scratch = _f(F, I, 3), _f(F, I, 14), _f(F, I, 16)
    link_end, is_frame = _i(I, 0), _i(I, 10)
    LT = scratch[:112]
    W = scratch[112:124]
    V = scratch[124:136]
    Wall = scratch[136:220]
    for k in range(7):
        c, s = np.cos(q[k]), np.sin(q[k])
        for e in range(16):
            LT[16 * k + e] = Mc[16 * k + e] * c + Ms[16 * k + e] * s + M1[16 * k + e]
    for a in range(4):
        for b in range(3):
            W[3 * a + b] = LT[4 * a + b]
    for k in range(1, 8):
        if k > 1:
            o = 16 * (k - 1)
            for a in range(4):
                for b in range(3):
                    acc = 0.0
                    for m in range(4):
                        acc += LT[o + 4 * a + m] * W[3 * m + b]
                    V[3 * a + b] = acc
            for e in range(12):
                W[e] = V[e]
        for e in range(12):
            Wall[12 * (k - 1) + e] = W[e]
        lo = link_end[k + 1] if k < 7 else 0
        for r in range(lo, link_end[k]):
            if is_frame[r]:
                continue
            for b in range(3):
                acc = 0.0
                for m in range(4):
                    acc += rows0[4 * r + m] * W[3 * m + b]
                rows[3 * r + b] = acc


@_jit
def fk_frames(F, I):
    """The parts' frame rows of the configuration `fk_rows` last mapped (for FCL's placements)."""
    rows0, rows, scratch = _f(F, I, 3), _f(F, I, 14), _f(F, I, 16)
    link_end, is_frame = _i(I, 0), _i(I, 10)
    Wall = scratch[136:220]
    for k in range(1, 8):
        lo = link_end[k + 1] if k < 7 else 0
        w = 12 * (k - 1)
        for r in range(lo, link_end[k]):
            if not is_frame[r]:
                continue
            for b in range(3):
                acc = 0.0
                for m in range(4):
                    acc += rows0[4 * r + m] * Wall[w + 3 * m + b]
                rows[3 * r + b] = acc


@_jit
def _point_d2(O, ctr, half, rot, t, o, x, y, z):
    """Squared distance from point (x, y, z) to obstacle o of kind t (0 inside), exact for its
    kind. Obstacles are stored by coordinate: centre x of all, then y, z; rotation entry (a, b)
    of all at (3 a + b) O; half sizes (box), radius and half length (cylinder) or radius (sphere)."""
    vx, vy, vz = x - ctr[o], y - ctr[O + o], z - ctr[2 * O + o]
    if t == AABB:
        lx, ly, lz = vx, vy, vz
    elif t == SPHERE:
        d = np.sqrt(vx * vx + vy * vy + vz * vz) - half[o]
        return d * d if d > 0.0 else 0.0
    else:  # in the obstacle's frame: R^T v
        lx = rot[o] * vx + rot[3 * O + o] * vy + rot[6 * O + o] * vz
        ly = rot[O + o] * vx + rot[4 * O + o] * vy + rot[7 * O + o] * vz
        lz = rot[2 * O + o] * vx + rot[5 * O + o] * vy + rot[8 * O + o] * vz
    if t == CYLINDER:
        dr = np.sqrt(lx * lx + ly * ly) - half[o]
        dz = abs(lz) - half[O + o]
        dr = dr if dr > 0.0 else 0.0
        dz = dz if dz > 0.0 else 0.0
        return dr * dr + dz * dz
    dx = abs(lx) - half[o]
    dy = abs(ly) - half[O + o]
    dz = abs(lz) - half[2 * O + o]
    dx = dx if dx > 0.0 else 0.0
    dy = dy if dy > 0.0 else 0.0
    dz = dz if dz > 0.0 else 0.0
    return dx * dx + dy * dy + dz * dz


@_jit
def _d2_all(F, I):
    """Squared distance of every sphere pair into the d2 field: each scene sphere's centre to each
    obstacle (exact, by its kind: `_point_d2`), obstacle-major, then the self pairs' centres."""
    rows, d2, sph = _f(F, I, 14), _f(F, I, 15), _f(F, I, 22)
    s_row, ia, ib = _i(I, 1), _i(I, 2), _i(I, 3)
    O, n_env = I[2], I[5]
    S = len(s_row)
    for s in range(S):  # the scene spheres' centres by coordinate
        r = 3 * s_row[s]
        sph[s], sph[S + s], sph[2 * S + s] = rows[r], rows[r + 1], rows[r + 2]
    ctr, half, rot, kind = _f(F, I, 4), _f(F, I, 5), _f(F, I, 21), _i(I, 15)
    for o in range(O):
        t = kind[o]
        cx, cy, cz = ctr[o], ctr[O + o], ctr[2 * O + o]
        hx, hy, hz = half[o], half[O + o], half[2 * O + o]
        base = o * S
        if t == AABB:  # the common case, in a loop the compiler vectorizes
            for s in range(S):
                dx = abs(sph[s] - cx) - hx
                dy = abs(sph[S + s] - cy) - hy
                dz = abs(sph[2 * S + s] - cz) - hz
                dx = dx if dx > 0.0 else 0.0
                dy = dy if dy > 0.0 else 0.0
                dz = dz if dz > 0.0 else 0.0
                d2[base + s] = dx * dx + dy * dy + dz * dz
        elif t == SPHERE:
            for s in range(S):
                vx, vy, vz = sph[s] - cx, sph[S + s] - cy, sph[2 * S + s] - cz
                d = np.sqrt(vx * vx + vy * vy + vz * vz) - hx
                d2[base + s] = d * d if d > 0.0 else 0.0
        else:
            r00, r01, r02 = rot[o], rot[O + o], rot[2 * O + o]
            r10, r11, r12 = rot[3 * O + o], rot[4 * O + o], rot[5 * O + o]
            r20, r21, r22 = rot[6 * O + o], rot[7 * O + o], rot[8 * O + o]
            if t == OBB:
                for s in range(S):
                    vx, vy, vz = sph[s] - cx, sph[S + s] - cy, sph[2 * S + s] - cz
                    dx = abs(r00 * vx + r10 * vy + r20 * vz) - hx
                    dy = abs(r01 * vx + r11 * vy + r21 * vz) - hy
                    dz = abs(r02 * vx + r12 * vy + r22 * vz) - hz
                    dx = dx if dx > 0.0 else 0.0
                    dy = dy if dy > 0.0 else 0.0
                    dz = dz if dz > 0.0 else 0.0
                    d2[base + s] = dx * dx + dy * dy + dz * dz
            else:
                for s in range(S):
                    vx, vy, vz = sph[s] - cx, sph[S + s] - cy, sph[2 * S + s] - cz
                    lx = r00 * vx + r10 * vy + r20 * vz
                    ly = r01 * vx + r11 * vy + r21 * vz
                    dr = np.sqrt(lx * lx + ly * ly) - hx
                    dz = abs(r02 * vx + r12 * vy + r22 * vz) - hy
                    dr = dr if dr > 0.0 else 0.0
                    dz = dz if dz > 0.0 else 0.0
                    d2[base + s] = dr * dr + dz * dz
    for p in range(n_env, len(ia)):
        a, b = 3 * ia[p], 3 * ib[p]
        dx = abs(rows[a] - rows[b])
        dy = abs(rows[a + 1] - rows[b + 1])
        dz = abs(rows[a + 2] - rows[b + 2])
        d2[p] = dx * dx + dy * dy + dz * dz


@_jit
def _table_cell(F, I, C, t, qj):
    x = (qj - _f(F, I, 8)[t]) * _f(F, I, 9)[t]
    if 0.0 <= x < _f(F, I, 10)[t]:
        return C[t * I[6] + int(x)]
    return _UNKNOWN


@_jit
def _fine_pair(F, I, part, o):
    """A scene pair the coarse spheres left open, tried with the part's fine spheres (the same
    kind of cover, spaced closer): APART if none reaches the obstacle, COLLIDES if a fine inner
    ball meets it, else UNDECIDED (FCL's)."""
    rows0f, out2, in2, Wall = _f(F, I, 18), _f(F, I, 19), _f(F, I, 20), _f(F, I, 16)[136:220]
    part_link, fine_start = _i(I, 13), _i(I, 14)
    O, ctr, half, rot, t = I[2], _f(F, I, 4), _f(F, I, 5), _f(F, I, 21), _i(I, 15)[o]
    w = 12 * (part_link[part] - 1)
    hit = False
    for s in range(fine_start[part], fine_start[part + 1]):
        a0, a1, a2, a3 = rows0f[4 * s], rows0f[4 * s + 1], rows0f[4 * s + 2], rows0f[4 * s + 3]
        x = a0 * Wall[w] + a1 * Wall[w + 3] + a2 * Wall[w + 6] + a3 * Wall[w + 9]
        y = a0 * Wall[w + 1] + a1 * Wall[w + 4] + a2 * Wall[w + 7] + a3 * Wall[w + 10]
        z = a0 * Wall[w + 2] + a1 * Wall[w + 5] + a2 * Wall[w + 8] + a3 * Wall[w + 11]
        d2 = _point_d2(O, ctr, half, rot, t, o, x, y, z)
        if d2 <= out2[s]:
            if d2 < in2[s]:
                return COLLIDES
            hit = True
    return UNDECIDED if hit else _APART_PAIR


@_jit
def state_decide(q, F, I, C):
    """One state: FREE, COLLIDES, or UNDECIDED with its part-level pairs for FCL in the pairs
    field [:count]. Returns (decision, count); the rows field holds its world rows and d2 every
    sphere pair's squared distance (all of them unless an early COLLIDES)."""
    n_pp = I[7]
    marks = np.zeros(n_pp, np.bool_)
    tab_j, tab_k = _i(I, 5), _i(I, 6)
    for t in range(len(tab_j)):
        c = _table_cell(F, I, C, t, q[tab_j[t]])
        if c == _TOUCHING:
            return COLLIDES, 0
        if c != _APART:
            marks[tab_k[t]] = True
    fk_rows(q, F, I)
    _d2_all(F, I)
    d2, R2, rho2, pp = _f(F, I, 15), _f(F, I, 6), _f(F, I, 7), _i(I, 4)
    for p in range(len(d2)):
        if d2[p] <= R2[p]:
            if d2[p] < rho2[p]:
                return COLLIDES, 0
            marks[pp[p]] = True
    pp_part, pp_obs, fine_start = _i(I, 11), _i(I, 12), _i(I, 14)
    for k in range(n_pp):  # scene pairs: the part's fine spheres may decide them
        o = pp_obs[k]
        if marks[k] and o >= 0 and fine_start[pp_part[k] + 1] > fine_start[pp_part[k]]:
            r = _fine_pair(F, I, pp_part[k], o)
            if r == COLLIDES:
                return COLLIDES, 0
            if r == _APART_PAIR:
                marks[k] = False
    pairs = _i(I, 9)
    count = 0
    for k in range(n_pp):
        if marks[k]:
            pairs[count] = k
            count += 1
    if count:
        fk_frames(F, I)
        return UNDECIDED, count
    return FREE, 0


@_jit
def _reach(F, I, lam_pair, n):
    """How many sample steps a state's distances prove free on either side: the floor of the least
    (distance bound / lambda) over the counting pairs, minus 1e-9, as the numpy path computes it,
    capped at n + 1 (a reach beyond the motion proves nothing more). A pair whose squared distance
    shows it cannot lower the least so far skips its square root."""
    d2, pair_r, pair_counts = _f(F, I, 15), _f(F, I, 12), _i(I, 8)
    best = n + 1.0
    for p in range(len(d2)):
        lp = lam_pair[p]
        if pair_counts[p] and lp > 0.0:
            t = best * lp + pair_r[p]
            if t > 0.0 and d2[p] >= t * t:
                continue  # sqrt(d2) - r >= best * lambda: not below the least
            v = (np.sqrt(d2[p]) - pair_r[p]) / lp
            if v < best:
                best = v
    return np.int64(np.floor(best - 1e-9))


#: Layout of a motion check's work array (int64): phase, position, n, states evaluated, head
#: length, the head's sample indices, then the reach of q0 and of each head sample.
WS_HEAD, WS_REACH = 5, 5 + 8
WORK = WS_REACH + 9
_START, _HEAD, _REST = 0, 1, 2


@_jit
def _head_order(n, ws):
    """The motion's first samples, as `scenes.fcl_motion.check_order(n)[:8]`: the end n, then
    1..n-1 coarsest first (by the power of two dividing them; ascending among equals)."""
    ws[WS_HEAD] = n
    k = 1
    level = 0
    while (1 << (level + 1)) <= n - 1:
        level += 1
    while level >= 0 and k < 8:
        step = 1 << level
        i = step
        while i < n and k < 8:
            if (i >> level) & 1:  # exactly `level` factors of two
                ws[WS_HEAD + k] = i
                k += 1
            i += 2 * step
        level -= 1
    ws[4] = k


@_jit
def motion_check(q0, q1, resolution, F, I, C, todo, ws):
    """The planners' motion check of q0 -> q1 (samples q0 + (i / n)(q1 - q0), i = 1..n,
    n = max(1, ceil(max_j |q1_j - q0_j| / resolution)); q0 taken as free), decided as
    `MotionChecks._motion_samples_free` does: q0 and the head (the end and the coarsest samples)
    first, their distance bounds proving neighbours free, the joint tables looked up at every
    sample, then the samples nothing proved, in order.

    Resumable: it returns at the first sample it leaves UNDECIDED (its rows and pairs in F and I,
    the pair count returned) and, called again with the same `ws`, continues after it; set
    ws[0] = 0 to start a motion. Returns (FREE: the motion is free, COLLIDES, or UNDECIDED,
    pairs); ws[3] counts the states evaluated."""
    P, Rt = I[3], I[1]
    lam_pair = _f(F, I, 17)
    q = np.empty(7)
    d = np.empty(7)
    for j in range(7):
        d[j] = q1[j] - q0[j]
    if ws[0] == _START:
        ws[3] = 0
        big = 0.0
        for j in range(7):
            if abs(d[j]) > big:
                big = abs(d[j])
        n = np.int64(np.ceil(big / resolution))
        if n < 1:
            n = 1
        ws[2] = n
        if n + 1 > len(todo):
            return NEED_SPACE, 0  # the caller gives a `todo` of at least ws[2] + 1 and calls again
        ws[1], ws[3] = 0, 1
        _head_order(n, ws)
        ia, pair_b = _i(I, 2), _i(I, 7)
        row_chain, pair_self = _f(F, I, 11), _f(F, I, 13)
        lam = np.empty(Rt)
        for r in range(Rt):
            acc = 0.0
            for j in range(7):
                acc += row_chain[7 * r + j] * abs(d[j] / n)
            lam[r] = acc
        for p in range(P):
            lam_pair[p] = lam[ia[p]] + lam[pair_b[p]] * pair_self[p]
        fk_rows(q0, F, I)  # q0: only its distances are wanted
        _d2_all(F, I)
        ws[WS_REACH] = _reach(F, I, lam_pair, n)
        ws[0] = _HEAD
    n, n_head = ws[2], ws[4]
    if ws[0] == _HEAD:
        for h in range(ws[1], n_head):
            i = ws[WS_HEAD + h]
            for j in range(7):
                q[j] = q0[j] + (i / n) * d[j]
            ws[3] += 1
            code, count = state_decide(q, F, I, C)
            if code == COLLIDES:
                return COLLIDES, 0
            ws[WS_REACH + 1 + h] = _reach(F, I, lam_pair, n)
            if code == UNDECIDED:
                ws[1] = h + 1
                return UNDECIDED, count
        if n_head == n:
            return FREE, 0
        for m in range(n + 1):
            todo[m] = True
        for h in range(n_head + 1):
            i = 0 if h == 0 else ws[WS_HEAD + h - 1]
            k = ws[WS_REACH + h]
            if k >= 1:
                lo = i - k if i - k > 0 else 0
                hi = i + k + 1 if i + k + 1 < n + 1 else n + 1
                for m in range(lo, hi):
                    todo[m] = False
        tab_j = _i(I, 5)
        if len(tab_j):
            for m in range(1, n + 1):
                unknown = False
                for t in range(len(tab_j)):
                    j = tab_j[t]
                    c = _table_cell(F, I, C, t, q0[j] + (m / n) * d[j])
                    if c == _TOUCHING:
                        return COLLIDES, 0
                    if c == _UNKNOWN:
                        unknown = True
                if unknown:
                    todo[m] = True
        todo[0] = False
        for h in range(n_head):
            todo[ws[WS_HEAD + h]] = False  # evaluated already
        ws[0], ws[1] = _REST, 1
    for m in range(ws[1], n + 1):
        if not todo[m]:
            continue
        for j in range(7):
            q[j] = q0[j] + (m / n) * d[j]
        ws[3] += 1
        code, count = state_decide(q, F, I, C)
        if code != FREE:
            ws[1] = m + 1
            return code, count
    return FREE, 0


@_jit
def batch_decide(Q, stop_at_first, F, I, C):
    """Decisions (M,) of a batch of states; with stop_at_first, the states after the first
    COLLIDES are left FREE (unchecked). UNDECIDED states are FCL's."""
    out = np.zeros(len(Q), np.int64)
    for m in range(len(Q)):
        code, _ = state_decide(Q[m], F, I, C)
        out[m] = code
        if code == COLLIDES and stop_at_first:
            break
    return out


_WARM: dict[str, float] = {}


def compile_kernels() -> float:
    """Compile (or load from the disk cache) every kernel once in this process, on a tiny world;
    returns the seconds it took (0 after the first call). Called when a compiled world is built,
    so that the compile is set-up time, never planning time."""
    if "s" in _WARM:
        return 0.0
    t = time.perf_counter()
    fields = {k: np.zeros(0) for k in (*FLOAT_FIELDS, *INT_FIELDS, "tab_cells")}
    fields.update(Mc=np.zeros(112), Ms=np.zeros(112), M1=np.zeros(112), rows0=np.zeros(8), rows=np.zeros(9),
                  obs_ctr=np.zeros(3), obs_half=np.zeros(3), obs_rot=np.zeros(9), sph=np.zeros(3), R2=np.full(2, -1.0), rho2=np.full(2, -1.0),
                  row_chain=np.zeros(21), pair_r=np.zeros(2), pair_self=np.zeros(2), d2=np.zeros(2),
                  scratch=np.zeros(SCRATCH), link_end=np.array([0, 1, 1, 1, 1, 1, 1, 1]), s_row=np.zeros(1),
                  ia=np.zeros(2), ib=np.zeros(2), pp=np.zeros(2), pair_b=np.zeros(2), pair_counts=np.zeros(2),
                  pairs=np.zeros(1), is_frame=np.zeros(2), lam_pair=np.zeros(2), pp_part=np.zeros(1),
                  pp_obs=np.full(1, -1), part_link=np.ones(1), fine_start=np.zeros(2), obs_type=np.zeros(1))
    F, I, C = pack(fields, (2, 3, 1, 2, 0, 1, 1, 1))
    q = np.zeros(7)
    state_decide(q, F, I, C)
    batch_decide(np.zeros((1, 7)), True, F, I, C)
    motion_check(q, np.ones(7), 0.5, F, I, C, np.zeros(4, np.bool_), np.zeros(WORK, np.int64))
    _WARM["s"] = time.perf_counter() - t
    log.debug("fcl kernels ready in %.2f s (cache %s)", _WARM["s"], _CACHE)
    return _WARM["s"]
