"""`python -m suite rescore DIR`: recompute every metric of a run from its stored paths, then redraw its report."""

from __future__ import annotations

import argparse


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("dir", metavar="DIR", help="a run directory holding trials.jsonl (rewritten in place)")
    p.add_argument("--no-plots", action="store_true", help="write only the summary tables and benchmark logs")
    p.add_argument("--seed", type=int, default=0, help="seed of the bootstrap confidence intervals (default 0)")


def run(args: argparse.Namespace) -> int:
    from suite.report.write import write_report
    from suite.run.rescore import rescore_run

    counts = rescore_run(args.dir)
    table = write_report(args.dir, plots=not args.no_plots, seed=args.seed)
    print(table)
    print(counts.line())
    return 0
