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

import functools
import itertools
import math
from time import perf_counter as _clock

import fcl
import numpy as np

from scenes.fcl_shapes import G_INDEX, Part, aabb_half_extents, cover_spheres, fcl_geometry, grown_dims
from scenes.fcl_tables import APART, TABLE_MARGIN_M, TOUCHING, UNKNOWN, on_axis, pair_table
from scenes.robot_model import RobotModel, load_robot
from scenes.scene import HeldCan, Scene

#: Bodies that form one rigid assembly with the gripper (Drake filters welded assemblies).
GRIPPER_ASSEMBLY = frozenset({"iiwa_link_7", "body", "left_finger", "right_finger", "held_can"})

#: Spacing of the spheres covering a cylinder or capsule along its axis, as a fraction of its
#: radius (outer radius sqrt(1 + f^2 / 4) r: 7% above r for f = 0.75), for pairs with the scene
#: (fine: the scene is where most near misses happen) and between robot parts (coarse: few pairs).
ENV_SPACING = 0.75
SELF_SPACING = 2.0
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


class CollisionWorld:
    """Robot + scene collision queries with python-fcl.

    Args:
        scene: the scene (static boxes from its spec, cans as cylinders).
        robot: the robot model (the project's own, by default).
        gripper_opening_m: finger opening (the spec's open width by default).
        held: a can carried in the gripper; it is part of the robot and not on the plate.
        removed_can_ids: cans no longer on the plate (already recycled).
        padding_m: every scene obstacle grown by this much (m; 0: the validator's world). A path
            free in a padded world keeps at least that clearance from the scene (at its checked
            states); the robot's own pairs are not padded (its capsules come within millimetres
            of each other in ordinary postures).
    """

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
        self.robot = robot = robot or load_robot()
        spec = scene.spec
        opening = spec.grasp.open_width_m if gripper_opening_m is None else gripper_opening_m
        self.gripper_opening_m = opening
        self.held = held
        finger_X = robot.finger_offsets(opening)

        # --- robot parts (every part rides on one of the 9 FK bodies) ---
        parts: list[Part] = []
        for sh in robot.shapes:
            if sh.body in finger_X:
                body, X_BS = G_INDEX, finger_X[sh.body] @ sh.X_BS
            else:
                body, X_BS = robot.body_index(sh.body), sh.X_BS
            parts.append(Part(sh.body, body, X_BS, sh.kind, sh.dims, robot.X_7G))
        if held is not None:
            m = spec.grasp.held_margin_m
            can_dims = (spec.can.radius_m + m, spec.can.height_m + 2 * m)
            parts.append(Part("held_can", G_INDEX, held.X_GC, "cylinder", can_dims, robot.X_7G))
        self.parts = parts
        self._req = fcl.CollisionRequest()
        self._dreq = fcl.DistanceRequest(enable_signed_distance=True)

        # --- scene objects, with their axis-aligned boxes (exact for the static boxes) ---
        self.obstacles: list[tuple[str, fcl.CollisionObject]] = []
        obs_c, obs_h, obs_exact = [], [], []
        removed = set(removed_can_ids) | ({held.can.id} if held is not None else set())
        r_can, h_can = spec.can.radius_m, spec.can.height_m
        prims = [(o.name, o.shape, o.size_m, o.pose(), o.axis_aligned_box) for o in spec.obstacles()]
        prims += [(f"can_{c.id}", "cylinder", (r_can, h_can), c.X_WC(), False) for c in scene.cans if c.id not in removed]
        if self.padding_m:
            prims = [(name, shape, grown_dims(shape, size, self.padding_m), X, exact) for name, shape, size, X, exact in prims]
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

    # --- construction -----------------------------------------------------------------------------

    def _never_reaches(self, part: Part, obstacle: fcl.CollisionObject) -> bool:
        """True if a part round about joint 1's axis (so the same set in space for every q1, e.g.
        link 1's capsule) is apart from the obstacle: the pair can be left out."""
        if part.link != 1 or not on_axis(part.prim, self.robot.joints[0].X_origin):
            return False
        X = self.robot.link_poses(np.zeros(7))[1] @ part.X_LS
        part.obj.setTransform(fcl.Transform(X[:3, :3], X[:3, 3]))
        d = float(fcl.distance(part.obj, obstacle, self._dreq, fcl.DistanceResult()))
        return d > TABLE_MARGIN_M

    def _build_rows(self) -> None:
        """Homogeneous rows in link frames, hand first: each part's pose columns, its spheres for
        the scene pairs, its spheres for the self pairs."""
        rows: list[np.ndarray] = []
        n = len(self.parts)
        self._frame_row = [0] * n
        self._spheres: dict[str, list] = {"env": [None] * n, "self": [None] * n}  # (rows, outer, inner)
        link_end = [0] * 8
        for link in range(7, -1, -1):
            for p, part in enumerate(self.parts):
                if part.link != link:
                    continue
                self._frame_row[p] = len(rows)
                rows.extend(part.X_LS.T)  # R[:, 0], R[:, 1], R[:, 2] (w = 0) and p (w = 1)
                for use, spacing in (("env", ENV_SPACING), ("self", SELF_SPACING)):
                    c, outer, inner = cover_spheres(part.kind, part.dims, spacing)
                    c_L = c @ part.X_LS[:3, :3].T + part.X_LS[:3, 3]
                    self._spheres[use][p] = (np.arange(len(rows), len(rows) + len(c)), outer, inner)
                    rows.extend(np.column_stack([c_L, np.ones(len(c))]))
            link_end[link] = len(rows)
        self._rows0 = np.array(rows, float)
        self._link_end = link_end

    def _build_pairs(self, env_pairs, self_pairs, obs_c, obs_h, obs_exact) -> None:
        """Sphere-level pairs as index arrays into the world rows (robot rows, then the
        obstacles' box centres): scene pairs as a spheres x obstacles grid, then self pairs.
        Each part-level pair gets an id; self pairs with a table leave the sphere test to it."""
        self._pp_part: list[int] = []
        self._pp_other: list[tuple[int, fcl.CollisionObject | None]] = []

        def new_pair(i, other) -> int:
            self._pp_part.append(i)
            self._pp_other.append(other)
            return len(self._pp_part) - 1

        n_obs = len(self.obstacles)
        self._obs_row0 = len(self._rows0)
        env_parts = sorted({i for i, _ in env_pairs})
        env_rows = np.concatenate([self._spheres["env"][i][0] for i in env_parts])
        outer_e = np.concatenate([self._spheres["env"][i][1] for i in env_parts])
        inner_e = np.concatenate([self._spheres["env"][i][2] for i in env_parts])
        part_e = np.concatenate([[i] * len(self._spheres["env"][i][0]) for i in env_parts]).astype(int)
        S = len(env_rows)
        pp_grid = np.full((len(self.parts), n_obs), -1)
        for i, k in env_pairs:
            pp_grid[i, k] = new_pair(i, (-1, self.obstacles[k][1]))
        self._n_env_pp = len(self._pp_part)
        pp_env = pp_grid[part_e]  # (S, O); -1 where the pair does not count
        allowed = pp_env >= 0
        R2_env = np.where(allowed, outer_e[:, None] ** 2, -1.0)
        exact = np.asarray(obs_exact)[None, :]  # a can's box only bounds the can: no inner test
        rho2_env = np.where(allowed & exact, inner_e[:, None] ** 2, -1.0)
        ia = [np.repeat(env_rows, n_obs)]
        ib = [np.tile(self._obs_row0 + np.arange(n_obs), S)]
        h = [np.tile(np.asarray(obs_h, float), (S, 1))]
        r2, rho2, pp = [R2_env.ravel()], [rho2_env.ravel()], [pp_env.ravel()]
        self._n_env = S * n_obs
        tables = []
        for i, j in self_pairs:
            a, b = self.parts[i], self.parts[j]
            if a.link > b.link:
                i, j, a, b = j, i, b, a
            table = None if "held_can" in (a.name, b.name) else pair_table(self.robot, a.prim, b.prim)
            if table is not None and table.always_apart:
                continue  # they never touch within the joint limits
            k = new_pair(i, (j, None))
            if table is not None:
                tables.append((table.joint, table.lower_rad, table.cells_per_rad, len(table.cells), table.cells, k))
                continue
            (ri, oi, ni), (rj, oj, nj) = self._spheres["self"][i], self._spheres["self"][j]
            si, sj = np.meshgrid(ri, rj, indexing="ij")
            ia.append(si.ravel())
            ib.append(sj.ravel())
            h.append(np.zeros((si.size, 3)))
            r2.append(np.add.outer(oi, oj).ravel() ** 2)
            rho2.append(np.add.outer(ni, nj).ravel() ** 2)
            pp.append(np.full(si.size, k))
        self._tables = tables
        self._iab = np.stack([np.concatenate(ia), np.concatenate(ib)]).astype(np.intp)
        self._H = np.concatenate(h)
        self._R2 = np.concatenate(r2)
        self._rho2 = np.concatenate(rho2)
        self._pp = np.concatenate(pp).astype(np.intp)
        P = len(self._R2)
        self._obs_c = np.asarray(obs_c, float)
        # work buffers of the single-state path
        self._G = np.empty((2, P, 3))
        self._D = np.empty((P, 3))
        self._Z = np.zeros((P, 3))
        self._d2 = np.empty(P)
        self._mask = np.empty(P, bool)
        self._ones3 = np.ones(3)
        self._batch_idx: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}
        # for the motion check's proved skips: each pair's radius (sum of radii for a self pair),
        # whether it counts, and a self pair's second centre
        self._pair_r = np.sqrt(np.abs(self._R2))
        self._pair_counts = self._R2 >= 0
        self._pair_self = (np.arange(P) >= self._n_env).astype(float)
        self._pair_b = np.where(np.arange(P) >= self._n_env, self._iab[1], 0)
        self._row_chain: np.ndarray | None = None
        self._env_c = self._obs_c[self._iab[1, : self._n_env] - self._obs_row0]  # each scene pair's obstacle centre
        # the joint tables as arrays, for the batched checks: one lookup for every table at once
        T = len(tables)
        self._tab_j = np.array([t[0] for t in tables], np.intp)
        self._tab_lo = np.array([t[1] for t in tables], float)
        self._tab_inv = np.array([t[2] for t in tables], float)
        self._tab_n = np.array([t[3] for t in tables], float)
        self._tab_k = [t[5] for t in tables]
        width = max([t[3] for t in tables], default=0) + 1
        cells = np.full((T, width), UNKNOWN, np.uint8)  # the last column: outside the table's range
        for r, t in enumerate(tables):
            cells[r, : t[3]] = np.frombuffer(bytes(t[4]), np.uint8)
        self._tab_cells = cells.ravel()
        self._tab_row0 = width * np.arange(T)
        self._tab_out = np.array([t[3] for t in tables], np.intp)

    def _build_fk(self) -> None:
        """Local joint transforms from [cos q, sin q, 1] by one product, and the FK buffers.

        X_origin Rz(q) = O Ec cos q + O Es sin q + O E1, stored transposed (rows multiply from
        the left): joints 2..7 as 4 x 4, joint 1 as 4 x 3 (its product is the world rows, x y z).
        Step k (joint k) maps rows of links >= k from link k to link k-1: it reads buffer k, whose
        rows beyond link k+1's are link k's own constant rows, and writes the leading rows of
        buffer k-1, so no buffer ever needs restoring.
        """
        Ec = np.diag([1.0, 1.0, 0.0, 0.0])
        Es = np.zeros((4, 4))
        Es[0, 1], Es[1, 0] = -1.0, 1.0
        E1 = np.diag([0.0, 0.0, 1.0, 1.0])
        M_full = np.zeros((7 * 16, 15))
        for k, joint in enumerate(self.robot.joints):
            O = joint.X_origin
            for col, E in ((k, Ec), (7 + k, Es), (14, E1)):
                M_full[16 * k : 16 * k + 16, col] = (O @ E).T.ravel()
        self._M_full = M_full
        first = M_full[:16].reshape(4, 4, 15)[:, :3].reshape(12, 15)  # joint 1, x y z columns only
        self._M = np.vstack([M_full[16:], first])
        self._cs = np.zeros(15)
        self._cs[14] = 1.0
        self._cos, self._sin = self._cs[:7], self._cs[7:14]
        LT = np.empty(6 * 16 + 12)
        self._LT_flat = LT
        LTk = {k: LT[16 * (k - 2) : 16 * (k - 1)].reshape(4, 4) for k in range(2, 8)}
        LTk[1] = LT[96:].reshape(4, 3)
        e = self._link_end
        n_robot = len(self._rows0)
        bufs = {k: self._rows0[: e[k]].copy() for k in range(1, 8)}
        world = np.empty((n_robot + len(self._obs_c), 3))
        world[e[1] : n_robot] = self._rows0[e[1] :, :3]  # link 0 is the world frame
        world[n_robot:] = self._obs_c
        self._world0 = world.copy()
        self._steps = [(bufs[k], LTk[k], bufs[k - 1][: e[k]]) for k in range(7, 1, -1)]
        self._steps.append((bufs[1], LTk[1], world[: e[1]]))
        self._rows = world

    # --- kinematics -----------------------------------------------------------------------------

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
        placed: dict[int, fcl.CollisionObject] = {}
        for k in set(self._pp.take(hits).tolist()).union(unsafe):
            i = self._pp_part[k]
            oi = placed.get(i) or placed.setdefault(i, self._place(i, rows))
            j, other = self._pp_other[k]
            if other is None:
                other = placed.get(j) or placed.setdefault(j, self._place(j, rows))
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

    # --- motions --------------------------------------------------------------------------------

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
        for a, b, n in zip(path[:-1], path[1:], CollisionWorld.segment_steps(path, resolution_rad).tolist()):
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

    def _table_cells(self, qj: np.ndarray) -> np.ndarray:
        """Every joint table's cell (M, T) for each state's value of the table's joint `qj`
        (M, T): APART, TOUCHING, or UNKNOWN (also outside the table's range)."""
        x = (qj - self._tab_lo) * self._tab_inv  # cell coordinates
        inside = (x >= 0.0) & (x < self._tab_n)
        cell = np.where(inside, x, 0.0).astype(np.intp)
        np.copyto(cell, self._tab_out, where=~inside)  # the UNKNOWN column
        return self._tab_cells.take(cell + self._tab_row0)

    def _reach_chain(self) -> np.ndarray:
        """Per world row (robot rows, then obstacle centres: 0), bounds (7,) on each joint's lever
        arm on that point over every configuration (`point_axis_radii`); built once."""
        if self._row_chain is None:
            from scenes.fcl_certify import point_axis_radii

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

    # --- clearance ------------------------------------------------------------------------------

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
