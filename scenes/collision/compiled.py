"""The planners' collision world: `CollisionWorld` with its decisions made by the compiled kernels
of `scenes.collision.kernel_state`, and FCL's `collide` for the pairs they leave undecided.

It answers every question the numpy world answers (`is_free`, `states_free`, `first_collision`,
`path_free`, `motion_free`, `motion_samples_free`), with the same answers: the differential test
(`tests/scenes/collision/test_compiled.py`, and `python -m suite bench kernel` at full size) compares
the two. The judge (validator, certifier) keeps the numpy world, so the two implementations check
each other on every success.
"""

from __future__ import annotations

import logging
from time import perf_counter as _clock

import numpy as np

from scenes.collision import kernel_codes as K
from scenes.collision.kernel_data import CACHE_PATH, FLOAT_FIELDS, INT_FIELDS, SCRATCH, float_field, int_field, pack
from scenes.collision.kernel_motion import motion_check
from scenes.collision.kernel_state import batch_decide, state_decide
from scenes.collision.world import CollisionWorld

log = logging.getLogger(__name__)


#: Spacing of the fine spheres that decide a scene pair the coarse ones leave open (as a fraction
#: of a cylinder's or capsule's radius: outer radius 0.8% above it; `scenes.collision.shapes.cover_spheres`).
FINE_SPACING = 0.25


_WARM: dict[str, float] = {}


def compile_kernels() -> float:
    """Compile (or load from the disk cache) every kernel once in this process, on a tiny world;
    returns the seconds it took (0 after the first call). Called when a compiled world is built,
    so that the compile is set-up time, never planning time."""
    if "s" in _WARM:
        return 0.0
    t = _clock()
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
    motion_check(q, np.ones(7), 0.5, F, I, C, np.zeros(4, np.bool_), np.zeros(K.WORK, np.int64))
    _WARM["s"] = _clock() - t
    log.debug("fcl kernels ready in %.2f s (cache %s)", _WARM["s"], CACHE_PATH)
    return _WARM["s"]


def _c(a, dtype) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=dtype)


