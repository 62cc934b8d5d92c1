"""`python -m suite plot DIR`: redraw a run's summary, plots, Planner Arena logs and report.html from DIR/trials.jsonl."""

from __future__ import annotations

import argparse

from suite.report.write import write_report


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("dir", metavar="DIR", help="a run directory holding trials.jsonl")
    p.add_argument("--no-plots", action="store_true", help="write only the summary tables, benchmark logs and report.html")
    p.add_argument("--no-html", action="store_true", help="do not write report.html")
    p.add_argument("--seed", type=int, default=0, help="seed of the bootstrap confidence intervals (default 0)")


def run(args: argparse.Namespace) -> int:
    print(write_report(args.dir, plots=not args.no_plots, html=not args.no_html, seed=args.seed))
    return 0
