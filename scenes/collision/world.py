"""The python-fcl collision world, built from the same scene and model files as the Drake scene.

It answers three questions for the sampling planners, the validator and the metrics:
- is a configuration collision-free (robot vs scene, and robot self-collision)?
- what is the signed clearance between robot (with a held can) and scene, in metres?
- is the straight joint-space motion between two configurations free at a given resolution?

A state check costs a fixed, small number of numpy calls (the cost of a call, not the
arithmetic, dominates at this size), then exact FCL queries only for the few pairs nothing
cheaper can decide:

1. Kinematics on points. Every point the checks need (bounding-sphere centres, and the four
   rows of each part's pose) is stored as a homogeneous row in its link's frame; rows are
   ordered from the hand down to the base, so applying the local joint transforms from joint 7
   to joint 1 is seven `np.dot` calls on growing leading blocks of small buffers. A batch of
   states (a motion's samples) chains the joint transforms first and maps each link's rows once.
2. Bounding spheres. Each primitive is covered by spheres (outer radius) that also contain an
   inner ball lying inside the primitive (inner radius). One gather and six array operations
   give the squared distance of every (sphere, obstacle box) and (sphere, sphere) pair (in a
   batch, an obstacle's side is a constant array, not gathered): no
   outer overlap means free; an inner overlap with a true box or another robot part means a
   certain collision.
3. Joint tables. A self pair whose distance depends on one joint only (after dropping a joint
   about whose axis a shape is round, and enclosing a box in the cylinder it sweeps about its
   own joint: link 5 against link 7 or the gripper body depends on q6 only) gets a table of
   that joint's range, proved once per process from FCL signed distances and a Lipschitz bound:
   cells where the pair is apart, or (exact shapes only) in collision, need no query. These are
   the wrist and elbow pairs whose spheres always overlap (flat faces millimetres apart).
   Parts round about joint 1 that never reach an obstacle (link 1) drop those pairs likewise.
4. Exact FCL `collide` for what remains.

None of the shortcuts changes an answer: each one only skips a query whose result it has proved.
The single-state path works in buffers owned by the world: one world per thread.

Filtering mirrors the Drake scene: pairs joined by a joint, the always-touching pairs of
`robot_model.ALWAYS_TOUCHING`, the rigid gripper assembly (link 7, gripper body, fingers, held
can), the base link against the static world, and the held can against the plate it was lifted
from.
"""

from __future__ import annotations

import itertools
import math
from time import perf_counter as _clock

import fcl
import numpy as np

from scenes.collision.build import WorldBuild
from scenes.collision.motion import CHUNK, MotionChecks
from scenes.collision.shapes import G_INDEX, Part, aabb_half_extents, fcl_geometry, grown_dims
from scenes.collision.joint_tables import APART, TOUCHING, UNKNOWN
from scenes.robot_model import RobotModel, load_robot
from scenes.scene import HeldCan, Scene

#: Bodies that form one rigid assembly with the gripper (Drake filters welded assemblies).
GRIPPER_ASSEMBLY = frozenset({"iiwa_link_7", "body", "left_finger", "right_finger", "held_can"})


def robot_parts(robot, opening_m: float, held_can: tuple | None = None) -> list[Part]:
    """The robot's collision parts, each riding on one of the 9 FK bodies (the fingers on the
    gripper's, at `opening_m`), and a held can's cylinder on the gripper: held_can is (X_GC,
    (radius, height)) with any margin already added."""
    finger_X = robot.finger_offsets(opening_m)
    parts: list[Part] = []
    for sh in robot.shapes:
        if sh.body in finger_X:
            body, X_BS = G_INDEX, finger_X[sh.body] @ sh.X_BS
        else:
            body, X_BS = robot.body_index(sh.body), sh.X_BS
        parts.append(Part(sh.body, body, X_BS, sh.kind, sh.dims, robot.X_7G))
    if held_can is not None:
        parts.append(Part("held_can", G_INDEX, held_can[0], "cylinder", tuple(held_can[1]), robot.X_7G))
    return parts