class CompiledWorld(CollisionWorld):
    """`CollisionWorld` (same arguments) deciding with the compiled kernels; building the first one
    in a process compiles (or loads) them: set-up, never planning time."""

    engine = "compiled"

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        compile_kernels()
        M = self._M_full
        n_obs, ne, T = len(self._obs_c), self._n_env, len(self._tab_k)
        is_frame = np.zeros(len(self._rows0), np.int64)  # the parts' pose rows: FCL's alone
        for f in self._frame_row:
            is_frame[f : f + 4] = 1
        S = ne // n_obs if n_obs else 0

        def pairs(a):  # the scene pairs obstacle-major (o * S + s, not s * O + o), then the self pairs
            a = np.asarray(a)
            return np.concatenate([a[:ne].reshape(S, n_obs).T.ravel(), a[ne:]])

        # every scene sphere's inner ball counts against every obstacle: its distance is exact here
        rho2 = np.where(self._R2 >= 0, np.concatenate([np.repeat(self._inner_env**2, n_obs),
                                                       np.full(len(self._R2) - ne, -1.0)]), -1.0)
        rho2[ne:] = self._rho2[ne:]
        fields = {
            "Mc": np.stack([M[16 * k : 16 * k + 16, k] for k in range(7)]),
            "Ms": np.stack([M[16 * k : 16 * k + 16, 7 + k] for k in range(7)]),
            "M1": np.stack([M[16 * k : 16 * k + 16, 14] for k in range(7)]),
            "rows0": self._rows0, "R2": pairs(self._R2), "rho2": pairs(rho2),
            "tab_lo": self._tab_lo, "tab_inv": self._tab_inv, "tab_n": self._tab_n,
            "row_chain": self._reach_chain(), "pair_r": pairs(self._pair_r), "pair_self": pairs(self._pair_self),
            "rows": self._world0, "d2": np.zeros(len(self._R2)), "scratch": np.zeros(SCRATCH),
            "lam_pair": np.zeros(len(self._R2)), "sph": np.zeros(3 * S),
            "link_end": self._link_end, "s_row": self._iab[0, :ne:n_obs], "ia": pairs(self._iab[0]),
            "ib": pairs(self._iab[1]), "pp": pairs(self._pp), "tab_j": self._tab_j, "tab_k": self._tab_k,
            "pair_b": pairs(self._pair_b), "pair_counts": pairs(self._pair_counts),
            "pairs": np.zeros(len(self._pp_part)), "tab_cells": self._tab_cells, "is_frame": is_frame,
            **self._obstacle_fields(),
        }
        fields.update(self._fine_cover())
        sizes = (len(self._rows0), len(self._world0), n_obs, len(self._R2), T, ne,
                 len(self._tab_cells) // T if T else 1, len(self._pp_part))
        self._F, self._I, self._C = pack(fields, sizes)
        self._krows = float_field(self._F, self._I, "rows").reshape(-1, 3)
        self._kpairs = int_field(self._I, "pairs")
        self._todo = np.zeros(1024, np.bool_)  # the motion check's samples still to evaluate
        self._ws = np.zeros(K.WORK, np.int64)  # and where it stands
        self._check = self._compiled_check

    def _obstacle_fields(self) -> dict:
        """Every obstacle as its kind (`K.AABB`, `K.OBB`, `K.CYLINDER`, `K.SPHERE`), centre,
        rotation (world from obstacle) and half sizes (box), radius and half length (cylinder) or
        radius (sphere), stored by coordinate, for the exact point distances."""
        kinds, ctr, rot, half = [], [], [], []
        for _, shape, size, X, aligned in self._obs_prims:
            if shape == "box":
                kinds.append(K.AABB if aligned else K.OBB)
                half.append(np.asarray(size, float) / 2)
            elif shape == "cylinder":
                kinds.append(K.CYLINDER)
                half.append([size[0], size[1] / 2, 0.0])
            elif shape == "sphere":
                kinds.append(K.SPHERE)
                half.append([size[0], 0.0, 0.0])
            else:
                raise ValueError(f"obstacle shape {shape!r} has no compiled distance")
            ctr.append(X[:3, 3])
            rot.append(np.asarray(X[:3, :3], float).ravel())
        return {"obs_type": np.array(kinds), "obs_ctr": np.array(ctr).T, "obs_half": np.array(half).T,
                "obs_rot": np.array(rot).T}

    def _fine_cover(self) -> dict:
        """Each part's fine spheres (`FINE_SPACING`) in its link's frame, with squared outer and
        inner radii; which part and obstacle each part-level pair joins (-1: a self pair)."""
        from scenes.collision.shapes import cover_spheres

        rows, out2, in2, start = [], [], [], [0]
        for part in self.parts:
            if part.link >= 1:
                c, outer, inner = cover_spheres(part.kind, part.dims, FINE_SPACING)
                c_L = c @ part.X_LS[:3, :3].T + part.X_LS[:3, 3]
                rows.append(np.column_stack([c_L, np.ones(len(c))]))
                out2.append(outer**2)
                in2.append(inner**2)
            start.append(start[-1] + (len(rows[-1]) if part.link >= 1 else 0))
        index = {id(obj): k for k, (_, obj) in enumerate(self.obstacles)}
        pp_obs = [-1 if other is None else index[id(other)] for _, other in self._pp_other]
        return {"fine_rows0": np.vstack(rows), "fine_out2": np.concatenate(out2), "fine_in2": np.concatenate(in2),
                "pp_part": np.array(self._pp_part), "pp_obs": np.array(pp_obs),
                "part_link": np.array([p.link for p in self.parts]), "fine_start": np.array(start)}

    def _compiled_check(self, q) -> bool:
        """One state (`is_free`'s check): the kernel's decision, and FCL's for the pairs it leaves
        undecided (placed by the rows the kernel left in self._krows)."""
        code, count = state_decide(np.ascontiguousarray(q, dtype=np.float64), self._F, self._I, self._C)
        if code != K.UNDECIDED:
            return code == K.FREE
        return not self._exact_pairs(self._krows, self._kpairs[:count].tolist())

    def _scan(self, Q: np.ndarray, *, stop_at_first: bool) -> np.ndarray:
        Q = np.ascontiguousarray(Q, dtype=np.float64)
        codes = batch_decide(Q, bool(stop_at_first), self._F, self._I, self._C)
        out = np.ones(len(Q), bool)
        for m in np.flatnonzero(codes != K.FREE).tolist():
            bad = codes[m] == K.COLLIDES or not self._compiled_check(Q[m])
            if bad:
                out[m] = False
                if stop_at_first:
                    return out
        return out

    def motion_samples_free(self, q0: np.ndarray, q1: np.ndarray, *, resolution_rad: float) -> bool:
        """`MotionChecks.motion_samples_free`, decided by the compiled kernel in one call (more
        only where FCL decides a sample): the same answer."""
        t = _clock()
        ws = self._ws
        ws[K.WS_PHASE] = K.PHASE_START
        F, I, C = self._F, self._I, self._C
        q0 = np.ascontiguousarray(q0, dtype=np.float64)
        q1 = np.ascontiguousarray(q1, dtype=np.float64)
        try:
            while True:
                code, count = motion_check(q0, q1, resolution_rad, F, I, C, self._todo, ws)
                if code == K.NEED_SPACE:
                    self._todo = np.zeros(2 * int(ws[K.WS_N]) + 64, np.bool_)
                    ws[K.WS_PHASE] = K.PHASE_START
                    continue
                if code == K.FREE:
                    return True
                if code == K.COLLIDES or self._exact_pairs(self._krows, self._kpairs[:count].tolist()):
                    return False
        finally:
            self.checks += int(ws[K.WS_STATES])
            self.query_s += _clock() - t

