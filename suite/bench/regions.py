"""`python -m suite bench regions`: gcs's offline cost, the wall time to grow one world's regions.

Each selected world is grown from nothing in this process (no cache is read or written), exactly as
`regions build` grows it with gcs's default region options (`grow_for_world`; `grow_for_problem`
under `seeding: problem`). Worlds are chosen
among a dataset tier's problems, either the slowest ones of the shipped cache (its recorded
`offline_s`: the worst case the per-world budget is about) or spread evenly over the tier. Each
world is timed once (a build takes tens of seconds; its variation is in the spread of worlds).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import time

from suite.cli.args import positive_int
from suite.problems import DEFAULT_TIER


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--dataset", default=DEFAULT_TIER, help=f"NAME[:TIER] (default {DEFAULT_TIER})")
    p.add_argument("--worlds", type=positive_int, default=6, help="worlds to grow (default 6)")
    p.add_argument("--pick", choices=("slowest", "spread"), default="slowest",
                   help="the worlds the shipped cache records as slowest, or spread over the tier (default slowest)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")


def _cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def pick_worlds(ds, options, *, worlds: int, pick: str) -> list:
    """(problem_id, problem, recorded offline_s or None) of the chosen worlds (one problem each)."""
    from planners.gcs.sets import RegionSet, find_cached, world_hash

    first: dict[str, tuple] = {}
    for pid, problem in zip(ds.ids, ds.problems):
        whash = world_hash(problem, options)
        if whash not in first:
            path = find_cached(whash, None)
            recorded = RegionSet.load(path).offline_s if path is not None else None
            first[whash] = (pid, problem, recorded)
    rows = list(first.values())
    if pick == "slowest":
        rows.sort(key=lambda r: -(r[2] or 0.0))
        return rows[:worlds]
    step = max(1, len(rows) // worlds)
    return rows[::step][:worlds]


def measure(text: str, *, worlds: int, pick: str) -> dict:
    from planners.gcs.iris import RegionBuilder, quiet_drake
    from planners.gcs.regions import grow_for_problem, grow_for_world
    from planners.gcs.sets import RegionOptions, RegionSet, world_hash
    from suite.problems.dataset import load_dataset

    ds = load_dataset(text)
    options = RegionOptions()
    rows = []
    for pid, problem, recorded in pick_worlds(ds, options, worlds=worlds, pick=pick):
        rs = RegionSet(world_hash(problem, options), iris=options.iris)
        t0, c0 = time.perf_counter(), _cpu_s()
        grow = grow_for_problem if options.seeding == "problem" else grow_for_world
        with quiet_drake():  # as `regions build` grows them
            grow(rs, problem, RegionBuilder(problem, options))
        wall, cpu = time.perf_counter() - t0, _cpu_s() - c0
        rows.append({"problem_id": pid, "family": ds.meta[pid]["family"], "kind": ds.meta[pid]["kind"],
                     "regions": len(rs.seeds), "wall_s": round(wall, 1), "cpu_s": round(cpu, 1),
                     "iris_and_checks_s": round(sum(rs.region_build_s), 1),
                     "recorded_s": None if recorded is None else round(recorded, 1)})
    walls = [r["wall_s"] for r in rows]
    return {"dataset": text, "pick": pick, "iris": options.iris, "cores": os.cpu_count(),
            "load_1min": round(os.getloadavg()[0], 2), "worlds": rows,
            "wall_s_median": round(statistics.median(walls), 1), "wall_s_max": max(walls)}


def run(args: argparse.Namespace) -> int:
    fig = measure(args.dataset, worlds=args.worlds, pick=args.pick)
    if args.json:
        print(json.dumps(fig))
        return 0
    print(f"gcs regions grown from nothing ({fig['iris']}, one process, one thread) for {len(fig['worlds'])} "
          f"{fig['pick']} worlds of {fig['dataset']}; load {fig['load_1min']} on {fig['cores']} cores")
    print(f"{'problem':22s} {'family':8s} {'kind':8s} {'regions':>7s} {'wall s':>7s} {'cpu s':>6s} "
          f"{'IRIS+checks':>11s} {'shipped':>8s}")
    for r in fig["worlds"]:
        print(f"{r['problem_id']:22s} {r['family']:8s} {r['kind']:8s} {r['regions']:7d} {r['wall_s']:7.1f} "
              f"{r['cpu_s']:6.1f} {r['iris_and_checks_s']:11.1f} {r['recorded_s']!s:>8s}")
    print(f"per world: median {fig['wall_s_median']} s, max {fig['wall_s_max']} s")
    return 0
