"""`python -m suite bench planners`: the planners' figures and the timing+metrics cost."""

from __future__ import annotations

import argparse

from suite.cli.args import nonneg_int, positive_int


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scenes", type=positive_int, default=20, help="scenes per variant (default 20)")
    p.add_argument("--only", default="rrt,optim,metrics",
                   help="comma-separated parts: rrt (OMPL family), optim (ik, trajopt), metrics (default all)")
    p.add_argument("--first-seed", type=nonneg_int, default=0,
                   help="first scene seed (default 0): another range checks the figures on unseen scenes")
    p.add_argument("--repeats", type=positive_int, default=50, help="repeats of the metrics benchmark (default 50)")


def run(args: argparse.Namespace) -> int:
    from scenes.errors import SuiteError

    parts = [s.strip() for s in args.only.split(",") if s.strip()]
    unknown = set(parts) - {"rrt", "optim", "metrics"}
    if unknown:
        raise SuiteError(f"--only: unknown part {sorted(unknown)[0]!r}; allowed: rrt, optim, metrics")
    from suite.run.runner import worker_init

    worker_init()
    if "rrt" in parts:
        from suite.bench.ompl import run_bench as ompl_bench

        ompl_bench(scenes=args.scenes, variant="wall", first_seed=args.first_seed)
    if "optim" in parts:
        from suite.bench.optim import run_bench as optim_bench

        for variant in ("open", "wall"):
            optim_bench(scenes=args.scenes, variant=variant, first_seed=args.first_seed)
    if "metrics" in parts:
        from suite.bench.metrics import run_bench as metrics_bench

        metrics_bench(repeats=args.repeats)
    return 0
