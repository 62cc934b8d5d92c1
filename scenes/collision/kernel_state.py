"""The python-fcl world's decisions compiled with numba: forward kinematics on the stored rows, the
sphere tiers, the joint tables and the motion proof of `motion_samples_free`.

A state is FREE (no sphere pair overlaps and every tabled pair's cell is proved apart), COLLIDES
(an inner ball meets an obstacle or another part's inner ball, or a tabled pair's cell is proved
touching) or UNDECIDED, with the part-level pairs that FCL's `collide` must decide; that stays in
Python (`scenes.collision.compiled.CompiledWorld`), counted per trial. The answers are the numpy path's
(`scenes.collision.world`); the bounds are sharper, which only decides more pairs without FCL:

- a sphere's distance to an obstacle is exact for the obstacle's kind (a box in its own frame, a
  cylinder, a sphere), where the numpy path bounds every obstacle by its axis-aligned box (the
  window's rotated walls and the cans are not their boxes); so every inner ball counts;
- a scene pair the coarse spheres leave open is tried with the part's fine spheres (spaced a
  quarter of its radius: 0.8% above it) before FCL;
- the motion proof reads the same distance bounds, so it proves at least as many samples free.

No `fastmath`; the joint transforms are built from their three non-zero columns. A motion's
samples are evaluated in one call, the coarsest first, resumable where FCL must decide a sample.
The differential check (`python -m suite bench kernel`, `tests/scenes/collision/test_compiled.py`)
compares the answers with the numpy path's; at the boundary (`--near-contact`) they differ only
at overlaps under 1e-6 m, where FCL's `collide` decides for one of them and misses some.

Compiled once per machine into numba's disk cache (`scenes.collision.kernel_data`); the decision
codes are `scenes.collision.kernel_codes`; the motion check (`scenes.collision.kernel_motion`) calls
this state kernel, and `scenes.collision.compiled.compile_kernels` warms both.
"""

from __future__ import annotations

import numpy as np

from scenes.collision.kernel_codes import (
    AABB,
    APART,
    APART_PAIR,
    COLLIDES,
    CYLINDER,
    FREE,
    OBB,
    SPHERE,
    TOUCHING,
    UNDECIDED,
    UNKNOWN,
)
from scenes.collision.kernel_data import (
    F_D2,
    F_FINE_IN2,
    F_FINE_OUT2,
    F_FINE_ROWS0,
    F_M1,
    F_MC,
    F_MS,
    F_OBS_CTR,
    F_OBS_HALF,
    F_OBS_ROT,
    F_R2,
    F_RHO2,
    F_ROWS,
    F_ROWS0,
    F_SCRATCH,
    F_SPH,
    F_TAB_INV,
    F_TAB_LO,
    F_TAB_N,
    I_FINE_START,
    I_IA,
    I_IB,
    I_IS_FRAME,
    I_LINK_END,
    I_OBS_TYPE,
    I_PAIRS,
    I_PART_LINK,
    I_PP,
    I_PP_OBS,
    I_PP_PART,
    I_S_ROW,
    I_TAB_J,
    I_TAB_K,
    S_NENV,
    S_NPP,
    S_O,
    S_TABW,
    SCR_LT,
    SCR_V,
    SCR_W,
    SCR_WALL,
    SCRATCH,
    _f,
    _i,
    _jit,
)


