"""`python -m suite bench kernel`: the compiled checks against the numpy reference, answer for
answer (the differential check), and what each costs.

Draws, on worlds of every family of the dataset (a problem with a held can and one without, each
at its own gripper opening and at the other: open, or closed on the can), states and motions:

- states: a third uniform within the joint limits, a third near the problems' starts, goals and
  witness paths (Gaussian, 0.05 and 0.3 rad), a third uniform in limits widened by 0.3 rad
  (states past the joint limits, where the joint tables answer UNKNOWN);
- motions: from a state near a start, goal or witness point to one 0.05, 0.3 or 1.0 rad away
  (Gaussian per joint), and the witness paths' own segments, at the planners' resolutions (0.05
  and 0.01 rad).

Every state is decided by the numpy world (`states_free`, batched) and by the compiled one, both
batched (`states_free`) and one at a time (`is_free`); every motion by both worlds'
`motion_samples_free`. Any disagreement is a defect: the figures print them, and
`tests/scenes/collision/test_compiled.py` runs a small draw in the default test run and the full one
(`-m slow`).

`--near-contact` probes where uniform draws rarely land, the free/colliding boundary: bisected
states and grazing motions, decided by the two worlds and by python-fcl alone, every
disagreement judged by a certified signed distance (`suite.bench.near_contact`).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time

import numpy as np

from suite.bench.kernel_worlds import draw_worlds
from suite.cli.args import nonneg_int, positive_float, positive_int
from suite.problems import DEFAULT_DATASET

RESOLUTIONS_RAD = (0.05, 0.01)
NEAR_SIGMAS_RAD = (0.05, 0.3)
MOTION_SIGMAS_RAD = (0.05, 0.3, 1.0)
PAST_LIMITS_RAD = 0.3


@dataclasses.dataclass
class Differential:
    """The counts of one differential check (disagreements must be 0)."""

    worlds: int = 0
    states: int = 0
    state_disagreements: int = 0
    single_disagreements: int = 0
    motions: int = 0
    motion_disagreements: int = 0
    free_states: int = 0
    free_motions: int = 0
    numpy_state_s: float = 0.0
    compiled_state_s: float = 0.0
    compiled_single_s: float = 0.0
    numpy_motion_s: float = 0.0
    compiled_motion_s: float = 0.0
    numpy_motion_states: int = 0
    compiled_motion_states: int = 0
    compiled_fcl_calls: int = 0
    examples: list = dataclasses.field(default_factory=list)


def _states(rng, robot, points: np.ndarray, n: int) -> np.ndarray:
    lo, hi = robot.lower_rad, robot.upper_rad
    k = n // 3
    uniform = rng.uniform(lo, hi, size=(k, 7))
    centres = points[rng.integers(len(points), size=k)]
    near = centres + rng.normal(size=(k, 7)) * rng.choice(NEAR_SIGMAS_RAD, size=(k, 1))
    past = rng.uniform(lo - PAST_LIMITS_RAD, hi + PAST_LIMITS_RAD, size=(n - 2 * k, 7))
    return np.vstack([uniform, near, past])


def _motions(rng, points: np.ndarray, n: int) -> list[tuple[np.ndarray, np.ndarray, float]]:
    seg = [(a, b) for a, b in zip(points[2:-1], points[3:])]  # the witness's own segments
    out = [(a, b, RESOLUTIONS_RAD[i % 2]) for i, (a, b) in enumerate(seg)][:n]
    while len(out) < n:
        a = points[rng.integers(len(points))] + rng.normal(size=7) * 0.05
        b = a + rng.normal(size=7) * rng.choice(MOTION_SIGMAS_RAD)
        out.append((a, b, float(rng.choice(RESOLUTIONS_RAD))))
    return out


def differential(*, states_per_world: int, motions_per_world: int, seed: int = 0,
                 dataset: str = DEFAULT_DATASET, pick: int = 0, keep_examples: int = 5) -> Differential:
    """Decide the same states and motions with the numpy and the compiled world (see the module
    docstring); returns the counts and the seconds each spent."""
    from scenes.collision.compiled import CompiledWorld
    from scenes.collision.world import CollisionWorld

    perf = time.perf_counter
    out = Differential()
    for w, (family, p, points) in enumerate(draw_worlds(dataset, pick=pick)):
        kw = dict(gripper_opening_m=p.gripper_opening_m, held=p.held, removed_can_ids=p.removed_can_ids)
        ref, fast = CollisionWorld(p.scene, **kw), CompiledWorld(p.scene, **kw)
        rng = np.random.default_rng([seed, w])
        Q = _states(rng, ref.robot, points, states_per_world)
        t = perf()
        a = ref.states_free(Q)
        out.numpy_state_s += perf() - t
        t = perf()
        b = fast.states_free(Q)
        out.compiled_state_s += perf() - t
        t = perf()
        c = np.array([fast.is_free(q) for q in Q])
        out.compiled_single_s += perf() - t
        out.worlds += 1
        out.states += len(Q)
        out.free_states += int(a.sum())
        out.state_disagreements += int((a != b).sum())
        out.single_disagreements += int((a != c).sum())
        for m in np.flatnonzero((a != b) | (a != c))[: max(0, keep_examples - len(out.examples))]:
            out.examples.append({"family": family, "q": Q[m].tolist(), "numpy": bool(a[m]), "compiled": bool(b[m])})
        motions = _motions(rng, points, motions_per_world)
        c0, f0 = ref.checks, fast.checks
        t = perf()
        ma = [ref.motion_samples_free(x, y, resolution_rad=r) for x, y, r in motions]
        out.numpy_motion_s += perf() - t
        fcl0 = fast.fcl_calls
        t = perf()
        mb = [fast.motion_samples_free(x, y, resolution_rad=r) for x, y, r in motions]
        out.compiled_motion_s += perf() - t
        out.numpy_motion_states += ref.checks - c0
        out.compiled_motion_states += fast.checks - f0
        out.compiled_fcl_calls += fast.fcl_calls - fcl0
        out.motions += len(motions)
        out.free_motions += sum(ma)
        bad = [i for i, (x, y) in enumerate(zip(ma, mb)) if x != y]
        out.motion_disagreements += len(bad)
        for i in bad[: max(0, keep_examples - len(out.examples))]:
            x, y, r = motions[i]
            out.examples.append({"family": family, "q0": x.tolist(), "q1": y.tolist(), "resolution_rad": r,
                                 "numpy": ma[i], "compiled": mb[i]})
    return out


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--states", type=positive_int, default=1_000_000, help="states in all (default 1,000,000)")
    p.add_argument("--motions", type=positive_int, default=100_000, help="motions in all (default 100,000)")
    p.add_argument("--seed", type=nonneg_int, default=0, help="the draws' seed (default 0)")
    p.add_argument("--json", action="store_true", help="print the counts as JSON")
    p.add_argument("--dataset", default=DEFAULT_DATASET, help=f"the worlds' dataset (default {DEFAULT_DATASET})")
    p.add_argument("--pick", type=nonneg_int, default=0,
                   help="which problem of each family and held/not gives its worlds, from 0 (default 0)")
    g = p.add_argument_group("near contact (--near-contact)")
    g.add_argument("--near-contact", action="store_true",
                   help="the boundary check instead: bisected free/colliding states and grazing motions, compiled, "
                        "numpy and python-fcl alone, every disagreement judged by a certified signed distance")
    g.add_argument("--segments", type=positive_int, default=40, help="bisected state segments per world (default 40)")
    g.add_argument("--grazing", type=nonneg_int, default=8, help="bisected motion shifts per world (default 8)")
    g.add_argument("--tol-rad", type=positive_float, default=1e-9,
                   help="bisect until the two ends are this close, max over joints (default 1e-9; at most 1e-6)")
    g.add_argument("--families", default=None, metavar="F,...", help="only these families (default all)")


def _run_near_contact(args: argparse.Namespace) -> int:
    from scenes.errors import SuiteError
    from suite.bench.near_contact import CONTACT_TOL_M, near_contact, report

    if args.tol_rad > 1e-6:
        raise SuiteError(f"--tol-rad {args.tol_rad:g} is coarser than 1e-6 rad: the bisection must reach the boundary")
    fams = [f for f in args.families.split(",") if f] if args.families else None
    worlds = draw_worlds(args.dataset, pick=args.pick)
    known = sorted({f for f, _, _ in worlds})
    if fams and not set(fams) <= set(known):
        raise SuiteError(f"--families {args.families!r}: {args.dataset} has {', '.join(known)}")
    nc = near_contact(pairs_per_world=args.segments, brackets_per_world=args.grazing, seed=args.seed,
                      tol_rad=args.tol_rad, families=fams, worlds=worlds)
    if args.json:
        print(json.dumps({"summary": nc.summary(),
                          "disputes": [{**dataclasses.asdict(x), "truth": x.bounds.truth, "wrong": list(x.wrong)}
                                       for x in nc.disputes]}))
    else:
        print("\n".join(report(nc, dataset=args.dataset, pick=args.pick, seed=args.seed)))
    # a defect: a disagreement far from contact, or the kernel's own decision refuted
    far = any(x.bounds.within_m >= CONTACT_TOL_M for x in nc.disputes)
    kernel_wrong = any("compiled" in x.wrong and x.compiled_by == "kernel" for x in nc.disputes)
    return 1 if far or kernel_wrong else 0


def run(args: argparse.Namespace) -> int:
    if getattr(args, "near_contact", False):
        return _run_near_contact(args)
    n_worlds = len(draw_worlds(args.dataset, pick=args.pick))
    d = differential(states_per_world=-(-args.states // n_worlds), motions_per_world=-(-args.motions // n_worlds),
                     seed=args.seed, dataset=args.dataset, pick=args.pick)
    if args.json:
        print(json.dumps(dataclasses.asdict(d)))
        return 0 if not (d.state_disagreements or d.single_disagreements or d.motion_disagreements) else 1
    print(f"differential check, compiled kernels against the numpy reference: {d.worlds} worlds of {args.dataset} "
          f"(every family, held and not, two gripper openings), seed {args.seed}")
    print(f"  states:  {d.states:,} ({d.free_states / d.states:.1%} free): disagreements batched {d.state_disagreements}, "
          f"one at a time {d.single_disagreements}")
    print(f"  motions: {d.motions:,} ({d.free_motions / d.motions:.1%} free): disagreements {d.motion_disagreements}")
    us = 1e6
    print(f"  per state, batched: numpy {d.numpy_state_s / d.states * us:.2f} us, compiled "
          f"{d.compiled_state_s / d.states * us:.2f} us ({d.numpy_state_s / d.compiled_state_s:.1f}x); one at a "
          f"time (is_free) compiled {d.compiled_single_s / d.states * us:.2f} us")
    print(f"  per motion: numpy {d.numpy_motion_s / d.motions * us:.1f} us ({d.numpy_motion_states / d.motions:.1f} "
          f"states), compiled {d.compiled_motion_s / d.motions * us:.1f} us ({d.compiled_motion_states / d.motions:.1f} "
          f"states, {d.compiled_fcl_calls / d.motions:.2f} FCL calls): {d.numpy_motion_s / d.compiled_motion_s:.1f}x; "
          f"per evaluated state {d.numpy_motion_s / max(d.numpy_motion_states, 1) * us:.2f} vs "
          f"{d.compiled_motion_s / max(d.compiled_motion_states, 1) * us:.2f} us")
    for e in d.examples:
        print("  disagreement:", json.dumps(e))
    return 0 if not (d.state_disagreements or d.single_disagreements or d.motion_disagreements) else 1
