"""`python -m suite bench certify`: what the exact verdict costs beside the 0.01 rad check.

For every path of a selection (a dataset's non-trivial references, and with `--run` each
planner's successful paths of that run), on the path's own python-fcl world: the seconds of the
validator's fixed-step check (`CollisionWorld.path_free` at 0.01 rad: the field's rule) and of the
exact check (`scenes.collision.certify`), each the median of `--repeats` runs, the states each looked at
and the exact distance queries of the certificate. Reported per group: median and p90 of the
per-path cost ratio (certified / fixed step), and the verdicts.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from suite.cli.args import positive_int
from suite.problems import DEFAULT_TIER


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--dataset", default=DEFAULT_TIER, help=f"NAME[:TIER[:FILTERS]] whose references (default {DEFAULT_TIER})")
    p.add_argument("--run", default=None, help="also every successful path of this run directory, per planner")
    p.add_argument("--repeats", type=positive_int, default=3, help="timed runs of each check per path (default 3)")
    p.add_argument("--json", action="store_true", help="print the per-path figures as JSON")
    p.add_argument("--breakdown", action="store_true",
                   help="also say where the exact check's time goes (its tiers, timed around each call), and "
                        "what the 0.01 rad check costs on the compiled kernels")
    p.add_argument("--figure", metavar="PNG", default=None,
                   help="also draw the deepest reference collision between two 0.01 rad states to PNG")


def measure_path(path: np.ndarray, world, *, repeats: int) -> dict:
    """One path's figures: fixed-step and certified seconds (medians), states, queries, verdict."""
    from scenes.collision.certify import certifier
    from suite.scoring.validate import VALIDATION_RESOLUTION_RAD

    cert = certifier(world)
    fixed, exact = [], []
    for _ in range(repeats):
        t = time.perf_counter()
        world.path_free(path, resolution_rad=VALIDATION_RESOLUTION_RAD)
        fixed.append(time.perf_counter() - t)
        c = cert.certify(path)
        exact.append(c.time_s)
    fixed_s, exact_s = float(np.median(fixed)), float(np.median(exact))
    fixed_states = 1 + int(world.segment_steps(path, VALIDATION_RESOLUTION_RAD).sum())
    return {"verdict": c.verdict, "detail": c.detail, "fixed_states": fixed_states,
            "states": c.states, "distance_queries": c.distance_queries, "fixed_s": fixed_s, "certify_s": exact_s,
            "ratio": exact_s / fixed_s}


#: The certifier's parts timed by `breakdown`: its method, and what it is.
PARTS = {"_evaluate": "FK and sphere bounds (numpy)", "_reach": "lever arms", "_pair_lambdas": "body-pair motion bounds",
         "_tables_apart": "joint tables", "_exact": "proved FCL distances (python-fcl)"}


def breakdown(items: list[tuple]) -> dict:
    """Where the exact check's seconds go over paths [(problem, path)]: each part of PARTS timed
    around its calls (the rest is the bisection's own bookkeeping), the exact FCL queries, and the
    0.01 rad check on the judge's numpy world and on the planners' compiled one."""
    from planners.worlds import collision_world, planning_world
    from scenes.collision.certify import Certifier
    from suite.scoring.validate import VALIDATION_RESOLUTION_RAD

    spent = dict.fromkeys(PARTS, 0.0)
    total = fixed_numpy = fixed_compiled = 0.0
    queries = 0
    for problem, path in items:
        path = np.asarray(path, float)
        world = collision_world(problem)
        cert = Certifier(world)  # its own: the wrappers below must not stay on the world's cached one

        def timed(name, fn):
            def wrapper(*a, **k):
                t = time.perf_counter()
                try:
                    return fn(*a, **k)
                finally:
                    spent[name] += time.perf_counter() - t
            return wrapper

        for name in PARTS:
            setattr(cert, name, timed(name, getattr(cert, name)))
        c = cert.certify(path)
        total += c.time_s
        queries += c.distance_queries
        t = time.perf_counter()
        world.path_free(path, resolution_rad=VALIDATION_RESOLUTION_RAD)
        fixed_numpy += time.perf_counter() - t
        compiled = planning_world(problem)
        compiled.path_free(path, resolution_rad=VALIDATION_RESOLUTION_RAD)  # its first call compiles or loads
        t = time.perf_counter()
        compiled.path_free(path, resolution_rad=VALIDATION_RESOLUTION_RAD)
        fixed_compiled += time.perf_counter() - t
    return {"paths": len(items), "certify_s": total, "parts_s": spent,
            "rest_s": total - sum(spent.values()), "exact_queries": queries,
            "fixed_numpy_s": fixed_numpy, "fixed_compiled_s": fixed_compiled}


def _print_breakdown(b: dict) -> None:
    total = b["certify_s"]
    n = max(b["paths"], 1)
    print(f"\nwhere the exact check's time goes: {b['paths']} references, {total:.2f} s in all "
          f"({1e3 * total / n:.1f} ms a path; the 0.01 rad check: {1e3 * b['fixed_numpy_s'] / n:.1f} ms numpy, "
          f"{1e3 * b['fixed_compiled_s'] / n:.2f} ms compiled)")
    for name, what in PARTS.items():
        v = b["parts_s"][name]
        print(f"  {what:36s} {v:8.2f} s {100 * v / total:5.1f}%")
    print(f"  {'bisection bookkeeping (the rest)':36s} {b['rest_s']:8.2f} s {100 * b['rest_s'] / total:5.1f}%")
    q = b["exact_queries"]
    print(f"  exact FCL queries: {q / n:.0f} a path, {1e6 * b['parts_s']['_exact'] / max(q, 1):.0f} µs each")


