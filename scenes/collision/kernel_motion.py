"""The compiled motion check (`motion_check`): the samples of a straight motion decided with the
state kernel of `scenes.collision.kernel_state`, the coarsest first, neighbours proved free by their
distance bounds, resumable where FCL must decide a sample; as `MotionChecks._motion_samples_free`
decides. Where a check stands lives in its work array (`scenes.collision.kernel_codes.WORK`)."""

from __future__ import annotations

import numpy as np

from scenes.collision.kernel_codes import (
    COLLIDES,
    FREE,
    NEED_SPACE,
    PHASE_HEAD,
    PHASE_REST,
    PHASE_START,
    TOUCHING,
    UNDECIDED,
    UNKNOWN,
    WS_AT,
    WS_HEAD,
    WS_N,
    WS_N_HEAD,
    WS_PHASE,
    WS_REACH,
    WS_STATES,
)
from scenes.collision.kernel_data import (
    F_D2,
    F_LAM_PAIR,
    F_PAIR_R,
    F_PAIR_SELF,
    F_ROW_CHAIN,
    I_IA,
    I_PAIR_B,
    I_PAIR_COUNTS,
    I_TAB_J,
    S_P,
    S_RT,
    _f,
    _i,
    _jit,
)
from scenes.collision.kernel_state import _d2_all, _table_cell, fk_rows, state_decide


@_jit
def _reach(F, I, lam_pair, n):
    """How many sample steps a state's distances prove free on either side: the floor of the least
    (distance bound / lambda) over the counting pairs, minus 1e-9, as the numpy path computes it,
    capped at n + 1 (a reach beyond the motion proves nothing more). A pair whose squared distance
    shows it cannot lower the least so far skips its square root."""
    d2, pair_r, pair_counts = _f(F, I, F_D2), _f(F, I, F_PAIR_R), _i(I, I_PAIR_COUNTS)
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


@_jit
def _head_order(n, ws):
    """The motion's first samples, as `scenes.collision.motion.check_order(n)[:8]`: the end n, then
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
    ws[WS_N_HEAD] = k


@_jit
def motion_check(q0, q1, resolution, F, I, C, todo, ws):
    """The planners' motion check of q0 -> q1 (samples q0 + (i / n)(q1 - q0), i = 1..n,
    n = max(1, ceil(max_j |q1_j - q0_j| / resolution)); q0 taken as free), decided as
    `MotionChecks._motion_samples_free` does: q0 and the head (the end and the coarsest samples)
    first, their distance bounds proving neighbours free, the joint tables looked up at every
    sample, then the samples nothing proved, in order.

    Resumable: it returns at the first sample it leaves UNDECIDED (its rows and pairs in F and I,
    the pair count returned) and, called again with the same `ws`, continues after it; set
    ws[WS_PHASE] = PHASE_START to start a motion. Returns (FREE: the motion is free, COLLIDES, or
    UNDECIDED, pairs); ws[WS_STATES] counts the states evaluated."""
    P, Rt = I[S_P], I[S_RT]
    lam_pair = _f(F, I, F_LAM_PAIR)
    q = np.empty(7)
    d = np.empty(7)
    for j in range(7):
        d[j] = q1[j] - q0[j]
    if ws[WS_PHASE] == PHASE_START:
        ws[WS_STATES] = 0
        big = 0.0
        for j in range(7):
            if abs(d[j]) > big:
                big = abs(d[j])
        n = np.int64(np.ceil(big / resolution))
        if n < 1:
            n = 1
        ws[WS_N] = n
        if n + 1 > len(todo):
            return NEED_SPACE, 0  # the caller gives a `todo` of at least ws[WS_N] + 1 and calls again
        ws[WS_AT], ws[WS_STATES] = 0, 1
        _head_order(n, ws)
        ia, pair_b = _i(I, I_IA), _i(I, I_PAIR_B)
        row_chain, pair_self = _f(F, I, F_ROW_CHAIN), _f(F, I, F_PAIR_SELF)
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
        ws[WS_PHASE] = PHASE_HEAD
    n, n_head = ws[WS_N], ws[WS_N_HEAD]
    if ws[WS_PHASE] == PHASE_HEAD:
        for h in range(ws[WS_AT], n_head):
            i = ws[WS_HEAD + h]
            for j in range(7):
                q[j] = q0[j] + (i / n) * d[j]
            ws[WS_STATES] += 1
            code, count = state_decide(q, F, I, C)
            if code == COLLIDES:
                return COLLIDES, 0
            ws[WS_REACH + 1 + h] = _reach(F, I, lam_pair, n)
            if code == UNDECIDED:
                ws[WS_AT] = h + 1
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
        tab_j = _i(I, I_TAB_J)
        if len(tab_j):
            for m in range(1, n + 1):
                unknown = False
                for t in range(len(tab_j)):
                    j = tab_j[t]
                    c = _table_cell(F, I, C, t, q0[j] + (m / n) * d[j])
                    if c == TOUCHING:
                        return COLLIDES, 0
                    if c == UNKNOWN:
                        unknown = True
                if unknown:
                    todo[m] = True
        todo[0] = False
        for h in range(n_head):
            todo[ws[WS_HEAD + h]] = False  # evaluated already
        ws[WS_PHASE], ws[WS_AT] = PHASE_REST, 1
    for m in range(ws[WS_AT], n + 1):
        if not todo[m]:
            continue
        for j in range(7):
            q[j] = q0[j] + (m / n) * d[j]
        ws[WS_STATES] += 1
        code, count = state_decide(q, F, I, C)
        if code != FREE:
            ws[WS_AT] = m + 1
            return code, count
    return FREE, 0
