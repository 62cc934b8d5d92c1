"""`python -m suite bench kernel --near-contact`: the three collision deciders at the free/colliding
boundary, each disagreement judged by a certified signed distance.

The deciders, on the same world (`scenes.collision.world`'s parts, obstacles and counting pairs):
the compiled kernels (`scenes.collision.compiled.CompiledWorld`, the planners'), the numpy reference
(`scenes.collision.world.CollisionWorld`, the judge's) and python-fcl alone (`fcl.collide` on every
counting pair, placed by forward kinematics: no spheres, no tables).

- Boundary states: a free and a colliding state (by one decider, each in turn) are bisected along
  their segment until the two are at most `tol_rad` apart (max over joints); the two ends and
  states at 1e-3 ... 1e-8 rad either side of the boundary are decided by all three.
- Grazing motions: a motion near a problem's start, goal or witness is shifted by s along a
  random joint-space direction; s is bisected (same tolerance) to where the motion turns from
  free to colliding (by one decider, in turn), so that its closest sample just touches. The two
  motions at the ends and those shifted 1e-4, 1e-6 and 1e-8 rad further either way are checked
  by all three (`motion_samples_free`; python-fcl checks every sample).

Wherever the three differ, the state's signed distance (the least over the counting pairs, m;
negative in penetration) is bounded from both sides in closed form (`suite.bench.exact_distance`,
not FCL): it says which answer is right, and how far from contact the disagreement lies; a motion
is judged by its samples. A state within `ROUNDING_M` of contact has no right answer.
"""

from __future__ import annotations

import dataclasses
import math
import time

import fcl
import numpy as np

from suite.bench.exact_distance import ROUNDING_M, Prim, candidates, gaps, sd_bounds

DECIDERS = ("compiled", "numpy", "fcl")
#: Offsets (rad, along the bisected segment or shift) of the extra states and motions either side.
STATE_LADDER_RAD = (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8)
MOTION_LADDER_RAD = (1e-4, 1e-6, 1e-8)
#: Pairs whose cheap lower bound exceeds this (m) are not refined: they cannot be the contact.
SCREEN_M = 1e-3
#: A disagreement farther than this from contact (m) is a defect (`bench kernel` exits 1): FCL's
#: collide, which all three call for some pairs, is exact only to its GJK tolerance (about 1e-6 m).
CONTACT_TOL_M = 1e-5
#: Shifts (rad) tried, nearest first, for a motion's offset that changes its answer.
SHIFTS_RAD = (0.01, 0.02, 0.05, 0.1, 0.2, 0.4)


@dataclasses.dataclass(frozen=True)
class Bounds:
    """lo_m <= signed distance <= hi_m (m) of a state or a motion (its least over samples)."""

    lo_m: float
    hi_m: float

    @property
    def truth(self) -> str:
        """free, collides, contact (within rounding of 0: no answer is wrong) or unresolved (the
        bounds straddle 0 more widely: neither answer is proved)."""
        if self.lo_m > ROUNDING_M:
            return "free"
        if self.hi_m < -ROUNDING_M:
            return "collides"
        return "contact" if self.within_m <= ROUNDING_M else "unresolved"

    @property
    def within_m(self) -> float:
        """How far from contact it is at most (m): max(|lo|, |hi|)."""
        return max(abs(self.lo_m), abs(self.hi_m))


@dataclasses.dataclass(frozen=True)
class Dispute:
    """Where the deciders differ: their answers (True: free), the certified bounds, who was right."""

    kind: str  # "state" or "motion"
    family: str
    answers: dict
    bounds: Bounds
    q: list | None = None
    q0: list | None = None
    q1: list | None = None
    resolution_rad: float | None = None
    #: a state's compiled answer: decided by the kernel itself ("kernel") or by FCL's `collide` on
    #: the pairs the kernel left open ("fcl", placed by the kernel's own forward kinematics); a
    #: motion's: the same for its deepest sample
    compiled_by: str | None = None

    @property
    def wrong(self) -> tuple[str, ...]:
        """The deciders whose answer the distance refutes (none at contact or unresolved)."""
        t = self.bounds.truth
        if t not in ("free", "collides"):
            return ()
        return tuple(d for d, free in self.answers.items() if free != (t == "free"))