class CollisionWorld(WorldBuild, MotionChecks):
    """Robot + scene collision queries with python-fcl (the numpy reference path; the planners'
    compiled path is `scenes.collision.compiled.CompiledWorld`, which decides the same).

    Args:
        scene: the scene (static boxes from its spec, cans as cylinders).
        robot: the robot model (the scene spec's variant, by default).
        gripper_opening_m: finger opening (the spec's open width by default).
        held: a can carried in the gripper; it is part of the robot and not on the plate.
        removed_can_ids: cans no longer on the plate (already recycled).
        padding_m: every scene obstacle grown by this much (m; 0: the validator's world). A path
            free in a padded world keeps at least that clearance from the scene (at its checked
            states); the robot's own pairs are not padded (its capsules come within millimetres
            of each other in ordinary postures).
    """

    #: which implementation decides (recorded with every planner's statistics)
    engine = "numpy"

    def __init__(
        self,
        scene: Scene,
        *,
        robot: RobotModel | None = None,
        gripper_opening_m: float | None = None,
        held: HeldCan | None = None,
        removed_can_ids=(),
        padding_m: float = 0.0,
    ) -> None:
        self.scene = scene
        self.padding_m = float(padding_m)
        self.robot = robot = robot or load_robot(scene.spec.robot)
        spec = scene.spec
        opening = spec.grasp.open_width_m if gripper_opening_m is None else gripper_opening_m
        self.gripper_opening_m = opening
        self.held = held

        # --- robot parts (every part rides on one of the 9 FK bodies) ---
        held_can = None
        if held is not None:
            spec.require("can", needed_by="a held can")
            m = spec.grasp.held_margin_m
            held_can = (held.X_GC, (spec.can.radius_m + m, spec.can.height_m + 2 * m))
        self.parts = parts = robot_parts(robot, opening, held_can)
        self._req = fcl.CollisionRequest()
        self._dreq = fcl.DistanceRequest(enable_signed_distance=True)

        # --- scene objects, with their axis-aligned boxes (exact for the static boxes) ---
        self.obstacles: list[tuple[str, fcl.CollisionObject]] = []
        obs_c, obs_h, obs_exact = [], [], []
        removed = set(removed_can_ids) | ({held.can.id} if held is not None else set())
        prims = [(o.name, o.shape, o.size_m, o.pose(), o.axis_aligned_box) for o in spec.obstacles()]
        if scene.cans:  # a world without cans has no can model either
            r_can, h_can = spec.can.radius_m, spec.can.height_m
            prims += [(f"can_{c.id}", "cylinder", (r_can, h_can), c.X_WC(), False) for c in scene.cans
                      if c.id not in removed]
        if self.padding_m:
            prims = [(name, shape, grown_dims(shape, size, self.padding_m), X, exact) for name, shape, size, X, exact in prims]
        self._obs_prims = prims  # (name, shape, size, X_WO, axis-aligned box), padding included
        for name, shape, size, X, exact in prims:
            self.obstacles.append((name, fcl.CollisionObject(fcl_geometry(shape, size), fcl.Transform(X[:3, :3], X[:3, 3]))))
            obs_c.append(X[:3, 3].copy())
            obs_h.append(aabb_half_extents(shape, size, X[:3, :3]))
            obs_exact.append(exact)  # only an axis-aligned box is its own bounding box

        # --- which (part, obstacle) and (part, part) pairs count ---
        self_pairs = []
        for i, j in itertools.combinations(range(len(parts)), 2):
            a, b = parts[i].name, parts[j].name
            if a == b or frozenset((a, b)) in robot.filtered_pairs:
                continue
            if a in GRIPPER_ASSEMBLY and b in GRIPPER_ASSEMBLY:
                continue
            self_pairs.append((i, j))
        self.self_pairs = self_pairs
        env_pairs = [
            (i, k)
            for i, p in enumerate(parts)
            if p.name != "iiwa_link_0"  # the base is welded to the static world
            for k, (oname, _) in enumerate(self.obstacles)
            if not (p.name == "held_can" and oname == "plate")  # it rests on the plate at the grasp
            and not self._never_reaches(p, self.obstacles[k][1])
        ]
        self._build_rows()
        self._build_pairs(env_pairs, self_pairs, obs_c, obs_h, obs_exact)
        self._build_fk()
        self._check = self._make_state_check()
        self.checks = 0  # state checks answered, for planner statistics
        self.query_s = 0.0  # seconds spent answering them (two clock reads a call: about 1% of a check)
        self.fcl_calls = 0  # exact FCL collide() calls made for them (the pairs nothing cheaper decided)

    # --- kinematics

    def _state_rows(self, q) -> np.ndarray:
        """World rows (x, y, z) of one configuration: robot rows then obstacle centres (a work buffer)."""
        np.cos(q, out=self._cos)
        np.sin(q, out=self._sin)
        np.dot(self._M, self._cs, out=self._LT_flat)
        for src, LT, dst in self._steps:
            np.dot(src, LT, out=dst)
        return self._rows

    def _batch_rows(self, Q: np.ndarray) -> np.ndarray:
        """World rows of a batch (M, 7): (M, rows, 3).

        The chain's products W_k = LT_k ... LT_1 (each link's frame to the world, x y z columns)
        come first, six small batched products; each link's rows are then mapped once."""
        m = len(Q)
        cs = np.empty((m, 15))
        cs[:, :7] = np.cos(Q)
        cs[:, 7:14] = np.sin(Q)
        cs[:, 14] = 1.0
        LT = (cs @ self._M_full.T).reshape(m, 7, 4, 4)
        out = np.empty((m,) + self._world0.shape)
        e = self._link_end
        W = LT[:, 0, :, :3]
        for k in range(1, 8):
            if k > 1:
                W = np.matmul(LT[:, k - 1], W)
            lo = e[k + 1] if k < 7 else 0
            if e[k] > lo:
                np.matmul(self._rows0[lo : e[k]], W, out=out[:, lo : e[k]])
        out[:, e[1] :] = self._world0[e[1] :]  # link 0's rows (the world frame) and the obstacle centres
        return out

    def _place(self, p: int, rows: np.ndarray) -> fcl.CollisionObject:
        f = self._frame_row[p]
        obj = self.parts[p].obj
        obj.setRotation(np.ascontiguousarray(rows[f : f + 3, :3].T))
        obj.setTranslation(rows[f + 3, :3])
        return obj

    # --- state checks ---------------------------------------------------------------------------

    def _state_d2(self, rows: np.ndarray) -> np.ndarray:
        """Squared distance (P,) of each sphere pair's centre to its partner: an obstacle's box
        (half sizes H) or another sphere's centre (H = 0)."""
        D = self._D
        np.take(rows, self._iab, axis=0, out=self._G, mode="clip")
        np.subtract(self._G[0], self._G[1], out=D)
        np.abs(D, out=D)
        np.subtract(D, self._H, out=D)
        np.maximum(D, self._Z, out=D)
        np.multiply(D, D, out=D)
        return np.dot(D, self._ones3, out=self._d2)

    def _batch_d2(self, rows: np.ndarray) -> np.ndarray:
        """`_state_d2` for a batch of world rows (M, rows, 3): (M, P). A scene pair's partner is
        a fixed obstacle centre, so only the robot side is gathered for those."""
        m, n = rows.shape[:2]
        flat = rows.reshape(m * n, 3)
        idx_a, idx_b = self._batch_index(m, n)
        D = flat.take(idx_a, axis=0).reshape(m, -1, 3)  # row gathers: faster than take(axis=1)
        ne = self._n_env
        D[:, :ne] -= self._env_c
        D[:, ne:] -= flat.take(idx_b, axis=0).reshape(m, -1, 3)
        np.abs(D, out=D)
        D -= self._H
        np.maximum(D, 0.0, out=D)
        D *= D
        return D @ self._ones3

    def _batch_index(self, m: int, n: int) -> tuple[np.ndarray, np.ndarray]:
        """The row indices of a batch of M states of n rows each: every sphere pair's robot side
        (M * P,) and the self pairs' other side (M * (P - scene pairs),)."""
        key = (m, n)
        idx = self._batch_idx.get(key)
        if idx is None:
            off = (n * np.arange(m))[:, None]
            idx = ((self._iab[0][None, :] + off).ravel(), (self._iab[1][None, self._n_env :] + off).ravel())
            if len(self._batch_idx) < 2 * CHUNK:
                self._batch_idx[key] = idx
        return idx

    def _collides(self, rows: np.ndarray, d2: np.ndarray, hits: np.ndarray, unsafe: list[int]) -> bool:
        """Decide one state from its overlapping sphere pairs `hits` and unproved tabled pairs:
        a certain collision by inner balls, else exact FCL."""
        if len(hits) and np.count_nonzero(d2.take(hits) < self._rho2.take(hits)):
            return True
        return self._exact(rows, hits, unsafe)

    def _exact(self, rows: np.ndarray, hits: np.ndarray, unsafe: list[int]) -> bool:
        """True if an FCL query finds a collision in a part-level pair of `hits` or `unsafe`."""
        return self._exact_pairs(rows, set(self._pp.take(hits).tolist()).union(unsafe))

    def _exact_pairs(self, rows: np.ndarray, pairs) -> bool:
        """True if an FCL `collide` finds a collision in one of the part-level pairs (their ids)
        placed by the world rows `rows`; counts the calls in `fcl_calls`."""
        placed: dict[int, fcl.CollisionObject] = {}
        for k in pairs:
            i = self._pp_part[k]
            oi = placed.get(i) or placed.setdefault(i, self._place(i, rows))
            j, other = self._pp_other[k]
            if other is None:
                other = placed.get(j) or placed.setdefault(j, self._place(j, rows))
            self.fcl_calls += 1
            if fcl.collide(oi, other, self._req, fcl.CollisionResult()):
                return True
        return False

    def _make_state_check(self):
        """`check(q) -> bool` (True if free): the single-state path of `is_free`, `_state_rows`
        and `_state_d2` inlined with every array bound as a local (attribute lookups and calls
        are a good part of a 20 us budget)."""
        cos, sin, dot, take = np.cos, np.sin, np.dot, np.take
        subtract, absolute, maximum, multiply = np.subtract, np.abs, np.maximum, np.multiply
        less, less_equal, count_nonzero = np.less, np.less_equal, np.count_nonzero
        cos_q, sin_q, M, cs, LT_flat, rows = self._cos, self._sin, self._M, self._cs, self._LT_flat, self._rows
        (s7, L7, d7), (s6, L6, d6), (s5, L5, d5), (s4, L4, d4), (s3, L3, d3), (s2, L2, d2_), (s1, L1, d1) = self._steps
        iab, G, D, H, Z, ones3 = self._iab, self._G, self._D, self._H, self._Z, self._ones3
        G0, G1 = G[0], G[1]
        d2, R2, rho2, mask = self._d2, self._R2, self._rho2, self._mask
        mask_in = np.empty_like(mask)
        tables, exact = self._tables, self._exact
        ndarray = np.ndarray

        def check(q) -> bool:
            cos(q, cos_q)
            sin(q, sin_q)
            dot(M, cs, LT_flat)
            dot(s7, L7, d7)
            dot(s6, L6, d6)
            dot(s5, L5, d5)
            dot(s4, L4, d4)
            dot(s3, L3, d3)
            dot(s2, L2, d2_)
            dot(s1, L1, d1)
            take(rows, iab, 0, G, "clip")
            subtract(G0, G1, D)
            absolute(D, D)
            subtract(D, H, D)
            maximum(D, Z, out=D)  # (a positional out is deprecated, and slow, for maximum)
            multiply(D, D, D)
            dot(D, ones3, d2)
            hits = less_equal(d2, R2, mask).nonzero()[0]
            ql = q.tolist() if type(q) is ndarray else [float(v) for v in q]
            unsafe = []
            for j, lo, inv, n, cells, k in tables:
                x = (ql[j] - lo) * inv
                c = cells[int(x)] if 0.0 <= x < n else UNKNOWN
                if c != APART:
                    if c == TOUCHING:
                        return False  # a self pair proved in collision in this joint cell
                    unsafe.append(k)
            if not len(hits) and not unsafe:
                return True
            if count_nonzero(less(d2, rho2, mask_in)):
                return False  # an inner ball meets a box or another part's inner ball
            return not exact(rows, hits, unsafe)

        return check

    def is_free(self, q: np.ndarray) -> bool:
        """True if configuration q (7,) rad is free of scene and self collisions."""
        self.checks += 1
        t = _clock()
        free = self._check(q)
        self.query_s += _clock() - t
        return free

    def _scan(self, Q: np.ndarray, *, stop_at_first: bool) -> np.ndarray:
        """Free flags (M,) of a batch; with stop_at_first, states after the first collision are
        left unchecked (reported free)."""
        out = np.ones(len(Q), bool)
        for start in range(0, len(Q), CHUNK):
            free, _ = self._scan_chunk(Q[start : start + CHUNK], stop_at_first=stop_at_first)
            out[start : start + CHUNK] = free
            if stop_at_first and not free.all():
                return out
        return out

    def _scan_chunk(self, Qc: np.ndarray, *, stop_at_first: bool, decide: np.ndarray | None = None):
        """Free flags (M,) of at most CHUNK states and their sphere-pair distances (M, P); only
        the states `decide` marks are decided (the others are reported free)."""
        out = np.ones(len(Qc), bool)
        rows = self._batch_rows(Qc)
        d2 = self._batch_d2(rows)
        near = d2 <= self._R2
        flagged = near.any(axis=1)
        touching = None
        unknown = None
        if len(self._tab_k):
            c = self._table_cells(Qc[:, self._tab_j])
            touching = (c == TOUCHING).any(axis=1)
            unknown = c == UNKNOWN
            flagged |= (c != APART).any(axis=1)
        if decide is not None:
            flagged &= decide
        for m in np.flatnonzero(flagged):
            if touching is not None and touching[m]:
                bad = True
            else:
                unsafe = [] if unknown is None else [self._tab_k[t] for t in np.flatnonzero(unknown[m])]
                bad = self._collides(rows[m], d2[m], near[m].nonzero()[0], unsafe)
            if bad:
                out[m] = False
                if stop_at_first:
                    return out, d2
        return out, d2

    def first_collision(self, Q: np.ndarray) -> int:
        """Index of the first colliding configuration of a batch (M, 7), or -1 if all are free."""
        Q = np.atleast_2d(np.asarray(Q, float))
        self.checks += len(Q)
        t = _clock()
        bad = np.flatnonzero(~self._scan(Q, stop_at_first=True))
        self.query_s += _clock() - t
        return int(bad[0]) if len(bad) else -1

    def states_free(self, Q: np.ndarray) -> np.ndarray:
        """Boolean (M,) array: which configurations of a batch are free."""
        Q = np.atleast_2d(np.asarray(Q, float))
        self.checks += len(Q)
        t = _clock()
        free = self._scan(Q, stop_at_first=False)
        self.query_s += _clock() - t
        return free

    def _table_cells(self, qj: np.ndarray) -> np.ndarray:
        """Every joint table's cell (M, T) for each state's value of the table's joint `qj`
        (M, T): APART, TOUCHING, or UNKNOWN (also outside the table's range)."""
        x = (qj - self._tab_lo) * self._tab_inv  # cell coordinates
        inside = (x >= 0.0) & (x < self._tab_n)
        cell = np.where(inside, x, 0.0).astype(np.intp)
        np.copyto(cell, self._tab_out, where=~inside)  # the UNKNOWN column
        return self._tab_cells.take(cell + self._tab_row0)

    # --- clearance

    def clearance(self, q: np.ndarray) -> float:
        """Signed distance (metres) between the robot (with a held can) and the scene.

        Negative in penetration (FCL's signed distance, enabled explicitly: by default
        python-fcl reports -1 for any colliding pair). Exact FCL distances are computed only for
        pairs whose bounding-sphere lower bound could beat the best found so far. Pairs whose
        distance does not depend on q (the base, and link 1 which only spins about its vertical
        axis, against the static world) are left out: they would cap every path's clearance at
        the same constant (0.0725 m, link 1 over the table) and hide the differences that matter.
        """
        rows = self._state_rows(np.asarray(q, float))
        d2 = self._state_d2(rows)[: self._n_env]
        R2 = self._R2[: self._n_env]
        lb_s = np.where(R2 >= 0, np.sqrt(d2) - np.sqrt(np.abs(R2)), np.inf)
        lb = np.full(self._n_env_pp, np.inf)
        pp = self._pp[: self._n_env]
        np.minimum.at(lb, pp[pp >= 0], lb_s[pp >= 0])
        best = math.inf
        for k in np.argsort(lb):
            # A bound <= 0 may hide any penetration depth: such pairs are always measured.
            if lb[k] >= best and lb[k] > 0:
                break
            obj = self._place(self._pp_part[k], rows)
            dist = fcl.distance(obj, self._pp_other[k][1], self._dreq, fcl.DistanceResult())
            best = min(best, float(dist))
        return best

    def clearances(self, Q: np.ndarray) -> np.ndarray:
        """Signed clearance (metres) of each configuration of a batch (M, 7)."""
        return np.array([self.clearance(q) for q in np.atleast_2d(Q)])
