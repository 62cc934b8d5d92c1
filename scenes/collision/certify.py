"""Certified motions: an exact collision verdict for straight joint-space segments.

The test of Schwarzer, Saha and Latombe (IEEE T-RO 2005; LaValle, *Planning Algorithms* 5.3.4):
a pair of bodies cannot meet on the straight segment a -> b if

    eta(a) + eta(b) > lambda(a, b),

eta a lower bound on the pair's distance at a configuration and lambda an upper bound on how far
any point of one body moves relative to the other between a and b. Where the test fails the
segment is bisected; a pair proved free on a segment is free on its halves. The check never
misses a collision: every proof is a bound, never a sample.

lambda. Joint j turns a point p about its axis at speed |dq_j| dist(p, axis_j), so along a
straight segment p moves at most sum_j r_j |dq_j|, with r_j any bound on dist(p, axis_j) over
all configurations. For a point of link L and a joint j <= L, `point_axis_radii` bounds it through
the chain of fixed joint offsets (robot_model's X_origin): in link j's frame, whose z axis is
joint j's axis, p = t_{j+1} + R (p in link j+1), so dist <= |xy(t_{j+1})| + |p|_{j+1} and
|p|_k <= |t_{k+1}| + |p|_{k+1}. A pair of robot bodies on links La < Lb moves relatively only
through joints La+1 .. Lb (its distance is the same in link La's frame), so those alone count.

eta, in three tiers, cheapest first:
1. Bounding spheres (the world's covers: every primitive lies inside the union of its outer
   spheres). Per sphere pair the distance of sphere to obstacle box (or to sphere) minus the
   radii is a lower bound, and it changes along the segment by at most the sphere centre's own
   lambda, sharper than the whole body's. A body pair is proved on a segment when every one of its
   sphere pairs is.
2. Joint tables (`scenes.collision.joint_tables`): a self pair whose distance depends on one joint only is
   proved apart cell by cell; a segment whose joint interval stays in proved cells is free.
3. Proved distances between the two primitives at both ends, with the body pair's lambda (the
   largest over its spheres, plus their radius). FCL's GJK distance is only an estimate (seen
   0.3 mm above the truth between two cylinders); a fraction of it is proved by FCL's collide() on
   the moving primitive grown by that much (`Certifier._exact`).

The verdict of a path: `certified` (every segment proved free), `collision` (a state in
collision, by FCL's collide(), with the segment, the position on it, the pair and the depth from
FCL's signed distance), or `unproved` (a segment shorter than FLOOR_RAD still unproved, or the
state budget MAX_STATES spent: the pair and its clearance there are given). The pairs are the
validator's own (`CollisionWorld`): an ignored pair stays ignored.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Any

import fcl
import numpy as np

from scenes.collision.shapes import fcl_geometry, grown_dims
from scenes.collision.joint_tables import APART

#: Bisection stops on a segment shorter than this (max-norm, rad): the pair is `unproved` there.
FLOOR_RAD = 1e-6
#: An FCL distance d is proved as a lower bound f d for the first of these fractions f that a
#: collision query with the grown part confirms (`Certifier._exact`).
PROOF_FRACTIONS = (0.95, 0.7, 0.3)
#: Taken off the sum of two proved distances: rounding in the bound's arithmetic (m).
EXACT_SLACK_M = 1e-9
#: A segment is cut into at most this many pieces at once (as many as its ends' bounds ask for).
MAX_PIECES = 16
#: Segments certified together (bounds the memory of a path with many waypoints).
CHUNK_SEGMENTS = 256
#: At most this many configurations are evaluated for one path; beyond, the verdict is `unproved`.
MAX_STATES = 200_000

CERTIFIED, COLLISION, UNPROVED = "certified", "collision", "unproved"
VERDICTS = (CERTIFIED, COLLISION, UNPROVED)


def point_axis_radii(robot, p_L: np.ndarray, link: int) -> np.ndarray:
    """Upper bounds (7,) on the distance (m) from each joint's axis to point p_L (3,) of link
    `link` (0..7), over every configuration: 0 for the joints that do not move it."""
    r = np.zeros(7)
    if link == 0:
        return r
    norm = float(np.linalg.norm(p_L))  # |p| in link `link`'s frame: its origin is on its joint's axis
    r[link - 1] = float(np.hypot(p_L[0], p_L[1]))
    for j in range(link - 1, 0, -1):  # joint j, axis = z of link j; p in link j+1 at most `norm` from its origin
        t = robot.joints[j].X_origin[:3, 3]  # joint j+1's origin in link j
        r[j - 1] = float(np.hypot(t[0], t[1])) + norm
        norm += float(np.linalg.norm(t))
    return r


@dataclasses.dataclass
class Certificate:
    """A path's exact verdict and what it cost.

    Attributes:
        verdict: `certified`, `collision` or `unproved`.
        segments: straight segments of the path.
        states: configurations whose bounds were evaluated (waypoints and bisection midpoints).
        distance_queries: exact python-fcl distance queries.
        time_s: wall time of the check.
        detail: for `collision`: segment, position t on it (0..1), pair, penetration_m (>= 0: how
            deep the other body reaches into the moving one, to 1 um),
            q; for `unproved`: segment, t, pair, clearance_m there, why.
        min_segment_rad: the shortest segment a proof needed (max-norm, rad).
    """

    verdict: str
    segments: int
    states: int
    distance_queries: int
    time_s: float
    detail: dict[str, Any] | None = None
    min_segment_rad: float | None = None

    def as_record(self) -> dict[str, Any]:
        out = {"verdict": self.verdict, "segments": self.segments, "states": self.states,
               "distance_queries": self.distance_queries, "time_s": round(self.time_s, 6)}
        if self.min_segment_rad is not None:
            out["min_segment_rad"] = float(f"{self.min_segment_rad:.4g}")
        if self.detail is not None:
            out.update(self.detail)
        return out


class Certifier:
    """The certified segment check on a `CollisionWorld`'s own parts, obstacles and pairs."""

    def __init__(self, world) -> None:
        self.world = w = world
        self.robot = w.robot
        e = w._link_end
        n_robot = len(w._rows0)
        row_link = np.zeros(n_robot, int)
        for link in range(7, -1, -1):
            row_link[(e[link + 1] if link < 7 else 0) : e[link]] = link

        # --- sphere pairs the world counts, sorted by body pair; each moves with one centre ---------
        keep = w._pp >= 0
        ia, ib, pp = w._iab[0][keep], w._iab[1][keep], w._pp[keep]
        R = np.sqrt(np.abs(w._R2[keep]))  # outer radius (scene pair) or the sum of both (self pair)
        env = ib >= n_robot
        mover = np.where(env, ia, ib)  # the centre whose motion counts (the upper link's, for self pairs)
        first_joint = np.where(env, 0, row_link[ia])  # joints 1..La move both bodies of a self pair alike
        part_rows = [w._spheres["env"][p][0] for p in range(len(w.parts))]
        centres = np.unique(np.concatenate([mover, *part_rows]))
        col = {int(r): c for c, r in enumerate(centres)}
        self._centres = centres
        self._centre_link = row_link[centres]
        self._chain = w._reach_chain()[centres]  # each centre's lever arms (`point_axis_radii`)
        self._moves = (np.arange(7)[None, :] < self._centre_link[:, None]).astype(float)  # joint j moves centre c
        order = np.argsort(pp, kind="stable")
        self._sp_pp = pp[order]
        self._sp_R = R[order]
        self._sp_c = np.array([col[int(r)] for r in mover[order]], int)
        self._sp_j = first_joint[order]
        self._sp_ia, self._sp_ib = ia[order], ib[order]  # world rows: a centre, and a centre or a box's
        self._sp_H = w._H[keep][order]  # the box's half sizes (0 for a sphere)
        n_pp = len(w._pp_part)
        self._n_pp = n_pp

        # --- tables (self pairs decided by one joint) -----------------------------------------------
        # per table: its joint, range, and the running count of cells not proved apart
        self._tables = [(k, j, lo, inv, n, np.concatenate([[0], np.cumsum(np.frombuffer(bytes(cells), np.uint8) != APART)]))
                        for j, lo, inv, n, cells, k in w._tables]

        # --- body pairs, for exact distances: the moving part's spheres bound its points ------------
        pp_c, pp_R, pp_j, self._names = [], [], [], []
        obstacle_name = {id(obj): name for name, obj in w.obstacles}
        for k in range(n_pp):
            i = w._pp_part[k]
            j, other = w._pp_other[k]
            if other is not None:  # a scene obstacle
                moving, first = i, 0
                self._names.append((w.parts[i].name, obstacle_name[id(other)]))
            else:
                lo, moving = sorted((i, j), key=lambda x: w.parts[x].link)
                first = w.parts[lo].link
                self._names.append((w.parts[i].name, w.parts[j].name))
            rows, outer, _inner = w._spheres["env"][moving]
            pp_c.append(np.array([col[int(r)] for r in rows], int))
            pp_R.append(np.asarray(outer, float))
            pp_j.append(int(first))
        width = max(len(c) for c in pp_c)
        # padded by repeating a pair's first sphere (a repeat leaves the maximum unchanged)
        self._pp_cpad = np.array([np.resize(c, width) for c in pp_c], int)
        self._pp_Rpad = np.array([np.resize(r, width) for r in pp_R], float)
        self._pp_j = np.array(pp_j, int)
        self._dreq = fcl.DistanceRequest()
        self._creq = fcl.CollisionRequest()

    # --- bounds -----------------------------------------------------------------------------------

    def _evaluate(self, Q: np.ndarray, cols: np.ndarray | None = None):
        """For a batch (M, 7): the world rows (M, rows, 3), the sphere-pair distance lower bounds
        (M, S) (only the columns `cols`, if given: NaN elsewhere), and each centre's distance from
        each joint axis (M, C, 7), 0 where the joint does not move it."""
        w = self.world
        rows = w._batch_rows(Q)
        m, n = rows.shape[:2]
        flat = rows.reshape(m * n, 3)
        off = (n * np.arange(m))[:, None]
        ia, ib, H, R = ((self._sp_ia, self._sp_ib, self._sp_H, self._sp_R) if cols is None else
                        (self._sp_ia[cols], self._sp_ib[cols], self._sp_H[cols], self._sp_R[cols]))
        G = np.abs(flat.take((ia[None, :] + off).ravel(), axis=0)
                   - flat.take((ib[None, :] + off).ravel(), axis=0))  # row gathers: fast
        G -= np.tile(H, (m, 1))
        np.maximum(G, 0.0, out=G)
        G *= G
        sub = np.sqrt(G.sum(axis=1)).reshape(m, -1) - R
        if cols is None:
            eta = sub
        else:
            eta = np.full((m, len(self._sp_R)), np.nan)
            eta[:, cols] = sub
        X = self.robot.link_poses(Q)[:, 1:8]  # link j's frame: its z axis is joint j's axis
        c = flat.take((self._centres[None, :] + off).ravel(), axis=0).reshape(m, -1, 1, 3)
        p = c - X[:, None, :, :3, 3]  # (M, C, 7, 3)
        along = (p * X[:, None, :, :3, 2]).sum(axis=-1)  # |z| = 1: |p x z|^2 = |p|^2 - (p.z)^2
        D = np.sqrt(np.maximum((p * p).sum(axis=-1) - along * along, 0.0))
        D *= self._moves
        return rows, eta, D

    def _reach(self, dq: np.ndarray, Da: np.ndarray, Db: np.ndarray) -> np.ndarray:
        """P (n, C, 8): P[s, c, j] bounds how far centre c moves along segment s through joints
        j+1..7 (index j = 0: every joint; P[..., 7] = 0).

        Joint j turns c at speed |dq_j| dist(c, axis_j); along the segment that distance is at most
        its value at an end plus how far c moves relative to link j, which only the later joints do
        (their chain radii times their |dq|).
        """
        W = self._chain[None] * dq[:, None, :]  # (n, C, 7)
        later = np.cumsum(W[..., ::-1], axis=-1)[..., ::-1] - W  # sum over k > j
        T = (np.minimum(Da, Db) + later) * dq[:, None, :]
        P = np.zeros(T.shape[:2] + (8,))
        P[..., :7] = np.cumsum(T[..., ::-1], axis=-1)[..., ::-1]
        return P

    def _pair_lambdas(self, s: np.ndarray, k: np.ndarray, dq: np.ndarray, P: np.ndarray) -> np.ndarray:
        """Bounds (m) on how far any point of body pair k[i]'s moving part moves relative to the
        other along segment s[i] (dq (n, 7), P its `_reach` (n, C, 8)): a point within R of a
        centre c is at most R farther from every axis, so it moves at most
        R sum_j |dq_j| (1 + sum_{k>j} |dq_k|) more than c (over the pair's joints j)."""
        j0 = self._pp_j[k]
        d = dq[s] * (np.arange(7)[None, :] >= j0[:, None])
        after = np.sum(d, axis=1)[:, None] - np.cumsum(d, axis=1)
        extra = np.sum(d * (1.0 + after), axis=1)
        c = self._pp_cpad[k]
        reach = P[s[:, None], c, j0[:, None]]
        return np.max(reach + self._pp_Rpad[k] * extra[:, None], axis=1)

    def _exact(self, k: int, rows: np.ndarray) -> float:
        """A proved lower bound (m) on body pair k's distance in a state's world rows; in
        collision (FCL's collide()), minus how deep the other body reaches into the moving part
        (`_reach_inside`), or -0.0 for a contact of no depth.

        FCL's GJK distance is an estimate (on cylinders it was seen 0.3 mm above the truth), so it
        is not used as a bound. It proposes one: delta = f d for f in PROOF_FRACTIONS, proved by
        FCL's collide() finding the moving part grown by delta (a box by delta on every side, a
        cylinder or capsule in radius and a cylinder in length, which contains every point within
        delta of it) apart from the other body: GJK separates convex shapes only with a
        separating direction, a certificate. 0 when no fraction is proved.
        """
        w = self.world
        i = w._pp_part[k]
        j, other = w._pp_other[k]
        a = w._place(i, rows)
        b = other if other is not None else w._place(j, rows)
        d = float(fcl.distance(a, b, self._dreq, fcl.DistanceResult()))  # -1 when they collide
        part = w.parts[i]
        X = fcl.Transform(a.getRotation(), a.getTranslation())
        if d <= 1e-9:
            if fcl.collide(a, b, self._creq, fcl.CollisionResult()):
                return -self._reach_inside(part, X, b)
            return 0.0
        for f in PROOF_FRACTIONS:
            grown = fcl.CollisionObject(fcl_geometry(part.kind, grown_dims(part.kind, part.dims, f * d)), X)
            if not fcl.collide(grown, b, self._creq, fcl.CollisionResult()):
                return f * d
        return 0.0

    def _reach_inside(self, part, X, other) -> float:
        """How deep (m) `other` reaches into a part placed at X that it collides with: the
        largest delta (to a micrometre) for which the part eroded by delta
        still collides. (FCL's signed distance, EPA, aborts the process on some cylinder pairs.)"""
        lo, hi = 0.0, min(part.dims[: 1 if part.kind != "box" else 3]) / (1 if part.kind != "box" else 2)
        while hi - lo > 1e-6:
            mid = 0.5 * (lo + hi)
            shrunk = fcl.CollisionObject(fcl_geometry(part.kind, grown_dims(part.kind, part.dims, -mid)), X)
            if fcl.collide(shrunk, other, self._creq, fcl.CollisionResult()):
                lo = mid
            else:
                hi = mid
        return lo

    def exact_distance(self, k: int, q: np.ndarray) -> float:
        """`_exact` of body pair k at configuration q (7,): a proved lower bound on its distance
        (m), or minus how deep the other body reaches into the moving part."""
        return self._exact(k, self.world._batch_rows(np.asarray(q, float)[None])[0])

    def _tables_apart(self, qa: np.ndarray, qb: np.ndarray, failing: np.ndarray) -> None:
        """Clear `failing[s, k]` for each tabled pair k proved apart in every cell that segment
        s's joint interval meets (qa, qb (n, 7))."""
        for k, j, lo, inv, n, not_apart in self._tables:
            x0 = (np.minimum(qa[:, j], qb[:, j]) - lo) * inv
            x1 = (np.maximum(qa[:, j], qb[:, j]) - lo) * inv
            inside = (x0 >= 0) & (x1 < n)
            c0 = np.where(inside, x0, 0).astype(int)
            c1 = np.where(inside, x1, 0).astype(int)
            apart = inside & (not_apart[c1 + 1] - not_apart[c0] == 0)
            failing[apart, k] = False

    # --- the check --------------------------------------------------------------------------------

    def certify(self, path: np.ndarray, *, max_states: int = MAX_STATES) -> Certificate:
        """The exact verdict of the piecewise-straight joint path (N, 7), CHUNK_SEGMENTS segments
        at a time (memory stays bounded however many waypoints the path has)."""
        t_start = time.perf_counter()
        path = np.atleast_2d(np.asarray(path, float))
        if len(path) == 1:
            path = np.vstack([path, path])
        n_seg = len(path) - 1
        states = queries = 0
        min_seg = math.inf
        for lo in range(0, n_seg, CHUNK_SEGMENTS):
            verdict, detail, n, k, shortest = self._certify_part(path[lo : lo + CHUNK_SEGMENTS + 1],
                                                                  max_states=max_states - states)
            states, queries, min_seg = states + n, queries + k, min(min_seg, shortest)
            if verdict != CERTIFIED:
                detail["segment"] += lo
                return Certificate(verdict, n_seg, states, queries, time.perf_counter() - t_start, detail,
                                   None if not math.isfinite(min_seg) else min_seg)
        return Certificate(CERTIFIED, n_seg, states, queries, time.perf_counter() - t_start, None,
                           None if not math.isfinite(min_seg) else min_seg)

    def _certify_part(self, path: np.ndarray, *, max_states: int) -> tuple:
        """(verdict, detail, states, exact queries, shortest segment) of a path of at least two
        waypoints; segments numbered from 0 within it."""
        n_seg = len(path) - 1
        rows, eta, D = self._evaluate(path)
        Q, ROWS, ETA, DIST = [path], [rows], [eta], [D]  # blocks of states, appended per level
        exact: dict[tuple[int, int], float] = {}
        queries, n_states, min_seg = 0, len(path), math.inf

        def done(verdict, detail=None):
            return verdict, detail, n_states, queries, min_seg

        # the segments of this level: end states (global indices), path segment, span on it, pairs to prove
        seg_a = np.arange(n_seg)
        seg_b = seg_a + 1
        seg_id = seg_a.copy()
        t0, t1 = np.zeros(n_seg), np.ones(n_seg)
        pending = np.ones((n_seg, self._n_pp), bool)
        while len(seg_a):
            if len(Q) > 1:
                Q, ROWS, ETA, DIST = ([np.concatenate(x)] for x in (Q, ROWS, ETA, DIST))
            allQ, allR, allE, allD = Q[0], ROWS[0], ETA[0], DIST[0]
            qa, qb = allQ[seg_a], allQ[seg_b]
            dq = np.abs(qb - qa)
            P = self._reach(dq, allD[seg_a], allD[seg_b])
            # tier 1: the sphere pairs of the body pairs still to prove, reduced to body pairs (the
            # least margin over a pair's spheres); NaN columns belong to pairs proved before
            cols = np.flatnonzero(pending.any(axis=0)[self._sp_pp])
            body_min = np.full((len(seg_a), self._n_pp), -np.inf)
            if len(cols):
                margin = (allE[seg_a][:, cols] + allE[seg_b][:, cols]
                          - P[:, self._sp_c[cols], self._sp_j[cols]])
                pp_sub = self._sp_pp[cols]
                starts = np.flatnonzero(np.r_[True, pp_sub[1:] != pp_sub[:-1]])
                body_min[:, pp_sub[starts]] = np.minimum.reduceat(margin, starts, axis=1)
            failing = pending & ~(body_min > 0)
            self._tables_apart(qa, qb, failing)  # tier 2
            ent_s, ent_k = np.nonzero(failing)
            split = np.zeros(len(seg_a), bool)
            pieces = np.full(len(seg_a), 2.0)
            if len(ent_s):  # tier 3: exact distances at both ends
                lam = self._pair_lambdas(ent_s, ent_k, dq, P)
                eta_ab = np.empty((len(ent_s), 2))
                for i, (s, k) in enumerate(zip(ent_s.tolist(), ent_k.tolist())):
                    for side, g in enumerate((int(seg_a[s]), int(seg_b[s]))):
                        d = exact.get((g, k))
                        if d is None:
                            d = exact[(g, k)] = self._exact(k, allR[g])
                            queries += 1
                        if d < 0.0 or math.copysign(1.0, d) < 0:
                            return done(COLLISION, {
                                "segment": int(seg_id[s]), "t": float(t1[s] if side else t0[s]),
                                "pair": list(self._names[k]), "penetration_m": abs(d), "q": allQ[g].round(9).tolist()})
                        eta_ab[i, side] = d
                room = eta_ab.sum(axis=1) - 2 * EXACT_SLACK_M
                proved = room > lam
                failing[ent_s[proved], ent_k[proved]] = False
                split[ent_s[~proved]] = True
                # how many pieces the bounds at the ends ask for (at least halves)
                need = np.where(room > 0, lam / np.maximum(room, 1e-300), 2.0)
                np.maximum.at(pieces, ent_s[~proved], np.minimum(np.ceil(need[~proved]), MAX_PIECES))
            if not np.any(split):
                break
            # bisect the segments with pairs still unproved; their halves inherit only those pairs
            idx = np.flatnonzero(split)
            seg_len = np.max(dq[idx], axis=1)
            min_seg = min(min_seg, float(np.min(seg_len)))
            floor = seg_len < FLOOR_RAD
            if np.any(floor) or n_states + len(idx) > max_states:
                s = int(idx[np.argmax(floor)] if np.any(floor) else idx[0])
                k = int(np.flatnonzero(failing[s])[0])
                clr = min(exact.get((int(seg_a[s]), k), math.nan), exact.get((int(seg_b[s]), k), math.nan))
                why = (f"a segment of {seg_len.min():.2g} rad, below the {FLOOR_RAD:g} rad floor"
                       if np.any(floor) else f"the budget of {max_states} states was spent")
                return done(UNPROVED, {"segment": int(seg_id[s]), "t": float(0.5 * (t0[s] + t1[s])),
                                       "pair": list(self._names[k]), "clearance_m": clr, "why": why})
            # cut each into the pieces its ends' bounds ask for (bisection when they say nothing)
            m = pieces[idx].astype(int)
            owner = np.repeat(idx, m - 1)
            f = np.concatenate([np.arange(1, k) / k for k in m])
            new_q = qa[owner] + f[:, None] * (qb[owner] - qa[owner])
            g_new = len(allQ) + np.arange(len(owner))
            need = np.flatnonzero(failing[idx].any(axis=0)[self._sp_pp])  # what the new states are used for
            for block, new in zip((Q, ROWS, ETA, DIST), (new_q, *self._evaluate(new_q, need))):
                block.append(new)
            n_states += len(owner)
            first = np.concatenate([[0], np.cumsum(m - 1)[:-1]])  # each owner's first new state
            # the pieces: ends a, new states in order, b
            a_list, b_list, own = [], [], []
            for i, s in enumerate(idx.tolist()):
                ends = [int(seg_a[s]), *(g_new[first[i] : first[i] + m[i] - 1].tolist()), int(seg_b[s])]
                a_list += ends[:-1]
                b_list += ends[1:]
                own += [s] * m[i]
            own = np.array(own, int)
            ft = np.concatenate([np.arange(k + 1) / k for k in m])
            tt = t0[np.repeat(idx, m + 1)] + ft * (t1 - t0)[np.repeat(idx, m + 1)]
            keep_lo = np.ones(len(tt), bool)
            keep_lo[np.cumsum(m + 1) - 1] = False  # the last point of each run is no piece's start
            keep_hi = np.ones(len(tt), bool)
            keep_hi[np.concatenate([[0], np.cumsum(m + 1)[:-1]])] = False
            seg_a, seg_b = np.array(a_list, int), np.array(b_list, int)
            seg_id = seg_id[own]
            t0, t1 = tt[keep_lo], tt[keep_hi]
            pending = failing[own]
        return done(CERTIFIED)


def certifier(world) -> Certifier:
    """The certifier of a world (built once and kept on it)."""
    c = getattr(world, "_certifier", None)
    if c is None:
        c = Certifier(world)
        world._certifier = c
    return c
