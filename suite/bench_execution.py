"""`python -m suite bench execution`: are the cans recycled in physics, and how fast is the simulation?

For each variant and grasp source, every planner plans and executes `--scenes` generated scenes
of `--cans` cans (one job per planner and scene, planned in the job's own process). Printed per
planner: scenes whose every problem was planned, cans in the bin among those scenes (the figure
that judges execution), cans in the bin over all scenes, unintended contacts, and the simulation's
real-time factor (simulated / wall time of the simulation alone; one job per core).
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from suite.args import nonneg_int, positive_int


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--planners", default="ik,rrt,trajopt", help="planners (default ik,rrt,trajopt)")
    p.add_argument("--variants", default="open,wall", help="variants (default open,wall)")
    p.add_argument("--grasps", default="truth,perceived", help="grasp sources (default truth,perceived)")
    p.add_argument("--scenes", type=positive_int, default=10, help="scenes per variant (default 10)")
    p.add_argument("--first-seed", type=nonneg_int, default=0, help="first scene seed (default 0)")
    p.add_argument("--cans", type=positive_int, default=5, help="cans per scene (default 5)")
    p.add_argument("--jobs", type=positive_int, default=2, help="worker processes, one simulation each (default 2)")
    p.add_argument("--reperceive", action="store_true", help="closed loop: perceive and plan after each pick")
    p.add_argument("--json", metavar="FILE", default=None, help="also write every execution record to FILE")


def run(args: argparse.Namespace) -> int:
    from planners.registry import parse_planner_list, planner_class
    from scenes.generate import generate_scene
    from scenes.spec import available_variants, load_spec
    from suite.errors import SuiteError
    from suite.execute_runs import ExecutionJob, run_jobs
    from suite.trial import config_dict, make_config

    planners = parse_planner_list(args.planners)
    variants = [v for v in args.variants.split(",") if v]
    for v in variants:
        if v not in available_variants(None):
            raise SuiteError(f"unknown variant {v!r}; allowed: {available_variants(None)}")
    grasp_modes = [g for g in args.grasps.split(",") if g]
    for g in grasp_modes:
        if g not in ("truth", "perceived"):
            raise SuiteError(f"unknown grasp source {g!r}; allowed: truth, perceived")
    configs = {p: config_dict(make_config(planner_class(p), None)) for p in planners}
    jobs = []
    for variant in variants:
        spec = load_spec(variant=variant).with_can_count(args.cans)
        for seed in range(args.first_seed, args.first_seed + args.scenes):
            scene = generate_scene(spec, seed=seed)
            for grasps in grasp_modes:
                for p in planners:
                    jobs.append(ExecutionJob(p, configs[p], scene, grasps, 5.0, seed, reperceive=args.reperceive))
    print(f"{len(jobs)} executions ({len(planners)} planners x {len(variants)} variants x {args.scenes} scenes "
          f"x {len(grasp_modes)} grasp sources, {args.cans} cans each) on {args.jobs} worker(s)")
    t0 = time.perf_counter()
    records = run_jobs(jobs, workers=args.jobs)
    print(f"done in {time.perf_counter() - t0:.0f} s wall")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"executions": records}, f, indent=1)
    for variant in variants:
        for grasps in grasp_modes:
            print(f"\n{variant}, {grasps} grasps{' (closed loop)' if args.reperceive else ''}:")
            print(f"  {'planner':<9} {'fully planned':>13} {'in bin (fully planned)':>23} {'in bin (all)':>13} "
                  f"{'collisions':>10} {'peak track':>10} {'RTF median':>10} {'errors':>6}")
            for p in planners:
                runs = [r for r in records if r["planner"] == p and r["variant"] == variant and r["grasps"] == grasps]
                ok = [r for r in runs if "error" not in r]
                full = [r for r in ok if not r["stopped"] and r["cans_attempted"] == r["cans_total"]]
                fb, ft = sum(r["cans_in_bin"] for r in full), sum(r["cans_total"] for r in full)
                ab, at = sum(r["cans_in_bin"] for r in ok), sum(r["cans_total"] for r in runs)
                rtf = np.median([r["real_time_factor"] for r in ok]) if ok else float("nan")
                peak = max((r["peak_tracking_error_rad"] for r in ok), default=float("nan"))
                print(f"  {p:<9} {len(full):>6}/{len(runs):<6} {fb:>9}/{ft:<4} ({100 * fb / max(ft, 1):5.1f}%) "
                      f"{ab:>6}/{at:<4} {sum(r['collisions'] for r in ok):>10} {peak * 1e3:>7.1f} mrad "
                      f"{rtf:>7.2f}x {len(runs) - len(ok):>6}")
    return 0
