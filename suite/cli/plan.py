"""`python -m suite plan`: every problem of one scene with one planner, in this process."""

from __future__ import annotations

import argparse
import json
import sys

from suite.cli.args import add_planning_arguments, scene_from_args


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_planning_arguments(p)
    p.add_argument("--json", action="store_true", help="print one JSON object with every problem's result")


def run(args: argparse.Namespace) -> int:
    from planners.registry import planner_class
    from suite.problems.cycle import build_problems
    from suite.run.runner import scene_grasps, worker_init
    from suite.run.trial import config_dict, make_config, run_problem

    cls = planner_class(args.planner)  # unknown names fail here, listing the known ones
    config = config_dict(make_config(cls, None))
    worker_init()
    scene = scene_from_args(args)
    grasps = scene_grasps(scene, grasps=args.grasps)
    problems = build_problems(scene, grasps, time_limit_s=args.time_limit_s, seed=args.seed)
    out = []
    for problem in problems:
        rec = run_problem(problem, planner=args.planner, planner_config=config, run_seed=args.seed)
        out.append({"can_id": rec.can_id, "problem": rec.problem, "status": rec.status,
                    "planning_time_s": rec.planning_time_s, "path": rec.path, "metrics": rec.metrics,
                    "stats": rec.stats})
        if not args.json:
            n = len(rec.path) if rec.path else 0
            print(f"can {rec.can_id} {rec.problem:<8} {rec.status:<16} "
                  f"{rec.planning_time_s * 1e3:8.1f} ms  {n:4d} waypoints", file=sys.stdout)
    if args.json:
        print(json.dumps({"planner": args.planner, "seed": args.seed, "variant": scene.variant, "problems": out}))
    return 0