@_jit
def fk_rows(q, F, I):
    """World rows (x, y, z) of configuration q: the sphere centres' rows into the rows field (the
    rest, link 0's rows and the obstacle centres, is constant); the parts' frame rows, which only
    FCL needs, are left to `fk_frames`.

    Joint k's local transform (transposed: rows multiply from the left) is
    Mc[k] cos q_k + Ms[k] sin q_k + M1[k], the three non-zero columns of the numpy path's M.
    Each link's frame to the world, W_k = LT_k ... LT_1 (x y z columns), then maps its rows."""
    Mc, Ms, M1 = _f(F, I, F_MC), _f(F, I, F_MS), _f(F, I, F_M1)
    rows0, rows, scratch = _f(F, I, F_ROWS0), _f(F, I, F_ROWS), _f(F, I, F_SCRATCH)
    link_end, is_frame = _i(I, I_LINK_END), _i(I, I_IS_FRAME)
    LT = scratch[SCR_LT:SCR_W]
    W = scratch[SCR_W:SCR_V]
    V = scratch[SCR_V:SCR_WALL]
    Wall = scratch[SCR_WALL:SCRATCH]
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
    rows0, rows, scratch = _f(F, I, F_ROWS0), _f(F, I, F_ROWS), _f(F, I, F_SCRATCH)
    link_end, is_frame = _i(I, I_LINK_END), _i(I, I_IS_FRAME)
    Wall = scratch[SCR_WALL:SCRATCH]
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
    rows, d2, sph = _f(F, I, F_ROWS), _f(F, I, F_D2), _f(F, I, F_SPH)
    s_row, ia, ib = _i(I, I_S_ROW), _i(I, I_IA), _i(I, I_IB)
    O, n_env = I[S_O], I[S_NENV]
    S = len(s_row)
    for s in range(S):  # the scene spheres' centres by coordinate
        r = 3 * s_row[s]
        sph[s], sph[S + s], sph[2 * S + s] = rows[r], rows[r + 1], rows[r + 2]
    ctr, half, rot, kind = _f(F, I, F_OBS_CTR), _f(F, I, F_OBS_HALF), _f(F, I, F_OBS_ROT), _i(I, I_OBS_TYPE)
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
    x = (qj - _f(F, I, F_TAB_LO)[t]) * _f(F, I, F_TAB_INV)[t]
    if 0.0 <= x < _f(F, I, F_TAB_N)[t]:
        return C[t * I[S_TABW] + int(x)]
    return UNKNOWN


@_jit
def _fine_pair(F, I, part, o):
    """A scene pair the coarse spheres left open, tried with the part's fine spheres (the same
    kind of cover, spaced closer): APART if none reaches the obstacle, COLLIDES if a fine inner
    ball meets it, else UNDECIDED (FCL's)."""
    rows0f, out2, in2, Wall = _f(F, I, F_FINE_ROWS0), _f(F, I, F_FINE_OUT2), _f(F, I, F_FINE_IN2), _f(F, I, F_SCRATCH)[SCR_WALL:SCRATCH]
    part_link, fine_start = _i(I, I_PART_LINK), _i(I, I_FINE_START)
    O, ctr, half, rot, t = I[S_O], _f(F, I, F_OBS_CTR), _f(F, I, F_OBS_HALF), _f(F, I, F_OBS_ROT), _i(I, I_OBS_TYPE)[o]
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
    return UNDECIDED if hit else APART_PAIR


@_jit
def state_decide(q, F, I, C):
    """One state: FREE, COLLIDES, or UNDECIDED with its part-level pairs for FCL in the pairs
    field [:count]. Returns (decision, count); the rows field holds its world rows and d2 every
    sphere pair's squared distance (all of them unless an early COLLIDES)."""
    n_pp = I[S_NPP]
    marks = np.zeros(n_pp, np.bool_)
    tab_j, tab_k = _i(I, I_TAB_J), _i(I, I_TAB_K)
    for t in range(len(tab_j)):
        c = _table_cell(F, I, C, t, q[tab_j[t]])
        if c == TOUCHING:
            return COLLIDES, 0
        if c != APART:
            marks[tab_k[t]] = True
    fk_rows(q, F, I)
    _d2_all(F, I)
    d2, R2, rho2, pp = _f(F, I, F_D2), _f(F, I, F_R2), _f(F, I, F_RHO2), _i(I, I_PP)
    for p in range(len(d2)):
        if d2[p] <= R2[p]:
            if d2[p] < rho2[p]:
                return COLLIDES, 0
            marks[pp[p]] = True
    pp_part, pp_obs, fine_start = _i(I, I_PP_PART), _i(I, I_PP_OBS), _i(I, I_FINE_START)
    for k in range(n_pp):  # scene pairs: the part's fine spheres may decide them
        o = pp_obs[k]
        if marks[k] and o >= 0 and fine_start[pp_part[k] + 1] > fine_start[pp_part[k]]:
            r = _fine_pair(F, I, pp_part[k], o)
            if r == COLLIDES:
                return COLLIDES, 0
            if r == APART_PAIR:
                marks[k] = False
    pairs = _i(I, I_PAIRS)
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