def _groups(args) -> dict[str, list[tuple]]:
    """group name -> [(problem, path)]."""
    from suite.problems.dataset import load_dataset

    ds = load_dataset(args.dataset)
    groups = {"references": [(p, ds.references[pid]) for pid, p in zip(ds.ids, ds.problems)
                             if not ds.meta[pid]["trivial"]]}
    if args.run:
        from suite.run.recorded_problems import RecordedProblems, Unrebuildable
        from suite.run.records import joint_path, read_manifest, read_trials

        records = read_trials(args.run)
        rebuild = RecordedProblems(records, read_manifest(args.run))
        for rec in records:
            path = joint_path(rec)
            if not rec.succeeded or path is None:
                continue
            try:
                groups.setdefault(rec.planner, []).append((rebuild.problem(rec), path))
            except Unrebuildable:
                continue
    return groups


def between_samples_figure(items: list[tuple], rows: list[dict], png: str) -> str | None:
    """Draw the deepest collision of `items` (problem, path) whose `rows` verdict is `collision`;
    returns what was drawn, or None if none collides."""
    from pathlib import Path

    from planners.worlds import collision_world
    from scenes.collision.certify import certifier
    from suite.report.plots_certify import plot_between_samples
    from suite.scoring.validate import VALIDATION_RESOLUTION_RAD

    hits = [(r["detail"]["penetration_m"], i) for i, r in enumerate(rows) if r["verdict"] == "collision"]
    if not hits:
        return None
    _, i = max(hits)
    problem, path = items[i]
    d = rows[i]["detail"]
    cert = certifier(collision_world(problem))
    k = cert._names.index(tuple(d["pair"]))
    a, b = np.asarray(path[d["segment"]], float), np.asarray(path[d["segment"] + 1], float)
    span = float(np.max(np.abs(b - a)))
    n = max(1, int(np.ceil(span / VALIDATION_RESOLUTION_RAD)))
    step = int(np.clip(np.floor(d["t"] * n), 0, n - 1))
    lo, hi = max(0, step - 2), min(n, step + 3)
    t_dense = np.linspace(lo / n, hi / n, 400)
    t_samples = np.arange(lo, hi + 1) / n
    dist = np.array([cert.exact_distance(k, a + t * (b - a)) for t in t_dense])
    dist_s = np.array([cert.exact_distance(k, a + t * (b - a)) for t in t_samples])
    title = (f"{problem.scene.variant} {problem.kind}, segment {d['segment']}: free at every 0.01 rad state, "
             f"{1e3 * float(-dist.min()):.2f} mm deep between two")
    plot_between_samples(s_rad=t_dense * span, distance_m=dist, sample_s_rad=t_samples * span,
                         sample_distance_m=dist_s, pair=tuple(d["pair"]), title=title, path=Path(png))
    return title


def run(args: argparse.Namespace) -> int:
    from planners.worlds import collision_world

    out, groups = {}, _groups(args)
    for group, items in groups.items():
        out[group] = [measure_path(np.asarray(path, float), collision_world(p), repeats=args.repeats)
                      for p, path in items]
    if args.figure:
        drawn = between_samples_figure(groups["references"], out["references"], args.figure)
        print(f"{args.figure}: {drawn}" if drawn else f"{args.figure}: no reference collides between samples; not drawn")
    extra = breakdown(groups["references"]) if args.breakdown else None
    if args.json:
        print(json.dumps(out if extra is None else {**out, "breakdown": extra}))
        return 0
    print(f"exact verdict vs the 0.01 rad check, per path (medians of {args.repeats} runs each); "
          f"ratio = certify seconds / fixed-step seconds")
    print(f"{'paths':14s} {'n':>4s} {'cert.':>5s} {'unpr.':>5s} {'coll.':>5s} {'ratio med':>9s} {'ratio p90':>9s} "
          f"{'states/fixed':>12s} {'queries med':>11s} {'certify ms':>10s} {'fixed ms':>8s}")
    every = [x for rows in out.values() for x in rows]
    for group, rows in [*out.items(), *([("all paths", every)] if len(out) > 1 else [])]:
        if not rows:
            continue
        r = np.array([x["ratio"] for x in rows])
        verdicts = [x["verdict"] for x in rows]
        print(f"{group:14s} {len(rows):4d} {verdicts.count('certified'):5d} {verdicts.count('unproved'):5d} "
              f"{verdicts.count('collision'):5d} {np.median(r):9.2f} {np.quantile(r, 0.9):9.2f} "
              f"{np.median([x['states'] / x['fixed_states'] for x in rows]):12.2f} "
              f"{np.median([x['distance_queries'] for x in rows]):11.0f} "
              f"{1e3 * np.median([x['certify_s'] for x in rows]):10.2f} {1e3 * np.median([x['fixed_s'] for x in rows]):8.2f}")
    if extra is not None:
        _print_breakdown(extra)
    return 0
