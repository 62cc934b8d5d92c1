"""Building `scenes.collision.world.CollisionWorld`'s arrays once per world: the homogeneous rows in link
frames (hand first), the sphere-level pairs with the scene and between robot parts, the joint
tables as arrays, and the forward-kinematics buffers. A mixin: `CollisionWorld.__init__` calls
these after it has its parts and obstacles."""

from __future__ import annotations

import fcl
import numpy as np

from scenes.collision.shapes import Part, cover_spheres
from scenes.collision.joint_tables import TABLE_MARGIN_M, UNKNOWN, on_axis, pair_table

#: Spacing of the spheres covering a cylinder or capsule along its axis, as a fraction of its
#: radius (outer radius sqrt(1 + f^2 / 4) r: 7% above r for f = 0.75), for pairs with the scene
#: (fine: the scene is where most near misses happen) and between robot parts (coarse: few pairs).
ENV_SPACING = 0.75
SELF_SPACING = 2.0


class WorldBuild:
    """The construction steps of a collision world (mixed into `CollisionWorld`)."""

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
        self._inner_env = inner_e  # every scene sphere's inner radius (the compiled checks' exact distances use it)
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
