"""`python -m suite bench gcs-regions`: gcs's world-only region strategies, measured per world.

For each chosen collision world of a dataset tier (families and kinds filtered, one job per world,
at most `--jobs` worker processes), each strategy (`--strategies`, values of gcs's `seeding`)
builds the world's regions from nothing into a scratch directory (no shipped cache is read), as
`regions build` would; then every problem of the tier in that world is planned by `gcs` with
those regions (its online joining of start and goal and its GCS solve are timed as a trial's
planning time), and its path is judged by the suite's validator. Per world it reports:

- offline seconds (`RegionSet.offline_s`) and the number of regions;
- coverage: the fraction of collision-free samples inside some region, for two sample
  distributions: "task" (the world's task chain, `planners.gcs.cover.task_chain`, perturbed by a
  Gaussian of 0.25 rad per joint: `task_samples`; a fixed seed other than the build's) and
  "uniform" (uniform in the joint limits); 500 collision-free samples each (python-fcl);
- per problem: whether start and goal are connected (after the online joins), the planning time
  (joins + GCS solves + repairs), the GCS solve time of the first solve, and success.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from suite.cli.args import positive_int

COVERAGE_SAMPLES = 500
COVERAGE_SEED = 4242


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--dataset", default="recycle-v3:tune", help="NAME[:TIER] (default recycle-v3:tune)")
    p.add_argument("--families", default="window,shelf", help="families whose worlds to build (default window,shelf)")
    p.add_argument("--kinds", default="window=transit,return",
                   help="per family, only worlds with a problem of these kinds: FAMILY=KIND,KIND;... "
                        "(default window=transit,return; '' for all)")
    p.add_argument("--strategies", default="chain,cliques", help="gcs seedings to compare (default chain,cliques)")
    p.add_argument("--iris", default="np2", help="IRIS algorithm (np2 or zo; default np2)")
    p.add_argument("--worlds", type=positive_int, default=None, help="at most this many worlds per family")
    p.add_argument("--jobs", type=positive_int, default=2, help="worker processes (default 2)")
    p.add_argument("--time-limit-s", type=float, default=5.0, help="each problem's planning budget (default 5)")
    p.add_argument("--out", default=None, help="also write the figures as JSON to this file")


def parse_kinds(text: str) -> dict[str, set[str]]:
    """FAMILY=KIND,KIND;FAMILY=KIND -> {family: kinds}."""
    out = {}
    for part in filter(None, (t.strip() for t in text.split(";"))):
        fam, _, kinds = part.partition("=")
        out[fam.strip()] = {k.strip() for k in kinds.split(",") if k.strip()}
    return out


def pick_worlds(ds, *, families: set[str], kinds: dict[str, set[str]], per_family: int | None) -> list[list]:
    """Problems grouped by collision world, worlds in dataset order, at most per_family each; a
    family named in `kinds` keeps only worlds holding a problem of those kinds."""
    worlds: dict[tuple, list] = {}
    for pid, problem in zip(ds.ids, ds.problems):
        m = ds.meta[pid]
        if m["family"] not in families or problem.pre_status is not None or problem.q_goal is None:
            continue
        worlds.setdefault(problem.world_key(), []).append((pid, m["family"], m["kind"], problem))
    rows = [w for w in worlds.values() if w[0][1] not in kinds or any(k in kinds[w[0][1]] for _, _, k, _ in w)]
    out, count = [], {}
    for w in rows:
        fam = w[0][1]
        if per_family is not None and count.get(fam, 0) >= per_family:
            continue
        count[fam] = count.get(fam, 0) + 1
        out.append(w)
    return out


def coverage_samples(problem, *, seed: int) -> dict[str, np.ndarray]:
    """The coverage distributions' collision-free samples (see the module docstring)."""
    from planners.gcs.cover import free_task_samples, task_chain
    from planners.worlds import collision_world

    world = collision_world(problem)
    rng = np.random.default_rng(seed)
    out = {}
    chain, _ = task_chain(problem, seed=1234)
    out["task"] = (free_task_samples(chain, n=COVERAGE_SAMPLES, sigma_rad=0.25, rng=rng, world=world)
                   if chain is not None else np.zeros((0, 7)))
    lo, hi = world.robot.lower_rad, world.robot.upper_rad
    got = []
    while sum(len(g) for g in got) < COVERAGE_SAMPLES:
        Q = rng.uniform(lo, hi, (COVERAGE_SAMPLES, 7))
        got.append(Q[world.states_free(Q)])
    out["uniform"] = np.concatenate(got)[:COVERAGE_SAMPLES]
    return out


