"""`python -m suite bench dataset`: loading a frozen dataset, and generating new scenes with their problems.

Loading is timed per problem over repeated loads of a whole dataset in this process (the first
load, which pays imports, is reported apart). Generation is timed per scene for every family: the
station draw and its IK checks, the cans and their picking order, then the cycle's problems with
their goal IK (what a generated `compare` pays before any planner runs).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

from suite.cli.args import nonneg_int, positive_int
from suite.problems import DEFAULT_DATASET


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--dataset", default=DEFAULT_DATASET, help=f"dataset to load (default {DEFAULT_DATASET})")
    p.add_argument("--loads", type=positive_int, default=5, help="timed loads of the dataset (default 5)")
    p.add_argument("--scenes", type=positive_int, default=10, help="generated scenes per family (default 10)")
    p.add_argument("--first-seed", type=nonneg_int, default=50_000, help="first scene seed (default 50000)")
    p.add_argument("--cans", type=positive_int, default=5, help="cans per scene; clutter draws its own (default 5)")
    p.add_argument("--families", default=None, help="comma-separated families (default: the six that datasets are built from)")
    p.add_argument("--no-bin-warm-start", action="store_true",
                   help="pose bin goals without the previous cycle's warm start (as recycle-v1 and -v2 were built)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")


def measure_loading(name: str, *, loads: int) -> dict:
    from suite.problems.dataset import load_dataset

    t0 = time.perf_counter()
    n = len(load_dataset(name).problems)
    first = time.perf_counter() - t0
    per = []
    for _ in range(loads):
        t0 = time.perf_counter()
        load_dataset(name)
        per.append((time.perf_counter() - t0) / n * 1e3)
    return {"problems": n, "first_load_s": round(first, 3), "ms_per_problem_median": round(statistics.median(per), 3),
            "ms_per_problem_max": round(max(per), 3)}


def measure_generation(families, *, scenes: int, first_seed: int, cans: int, bin_warm_start: bool = True) -> dict:
    from scenes.errors import SuiteError
    from scenes.generate import generate_scene
    from scenes.grasp_rule import truth_grasp
    from suite.problems.cycle import build_problems
    from suite.run.build_dataset import family_spec

    out = {}
    for family in families:
        spec = family_spec(family, cans)
        scene_s, problems_s, failed = [], [], 0
        for seed in range(first_seed, first_seed + scenes):
            t0 = time.perf_counter()
            try:
                scene = generate_scene(spec, seed=seed)
            except SuiteError:
                failed += 1
                continue
            t1 = time.perf_counter()
            build_problems(scene, [truth_grasp(scene, c) for c in scene.cans], time_limit_s=1.0, seed=seed,
                           bin_warm_start=bin_warm_start)
            t2 = time.perf_counter()
            scene_s.append(t1 - t0)
            problems_s.append(t2 - t1)
        total = [a + b for a, b in zip(scene_s, problems_s)]
        out[family] = {"scenes": len(total), "failed": failed,
                       "scene_s_median": round(statistics.median(scene_s), 2) if scene_s else None,
                       "problems_s_median": round(statistics.median(problems_s), 2) if problems_s else None,
                       "total_s_median": round(statistics.median(total), 2) if total else None,
                       "total_s_max": round(max(total), 2) if total else None}
    return out


def run(args: argparse.Namespace) -> int:
    from suite.run.build_dataset import BuildSettings

    # by default the can-recycling families a dataset is built from (not `gcs-arm`: no cans)
    families = args.families.split(",") if args.families else list(BuildSettings(name="bench").families)
    figures = {"loading": measure_loading(args.dataset, loads=args.loads),
               "generation": measure_generation(families, scenes=args.scenes, first_seed=args.first_seed,
                                                cans=args.cans, bin_warm_start=not args.no_bin_warm_start)}
    if args.json:
        print(json.dumps(figures))
        return 0
    ld = figures["loading"]
    print(f"loading {args.dataset}: {ld['problems']} problems, median {ld['ms_per_problem_median']} ms per problem "
          f"(max {ld['ms_per_problem_max']}; first load with imports {ld['first_load_s']} s)")
    warm = "without" if args.no_bin_warm_start else "with"
    print(f"generating scenes from seed {args.first_seed}, bin goals {warm} the previous cycle's warm start (seconds per scene: scene with its checks + problems' goal IK):")
    print(f"{'family':10s} {'scenes':>6s} {'failed':>6s} {'scene':>7s} {'problems':>9s} {'total':>7s} {'max':>7s}")
    for fam, g in figures["generation"].items():
        print(f"{fam:10s} {g['scenes']:6d} {g['failed']:6d} {g['scene_s_median']!s:>7s} {g['problems_s_median']!s:>9s} "
              f"{g['total_s_median']!s:>7s} {g['total_s_max']!s:>7s}")
    return 0
