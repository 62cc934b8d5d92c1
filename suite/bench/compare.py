"""`python -m suite bench compare`: trial throughput of the local executor at several --jobs."""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from suite.cli.args import positive_int


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--jobs-list", default="1,2", help="worker counts to compare (default 1,2)")
    p.add_argument("--scenes", type=positive_int, default=4, help="scenes (default 4)")
    p.add_argument("--cans", type=positive_int, default=3, help="cans per scene (default 3)")
    p.add_argument("--repeats", type=positive_int, default=2, help="runs per worker count (default 2)")


def run(args: argparse.Namespace) -> int:
    from scenes.errors import SuiteError
    from suite.run.runner import CompareConfig, make_executor, prepare_trials, run_trials

    try:
        jobs_list = [int(j) for j in args.jobs_list.split(",")]
    except ValueError:
        raise SuiteError(f"--jobs-list must be integers like 1,2, got {args.jobs_list!r}") from None
    config = CompareConfig(scenes=args.scenes, cans=args.cans, dataset=None)
    t0 = time.perf_counter()
    trials = prepare_trials(config)
    print(f"{len(trials)} trials ({','.join(config.planners)}, {config.scenes} {config.variant} scenes x "
          f"{config.cans} cans) prepared in {time.perf_counter() - t0:.1f} s")
    rates = {}
    for jobs in jobs_list:
        walls = []
        for _ in range(args.repeats):
            with tempfile.TemporaryDirectory() as d:
                executor = make_executor("local", jobs=jobs)
                executor.start()
                time.sleep(5.0)  # workers ready, as in `compare`, where they start during preparation
                t = time.perf_counter()
                run_trials(trials, out=Path(d), jobs=jobs, executor=executor, progress_bar=False)
                walls.append(time.perf_counter() - t)
        best = sorted(walls)[len(walls) // 2]
        rates[jobs] = len(trials) / best
        print(f"--jobs {jobs}: {', '.join(f'{w:.1f}' for w in walls)} s wall (median {best:.1f} s), "
              f"{rates[jobs]:.1f} trials/s (workers started beforehand)")
    base = rates.get(1)
    if base:
        for jobs, rate in rates.items():
            if jobs != 1:
                print(f"throughput --jobs {jobs} / --jobs 1: {rate / base:.2f}x")
    return 0