def measure_world(payload: tuple) -> dict:
    """Worker: build one world's regions with each strategy and plan its problems with them."""
    items, strategies, iris, time_limit_s = payload
    from planners.gcs.planner import GcsConfig, GcsPlanner
    from planners.gcs.regions import coverage_of, regions_for
    from planners.worlds import collision_world
    from suite.scoring.validate import validate_path

    first = items[0][3]
    samples = coverage_samples(first, seed=COVERAGE_SEED)
    row = {"family": items[0][1], "problems": [(pid, kind) for pid, _, kind, _ in items], "strategies": {}}
    for strategy in strategies:
        with tempfile.TemporaryDirectory() as tmp:
            cfg = GcsConfig(seeding=strategy, iris=iris, regions_dir=tmp, build_regions=False)
            t0 = time.perf_counter()
            rs, info = regions_for(first, cfg.region_options(), cache_dir=tmp, build=True, fresh=True)
            build_wall = time.perf_counter() - t0
            planner = GcsPlanner(cfg)
            trials = []
            for pid, _, kind, problem in items:
                problem = problem.with_(time_limit_s=time_limit_s)
                planner.prepare(problem)
                t1 = time.perf_counter()
                result = planner.plan(problem)
                wall = time.perf_counter() - t1
                st = result.stats
                reason = validate_path(problem, result.path, collision_world(problem)) if result.path is not None else None
                trials.append({
                    "problem_id": pid, "kind": kind, "status": result.status.value,
                    "valid": result.path is not None and reason is None,
                    "connected": bool(st.get("regions_connected", False)),
                    "joins": [st.get("start_join"), st.get("goal_join")], "online_regions": st.get("online_regions"),
                    "planning_s": round(wall, 3), "gcs_first_solve_s": st.get("first_solve_s"),
                    "repairs": st.get("repairs"), "reason_code": st.get("reason_code"),
                })
        build = info.get("build", {})
        row["strategies"][strategy] = {
            "offline_s": round(rs.offline_s, 1), "build_wall_s": round(build_wall, 1), "regions": len(rs),
            "coverage_task": round(coverage_of(rs, samples["task"]), 3),
            "coverage_uniform": round(coverage_of(rs, samples["uniform"]), 3),
            "chain_rad": build.get("chain_rad"), "ends_connected": build.get("ends_connected"),
            "trials": trials,
        }
    return row


def _median(xs):
    xs = [x for x in xs if x is not None]
    return round(statistics.median(xs), 3) if xs else None


def _p90(xs):
    xs = sorted(x for x in xs if x is not None)
    return round(xs[min(len(xs) - 1, int(np.ceil(0.9 * len(xs))) - 1)], 1) if xs else None


def summarize(rows: list[dict], strategies: list[str]) -> dict:
    out = {}
    for s in strategies:
        per = [r["strategies"][s] for r in rows if s in r["strategies"]]
        trials = [t for p in per for t in p["trials"]]
        tw = [t for r in rows for t in r["strategies"].get(s, {}).get("trials", [])
              if r["family"] == "window" and t["kind"] in ("transit", "return")]
        out[s] = {
            "worlds": len(per), "offline_s_median": _median([p["offline_s"] for p in per]),
            "offline_s_p90": _p90([p["offline_s"] for p in per]),
            "regions_median": _median([p["regions"] for p in per]),
            "coverage_task_median": _median([p["coverage_task"] for p in per]),
            "coverage_uniform_median": _median([p["coverage_uniform"] for p in per]),
            "problems": len(trials), "connected": sum(t["connected"] for t in trials),
            "valid": sum(t["valid"] for t in trials),
            "window_transit_return": f"{sum(t['valid'] for t in tw)}/{len(tw)}",
            "planning_s_median": _median([t["planning_s"] for t in trials if t["connected"]]),
            "gcs_first_solve_s_median": _median([t["gcs_first_solve_s"] for t in trials]),
        }
    return out


def run(args: argparse.Namespace) -> int:
    from suite.problems.dataset import load_dataset
    from suite.run.executors import Job, LocalExecutor

    ds = load_dataset(args.dataset)
    families = set(args.families.split(","))
    kinds = parse_kinds(args.kinds)
    strategies = args.strategies.split(",")
    worlds = pick_worlds(ds, families=families, kinds=kinds, per_family=args.worlds)
    load0 = os.getloadavg()
    print(f"{len(worlds)} worlds of {args.dataset} ({', '.join(sorted(families))}); strategies "
          f"{', '.join(strategies)} ({args.iris}); {args.jobs} workers; load {load0[0]:.2f}", flush=True)
    jobs = [Job(w[0][0], measure_world, (w, strategies, args.iris, args.time_limit_s), 3600.0) for w in worlds]
    rows = []
    t0 = time.perf_counter()
    outcomes = LocalExecutor(jobs=args.jobs).run(jobs)
    try:
        for outcome in outcomes:
            if outcome.result is None:
                print(f"{outcome.job.key}: {outcome.failure} ({outcome.message})", flush=True)
                continue
            r = outcome.result
            rows.append(r)
            for s, f in r["strategies"].items():
                t = f["trials"]
                print(f"{outcome.job.key} {r['family']:7s} {s:8s} offline {f['offline_s']:6.1f} s "
                      f"regions {f['regions']:3d} cov task {f['coverage_task']:.2f} uniform {f['coverage_uniform']:.3f} "
                      f"connected {sum(x['connected'] for x in t)}/{len(t)} valid {sum(x['valid'] for x in t)}/{len(t)} "
                      f"plan s {[x['planning_s'] for x in t]} load {os.getloadavg()[0]:.2f}", flush=True)
    finally:
        outcomes.close()
    summary = summarize(rows, strategies)
    for s, f in summary.items():
        print(f"{s}: " + ", ".join(f"{k} {v}" for k, v in f.items()))
    fig = {"dataset": args.dataset, "families": sorted(families), "kinds": {f: sorted(k) for f, k in kinds.items()},
           "iris": args.iris, "strategies": strategies, "jobs": args.jobs, "time_limit_s": args.time_limit_s,
           "cores": os.cpu_count(), "load_start": [round(x, 2) for x in load0],
           "load_end": [round(x, 2) for x in os.getloadavg()], "wall_s": round(time.perf_counter() - t0, 1),
           "summary": summary, "worlds": rows}
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(fig, indent=1))
    return 0