@dataclasses.dataclass
class NearContact:
    """The counts of one near-contact draw, its disputes and how close to contact it reached."""

    worlds: int = 0
    families: list = dataclasses.field(default_factory=list)
    tol_rad: float = 0.0
    boundary_pairs: int = 0
    boundary_states: int = 0
    grazing_brackets: int = 0
    grazing_motions: int = 0
    disputes: list = dataclasses.field(default_factory=list)
    #: the ends of bisected segments where the three agree (a sample): (the bisecting decider,
    #: the agreed answer, the certified bounds, who gave the compiled answer)
    brackets: list = dataclasses.field(default_factory=list)
    seconds: float = 0.0

    def summary(self) -> dict:
        """The figures the report prints (JSON-ready)."""
        d = self.disputes
        states = [x for x in d if x.kind == "state"]
        motions = [x for x in d if x.kind == "motion"]
        wrong = {k: sum(k in x.wrong for x in d) for k in DECIDERS}
        worst = {k: max([x.bounds.within_m for x in d if k in x.wrong], default=0.0) for k in DECIDERS}
        truths = {t: sum(x.bounds.truth == t for x in d) for t in ("free", "collides", "contact", "unresolved")}
        patterns: dict[str, int] = {}
        for x in d:
            key = " ".join(f"{k}={'free' if x.answers[k] else 'hit'}" for k in DECIDERS) + f" -> {x.bounds.truth}"
            patterns[key] = patterns.get(key, 0) + 1
        b = sorted(x.within_m for _, _, x, _ in self.brackets)
        by_decider = {k: sorted(x.within_m for dec, _, x, _ in self.brackets if dec == k) for k in DECIDERS}
        shared = [(dec, x, cb) for dec, free, x, cb in self.brackets
                  if x.truth in ("free", "collides") and free != (x.truth == "free")]
        by = {w: sum(x.compiled_by == w for x in d if "compiled" in x.wrong) for w in ("kernel", "fcl")}
        return {
            "worlds": self.worlds, "families": sorted(set(self.families)), "tol_rad": self.tol_rad,
            "boundary_pairs": self.boundary_pairs, "boundary_states": self.boundary_states,
            "grazing_brackets": self.grazing_brackets, "grazing_motions": self.grazing_motions,
            "state_disputes": len(states), "motion_disputes": len(motions), "truths": truths,
            "wrong": wrong, "wrong_within_m": worst, "patterns": patterns,
            "max_dispute_within_m": max([x.bounds.within_m for x in d], default=0.0),
            "compiled_wrong_decided_by": by,
            "bracket_within_m": {"n": len(b), "median": b[len(b) // 2] if b else None, "max": b[-1] if b else None,
                                 "median_by_bisector": {k: v[len(v) // 2] for k, v in by_decider.items() if v}},
            "agreed_but_wrong": {"n": len(shared), "max_within_m": max([x.within_m for _, x, _ in shared], default=0.0),
                                 "compiled_by_fcl": sum(cb == "fcl" for _, _, cb in shared)},
            "seconds": self.seconds,
        }


class Judge:
    """One world's three deciders and the certified signed distance of its states."""

    def __init__(self, scene, **kw) -> None:
        from scenes.collision.compiled import CompiledWorld
        from scenes.collision.world import CollisionWorld

        self.ref = CollisionWorld(scene, **kw)
        self.fast = CompiledWorld(scene, **kw)
        self.robot = self.ref.robot
        self._K = None
        self._req = fcl.CollisionRequest()
        index = {id(obj): k for k, (_, obj) in enumerate(self.ref.obstacles)}
        self._obs = [Prim(shape, tuple(size), np.asarray(X[:3, :3], float), np.asarray(X[:3, 3], float))
                     for _, shape, size, X, _ in self.ref._obs_prims]
        # every counting part-level pair: (part, other part or -1, obstacle index or -1)
        self.pairs = [(i, j, -1 if other is None else index[id(other)])
                      for i, (j, other) in zip(self.ref._pp_part, self.ref._pp_other)]

    # --- the deciders -----------------------------------------------------------------------------

    def fcl_free(self, q: np.ndarray) -> bool:
        """python-fcl alone: `collide` on every counting pair, placed by forward kinematics."""
        ref = self.ref
        rows = ref._state_rows(np.asarray(q, float))
        placed: dict[int, fcl.CollisionObject] = {}
        for i, j, o in self.pairs:
            a = placed.get(i) or placed.setdefault(i, ref._place(i, rows))
            b = ref.obstacles[o][1] if o >= 0 else (placed.get(j) or placed.setdefault(j, ref._place(j, rows)))
            if fcl.collide(a, b, self._req, fcl.CollisionResult()):
                return False
        return True

    def states(self, q: np.ndarray) -> dict[str, bool]:
        """Each decider's answer for state q (True: free)."""
        q = np.ascontiguousarray(q, dtype=float)
        return {"compiled": bool(self.fast.is_free(q)), "numpy": bool(self.ref.is_free(q)), "fcl": self.fcl_free(q)}

    def compiled_by(self, q: np.ndarray) -> str:
        """Who gives the compiled world's answer for q: the kernel, or FCL on the pairs it left open."""
        from scenes.collision.kernel_codes import UNDECIDED
        from scenes.collision.kernel_state import state_decide

        f = self.fast
        code, _ = state_decide(np.ascontiguousarray(q, dtype=float), f._F, f._I, f._C)
        return "fcl" if code == UNDECIDED else "kernel"

    @staticmethod
    def samples(q0: np.ndarray, q1: np.ndarray, resolution_rad: float) -> np.ndarray:
        """The samples `motion_samples_free` decides: q0 + (i / n)(q1 - q0), i = 1..n."""
        d = np.asarray(q1, float) - np.asarray(q0, float)
        n = max(1, math.ceil(float(np.max(np.abs(d))) / resolution_rad))
        return np.asarray(q0, float) + (np.arange(1, n + 1) / n)[:, None] * d

    def fcl_motion_free(self, q0, q1, resolution_rad: float) -> bool:
        return all(self.fcl_free(q) for q in self.samples(q0, q1, resolution_rad))

    def motions(self, q0, q1, resolution_rad: float) -> dict[str, bool]:
        """Each decider's answer for the motion q0 -> q1 at a resolution (True: free)."""
        q0, q1 = np.ascontiguousarray(q0, dtype=float), np.ascontiguousarray(q1, dtype=float)
        return {"compiled": bool(self.fast.motion_samples_free(q0, q1, resolution_rad=resolution_rad)),
                "numpy": bool(self.ref.motion_samples_free(q0, q1, resolution_rad=resolution_rad)),
                "fcl": self.fcl_motion_free(q0, q1, resolution_rad)}

    def decide(self, decider: str, q) -> bool:
        if decider == "compiled":
            return bool(self.fast.is_free(np.ascontiguousarray(q, dtype=float)))
        if decider == "numpy":
            return bool(self.ref.is_free(np.asarray(q, float)))
        return self.fcl_free(q)

    def decide_motion(self, decider: str, q0, q1, resolution_rad: float) -> bool:
        if decider == "fcl":
            return self.fcl_motion_free(q0, q1, resolution_rad)
        w = self.fast if decider == "compiled" else self.ref
        return bool(w.motion_samples_free(np.ascontiguousarray(q0, dtype=float), np.ascontiguousarray(q1, dtype=float),
                                          resolution_rad=resolution_rad))

    # --- the arbiter ------------------------------------------------------------------------------

    def _prims(self, q: np.ndarray) -> dict[int, Prim]:
        rows = self.ref._state_rows(np.asarray(q, float)).copy()
        out = {}
        for p, part in enumerate(self.ref.parts):
            f = self.ref._frame_row[p]
            out[p] = Prim(part.kind, tuple(part.dims), np.ascontiguousarray(rows[f : f + 3, :3].T), rows[f + 3, :3].copy())
        return out

    def bounds(self, q: np.ndarray) -> Bounds:
        """Certified bounds on the state's signed distance (least over the counting pairs, m).

        Every pair gets a cheap lower bound (its best gap over a few directions); the pairs that
        could be the nearest (below `SCREEN_M` and the least upper bound so far) are bounded
        tightly (`sd_bounds`), nearest first."""
        P = self._prims(q)
        shapes = [(P[i], P[j] if o < 0 else self._obs[o]) for i, j, o in self.pairs]
        cheap = [float(gaps(A, B, candidates(A, B)).max()) for A, B in shapes]
        hi, lows = math.inf, []
        for k in np.argsort(cheap):
            if cheap[k] > SCREEN_M or cheap[k] >= hi:
                lows.append(cheap[k])
                continue
            a, b = sd_bounds(*shapes[k])
            lows.append(a)
            hi = min(hi, b)
        return Bounds(min(lows), hi)

    def motion_bounds(self, q0, q1, resolution_rad: float) -> tuple[Bounds, np.ndarray]:
        """Bounds on the least signed distance over a motion's samples (m), and its sample of
        least upper bound (the deepest proved, where one is)."""
        Q = self.samples(q0, q1, resolution_rad)
        b = [self.bounds(q) for q in Q]
        k = int(np.argmin([x.hi_m for x in b]))
        return Bounds(min(x.lo_m for x in b), b[k].hi_m), Q[k]


def _bisect(pred, lo: float, hi: float, *, steps_to: float) -> tuple[float, float]:
    """(a, b) with pred(a) != pred(b), |b - a| <= steps_to, from pred(lo) != pred(hi)."""
    at_lo = pred(lo)
    while abs(hi - lo) > steps_to:
        mid = 0.5 * (lo + hi)
        if mid in (lo, hi):
            break
        if pred(mid) == at_lo:
            lo = mid
        else:
            hi = mid
    return lo, hi


def _clip(robot, q: np.ndarray) -> np.ndarray:
    return np.clip(q, robot.lower_rad, robot.upper_rad)


def boundary_states(judge: Judge, rng: np.random.Generator, points: np.ndarray, n_pairs: int, *,
                    tol_rad: float, first: int = 0, attempts: int = 50) -> list[np.ndarray]:
    """States at the free/colliding boundary of `n_pairs` segments (the bisected ends and the
    ladder either side), each segment bisected by the next decider in turn (`first` first)."""
    robot = judge.robot
    out = []
    for k in range(n_pairs):
        decider = DECIDERS[(first + k) % len(DECIDERS)]
        for _ in range(attempts):
            a = _clip(robot, points[rng.integers(len(points))] + rng.normal(size=7) * rng.choice([0.05, 0.3]))
            b = _clip(robot, a + rng.normal(size=7) * rng.choice([0.1, 0.3, 1.0]))
            if judge.decide(decider, a) and not judge.decide(decider, b):
                break
        else:
            continue
        span = float(np.max(np.abs(b - a)))
        t0, t1 = _bisect(lambda t: judge.decide(decider, a + t * (b - a)), 0.0, 1.0, steps_to=tol_rad / span)
        ts = [t0, t1] + [t + s * off / span for t in (t0,) for off in STATE_LADDER_RAD for s in (-1, 1)]
        out.extend(a + t * (b - a) for t in ts)
    return out


def grazing_motions(judge: Judge, rng: np.random.Generator, points: np.ndarray, n_brackets: int, *,
                    tol_rad: float, first: int = 0, attempts: int = 30) -> list[tuple]:
    """(q0, q1, resolution) of motions shifted to just touch an obstacle or another part: the ends
    of each bisected shift and the ladder either side."""
    robot = judge.robot
    out = []
    for k in range(n_brackets):
        decider = DECIDERS[(first + k) % len(DECIDERS)]
        found = None
        for _ in range(attempts):
            q0 = _clip(robot, points[rng.integers(len(points))] + rng.normal(size=7) * 0.05)
            q1 = q0 + rng.normal(size=7) * rng.choice([0.05, 0.3])
            res = float(rng.choice([0.05, 0.01]))
            v = rng.normal(size=7)
            v /= np.max(np.abs(v))

            def pred(s, q0=q0, q1=q1, v=v, res=res):
                return judge.decide_motion(decider, q0 + s * v, q1 + s * v, res)

            at0 = pred(0.0)
            for sign in (1.0, -1.0):
                s = next((s for s in SHIFTS_RAD if pred(sign * s) != at0), None)
                if s is not None:
                    found = (q0, q1, v, res, pred, sign * s)
                    break
            if found:
                break
        if found is None:
            continue
        q0, q1, v, res, pred, s_end = found
        s0, s1 = _bisect(pred, 0.0, s_end, steps_to=tol_rad)
        toward = math.copysign(1.0, s1 - s0)
        shifts = [s0, s1] + [s0 + toward * sgn * off for off in MOTION_LADDER_RAD for sgn in (-1, 1)]
        out.extend((q0 + s * v, q1 + s * v, res) for s in shifts)
    return out


def near_contact(*, pairs_per_world: int, brackets_per_world: int, seed: int = 0, dataset: str | None = None,
                 pick: int = 0, tol_rad: float = 1e-9, bracket_sample: int = 6, families=None,
                 worlds: list | None = None) -> NearContact:
    """The near-contact draw on the worlds of `draw_worlds(dataset, pick)` (or `worlds`)."""
    from suite.bench.kernel_worlds import draw_worlds

    t_start = time.perf_counter()
    out = NearContact(tol_rad=tol_rad)
    if worlds is None:
        worlds = draw_worlds(dataset, pick=pick) if dataset else draw_worlds(pick=pick)
    for w, (family, p, points) in enumerate(worlds):
        if families and family not in families:
            continue
        judge = Judge(p.scene, gripper_opening_m=p.gripper_opening_m, held=p.held, removed_can_ids=p.removed_can_ids)
        rng = np.random.default_rng([seed, w, 7])
        out.worlds += 1
        out.families.append(family)
        states = boundary_states(judge, rng, points, pairs_per_world, tol_rad=tol_rad, first=w)
        per = 2 + 2 * len(STATE_LADDER_RAD)
        out.boundary_pairs += len(states) // per
        out.boundary_states += len(states)
        for m, q in enumerate(states):
            ans = judge.states(q)
            if len(set(ans.values())) > 1:
                out.disputes.append(Dispute("state", family, ans, judge.bounds(q), q=q.tolist(),
                                            compiled_by=judge.compiled_by(q)))
            elif m % per < 2 and m // per < bracket_sample:  # how near the bisection came, certified
                out.brackets.append((DECIDERS[(w + m // per) % len(DECIDERS)], ans["numpy"], judge.bounds(q),
                                     judge.compiled_by(q)))
        motions = grazing_motions(judge, rng, points, brackets_per_world, tol_rad=tol_rad, first=w)
        out.grazing_brackets += len(motions) // (2 + 2 * len(MOTION_LADDER_RAD))
        out.grazing_motions += len(motions)
        for q0, q1, res in motions:
            ans = judge.motions(q0, q1, res)
            if len(set(ans.values())) > 1:
                b, deepest = judge.motion_bounds(q0, q1, res)
                out.disputes.append(Dispute("motion", family, ans, b, q0=q0.tolist(), q1=q1.tolist(),
                                            resolution_rad=res, compiled_by=judge.compiled_by(deepest)))
    out.seconds = time.perf_counter() - t_start
    return out


def report(nc: NearContact, *, dataset: str, pick: int, seed: int) -> list[str]:
    """The printed lines of a near-contact draw."""
    s, d = nc.summary(), nc.disputes
    lines = [f"near-contact check: compiled kernels, numpy reference and python-fcl alone on {s['worlds']} worlds of "
             f"{dataset} (problem {pick} of each family and held/not, families {', '.join(s['families'])}), seed {seed}, "
             f"bisected to {nc.tol_rad:g} rad",
             f"  boundary states: {s['boundary_states']:,} ({s['boundary_pairs']} bisected segments, ends and "
             f"{len(STATE_LADDER_RAD)} offsets either side, {STATE_LADDER_RAD[0]:g}-{STATE_LADDER_RAD[-1]:g} rad)",
             f"  grazing motions: {s['grazing_motions']:,} ({s['grazing_brackets']} bisected shifts, ends and "
             f"{len(MOTION_LADDER_RAD)} offsets either side)"]
    b = s["bracket_within_m"]
    if b["n"]:
        per = ", ".join(f"{k} {v:.1e}" for k, v in b["median_by_bisector"].items())
        lines.append(f"  the bisection's ends where the three agree: within {b['median']:.1e} m of contact (median of "
                     f"{b['n']} certified; by the decider that bisected: {per}), {b['max']:.1e} m at most")
        a = s["agreed_but_wrong"]
        if a["n"]:
            lines.append(f"    of them {a['n']} agreed and wrong, all within {a['max_within_m']:.1e} m of contact "
                         f"(the compiled answer from FCL's collide in {a['compiled_by_fcl']})")
    lines.append(f"  disagreements: {s['state_disputes']} states, {s['motion_disputes']} motions; the signed "
                 f"distance says free {s['truths']['free']}, collides {s['truths']['collides']}, contact within "
                 f"{ROUNDING_M:g} m {s['truths']['contact']}, unresolved {s['truths']['unresolved']}")
    for k in DECIDERS:
        if s["wrong"][k]:
            by = s["compiled_wrong_decided_by"]
            how = (f" (decided by the kernel itself {by['kernel']}, by FCL on the pairs it left open {by['fcl']})"
                   if k == "compiled" else "")
            lines.append(f"    {k} wrong in {s['wrong'][k]}{how}, all within {s['wrong_within_m'][k]:.1e} m of contact")
        else:
            lines.append(f"    {k} never wrong")
    for pattern, count in sorted(s["patterns"].items(), key=lambda kv: -kv[1]):
        lines.append(f"    {count:5d}  {pattern}")
    far = sum(x.bounds.within_m >= CONTACT_TOL_M for x in d)
    own = sum("compiled" in x.wrong and x.compiled_by == "kernel" for x in d)
    lines.append(f"  defects (a disagreement {CONTACT_TOL_M:g} m or more from contact, or the kernel's own decision "
                 f"refuted): {far + own}")
    if s["state_disputes"] + s["motion_disputes"]:
        x = s["max_dispute_within_m"]
        lines.append(f"  identical except within {x:.1e} m of contact (the largest |signed distance| at a disagreement)")
    else:
        lines.append("  identical: no disagreement")
    lines.append(f"  ({s['seconds']:.0f} s)")
    return lines
