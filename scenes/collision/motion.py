"""The motion checks of `scenes.collision.world.CollisionWorld`: straight joint-space motions sampled at
a joint resolution, checked sample by sample (`motion_free`, `path_free`, the validator's rule) or
with proved skips (`motion_samples_free`, the planners' check: the same answers, fewer states).
A mixin: it works on the world's rows, pairs and joint tables (`scenes.collision.build`)."""

from __future__ import annotations

import functools
import math
from time import perf_counter as _clock

import numpy as np

from scenes.collision.joint_tables import APART, TOUCHING, UNKNOWN

#: States per chunk in the batched checks (bounds memory; a colliding early chunk ends the scan).
CHUNK = 64


#: How many samples of a motion (its end and the coarsest first) the first batched query of
#: `motion_samples_free` takes.
COARSE_BATCH = 8


@functools.lru_cache(maxsize=4096)
def check_order(n: int) -> np.ndarray:
    """Sample indices 1..n of a motion in checking order: the end state n, then the others
    coarsest first (by the power of two dividing them), so a blocked motion fails early."""
    i = np.arange(1, n)
    ctz = np.zeros(len(i), int)
    m = i.copy()
    while np.any(m % 2 == 0):
        even = m % 2 == 0
        ctz[even] += 1
        m[even] //= 2
    order = i[np.lexsort((i, -ctz))]
    return np.concatenate([[n], order])


class MotionChecks:
    """Straight motions and paths through a collision world (mixed into `CollisionWorld`)."""

    @staticmethod
    def segment_steps(path: np.ndarray, resolution_rad: float) -> np.ndarray:
        """Steps (N - 1,) of each straight segment of a path (N, 7) at a joint resolution:
        max(1, ceil(max_j |dq_j| / resolution_rad)); the segment is checked at each step's end."""
        d = np.max(np.abs(np.diff(np.atleast_2d(np.asarray(path, float)), axis=0)), axis=1)
        return np.maximum(1, np.ceil(d / resolution_rad)).astype(int)

    @staticmethod
    def interpolate(path: np.ndarray, resolution_rad: float) -> np.ndarray:
        """Straight joint-space segments between waypoints, sampled so that no joint moves more
        than `resolution_rad` between consecutive samples. Includes every waypoint."""
        path = np.atleast_2d(np.asarray(path, float))
        if len(path) == 1:
            return path.copy()
        out = [path[:1]]
        for a, b, n in zip(path[:-1], path[1:], MotionChecks.segment_steps(path, resolution_rad).tolist()):
            t = np.arange(1, n + 1)[:, None] / n
            seg = a + t * (b - a)
            seg[-1] = b  # exactly the waypoint (a + 1 * (b - a) may differ from b in the last bit)
            out.append(seg)
        return np.vstack(out)

    def motion_free(self, q0: np.ndarray, q1: np.ndarray, *, resolution_rad: float) -> bool:
        """True if the straight motion q0 -> q1 is free at the given joint resolution."""
        return self.first_collision(self.interpolate(np.array([q0, q1]), resolution_rad)[1:]) < 0

    def motion_samples_free(self, q0: np.ndarray, q1: np.ndarray, *, resolution_rad: float) -> bool:
        """The planners' motion check: True if every sample q0 + (i / n)(q1 - q0), i = 1..n,
        n = max(1, ceil(max_j |q1_j - q0_j| / resolution_rad)), is free; q0 is taken as free (as
        OMPL's motion validators do). The same answer as checking every sample, with fewer states:

        1. q0, the end and the coarsest samples (`check_order`) are evaluated in one batch; a
           collision among the samples ends it.
        2. Each evaluated state proves its neighbours free: a sphere pair's distance bound d (its
           centres' distance minus the radii) can shrink by at most lambda per sample step, where
           lambda bounds how far the pair's centres move per step (`point_axis_radii`: every
           joint's largest lever arm on the centre, times its step; both centres for a self pair).
           So all samples within d / lambda steps keep every sphere pair apart. Self pairs
           decided by a joint table are looked up at every sample; an undecided cell leaves that
           sample to be evaluated.
        3. The samples nothing proved are evaluated (in batches, stopping at a collision).
        """
        q0 = np.asarray(q0, float)
        d = np.asarray(q1, float) - q0
        n = max(1, math.ceil(float(np.max(np.abs(d))) / resolution_rad))
        t = _clock()
        try:
            return self._motion_samples_free(q0, d, n)
        finally:
            self.query_s += _clock() - t

    def _motion_samples_free(self, q0: np.ndarray, d: np.ndarray, n: int) -> bool:
        head = check_order(n)[:COARSE_BATCH]
        idx = np.concatenate([[0], head])
        Q = q0 + (idx / n)[:, None] * d
        self.checks += len(idx)
        decide = np.ones(len(idx), bool)
        decide[0] = False  # q0: only its distances are wanted
        free, d2 = self._scan_chunk(Q, stop_at_first=True, decide=decide)
        if not free.all():
            return False
        if len(head) == n:
            return True
        # how many steps each evaluated state proves free on either side
        lam = self._reach_chain() @ np.abs(d / n)
        lam_pair = lam.take(self._iab[0]) + lam.take(self._pair_b) * self._pair_self
        margin = np.sqrt(d2) - self._pair_r
        with np.errstate(divide="ignore", invalid="ignore"):
            steps = np.where(self._pair_counts & (lam_pair > 0), margin / lam_pair, np.inf)
        reach = np.floor(np.min(steps, axis=1) - 1e-9)
        todo = np.ones(n + 1, bool)
        for i, k in zip(idx.tolist(), reach.tolist()):
            if k >= 1:
                k = int(k)
                todo[max(i - k, 0) : i + k + 1] = False
        todo[idx] = False  # evaluated already (q0 among them)
        if len(self._tab_k):
            c = self._table_cells(q0[self._tab_j] + (np.arange(n + 1) / n)[:, None] * d[self._tab_j])
            c[0] = APART  # q0 is taken as free
            if np.any(c == TOUCHING):
                return False  # a sample where a self pair is proved in collision
            unknown = (c == UNKNOWN).any(axis=1)
            unknown[idx] = False  # evaluated in full already
            todo |= unknown
        rest = np.flatnonzero(todo)
        if not len(rest):
            return True
        self.checks += len(rest)
        Q = q0 + (rest / n)[:, None] * d
        for start in range(0, len(Q), CHUNK):
            if not self._scan_chunk(Q[start : start + CHUNK], stop_at_first=True)[0].all():
                return False
        return True

    def _reach_chain(self) -> np.ndarray:
        """Per world row (robot rows, then obstacle centres: 0), bounds (7,) on each joint's lever
        arm on that point over every configuration (`point_axis_radii`); built once."""
        if self._row_chain is None:
            from scenes.collision.certify import point_axis_radii

            e = self._link_end
            chain = np.zeros((len(self._world0), 7))
            for link in range(1, 8):
                lo = e[link + 1] if link < 7 else 0
                for r in range(lo, e[link]):
                    chain[r] = point_axis_radii(self.robot, self._rows0[r, :3], link)
            self._row_chain = chain
        return self._row_chain

    def path_free(self, path: np.ndarray, *, resolution_rad: float) -> int:
        """-1 if the whole piecewise-straight path is free, else the index of the first bad sample
        of `interpolate(path, resolution_rad)`."""
        return self.first_collision(self.interpolate(path, resolution_rad))
