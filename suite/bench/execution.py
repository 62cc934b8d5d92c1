"""`python -m suite bench execution`: are the cans recycled in physics, and how fast is the simulation?

For each variant and grasp source, every planner plans and executes `--scenes` generated scenes
of `--cans` cans (one job per planner and scene, planned in the job's own process). Printed per
planner (`suite.report.summary_execution.execution_table`, as in a run's summary): cans in the bin over all scenes,
and among the scenes whose every problem was planned (the figure that judges execution), where
the others ended, unintended contacts, tracking, slip, and the simulation's real-time factor
(simulated / wall time of the simulation alone; one job per core).
"""

from __future__ import annotations

import argparse
import json
import time

from suite.cli.args import nonneg_int, positive_int


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
    from scenes.errors import SuiteError
    from suite.execution.jobs import ExecutionJob, run_jobs
    from suite.run.trial import config_dict, make_config

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
    from suite.report.summary_execution import execution_table

    for variant in variants:
        for grasps in grasp_modes:
            print(f"\n{variant}, {grasps} grasps{' (closed loop)' if args.reperceive else ''}:")
            subset = [r for r in records if r["variant"] == variant and r["grasps"] == grasps]
            print(execution_table(subset, planners=planners, tablefmt="simple"))
    return 0
