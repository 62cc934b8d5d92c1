"""`python -m suite report RUN`: write RUN/report.html, the run's self-contained one-page report.

Works on any run directory with a trials.jsonl, including runs of earlier datasets and suite
versions (fields a record lacks are shown as absent, never filled in). The PNG figures in RUN/plots
are inlined as they are; a run without them (`--no-plots`, or an old run) gets them drawn first.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from scenes.errors import SuiteError


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", metavar="RUN", help="a run directory holding trials.jsonl")
    p.add_argument("--no-plots", action="store_true",
                   help="do not draw the figures when RUN/plots is missing (the page then has none)")
    p.add_argument("--seed", type=int, default=0, help="seed of the paired comparisons' bootstrap (default 0)")


def run(args: argparse.Namespace) -> int:
    from suite.report.html import write_html
    from suite.run.records import TRIALS_FILE

    run_dir = Path(args.run)
    if not run_dir.is_dir():
        raise SuiteError(f"run directory {args.run!r} does not exist")
    if not (run_dir / TRIALS_FILE).is_file():
        raise SuiteError(f"{args.run!r} holds no {TRIALS_FILE}: not a run directory (the report is built from a "
                         "run's trial records)")
    if not (run_dir / "plots").is_dir() and not args.no_plots:
        from suite.execution.execution_records import read_execution
        from suite.report.budgets import budgets_in, by_budget_view
        from suite.report.plots import make_plots
        from suite.run.records import read_trials

        print(f"{run_dir / 'plots'} is missing: drawing the figures first", file=sys.stderr)
        raw = read_trials(run_dir / TRIALS_FILE)
        make_plots(run_dir, records=by_budget_view(raw), executions=read_execution(run_dir),
                   budget_records=raw if len(budgets_in(raw)) > 1 else [])
    path = write_html(run_dir, seed=args.seed)
    print(f"{path} ({path.stat().st_size / 1e6:.1f} MB)")
    return 0
