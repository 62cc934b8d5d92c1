"""`python -m suite import`: judge an external planner's results file like a suite trial."""

from __future__ import annotations

import argparse
import sys

from suite.cli.args import positive_float
from suite.problems import DEFAULT_TIER


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--dataset", default=DEFAULT_TIER, metavar="NAME[:TIER]",
                   help=f"the dataset (tier) the problems were exported from (default {DEFAULT_TIER}); "
                        "its problems missing from the file are recorded as no_result")
    p.add_argument("--results", required=True, metavar="FILE",
                   help="JSON lines: problem_id, status, path (N x 7 rad, or null), planning_time_s [, hardware, notes, stats]")
    p.add_argument("--planner", required=True, help="the name the external planner's records carry")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--out", metavar="DIR", help="a new run directory for the records")
    where.add_argument("--into", metavar="RUN", help="an existing run on the same dataset to add the records to")
    p.add_argument("--time-limit-s", type=positive_float, default=5.0,
                   help="the budget the problems were exported with, seconds (default 5)")
    p.add_argument("--no-plots", action="store_true", help="write only the summary tables and benchmark logs")
    p.add_argument("--explain", action="store_true",
                   help="for every claimed path rejected for collision, print how deeply and where it collides")


def run(args: argparse.Namespace) -> int:
    from suite.exchange.results import import_results
    from suite.report.write import write_report

    run_dir, counts = import_results(dataset=args.dataset, results=args.results, planner=args.planner,
                                     out=args.out, into=args.into, time_limit_s=args.time_limit_s,
                                     argv=sys.argv[1:])
    print(write_report(run_dir, plots=not args.no_plots))
    print(counts.line())
    if args.explain:
        from suite.exchange.explain import explain_rejections
        from suite.run.records import read_trials

        mine = [r for r in read_trials(run_dir) if r.planner == args.planner]
        print("\n".join(explain_rejections(args.results, args.dataset, mine)))
    print(f"records in {run_dir}")
    return 0
