"""`python -m suite plot DIR`: redraw a run's summary, plots and Planner Arena logs from DIR/trials.jsonl."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from suite.errors import SuiteError
from suite.records import TRIALS_FILE

log = logging.getLogger(__name__)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("dir", metavar="DIR", help="a run directory holding trials.jsonl")
    p.add_argument("--no-plots", action="store_true", help="write only the summary tables and benchmark logs")
    p.add_argument("--seed", type=int, default=0, help="seed of the bootstrap confidence intervals (default 0)")


def write_report(run_dir: str | Path, *, plots: bool = True, seed: int = 0) -> str:
    """Write everything derived from a run's records: summary.md/.csv, paired.csv, arena logs, plots.

    Args:
        run_dir: the run directory (trials.jsonl, optionally manifest.json).
        plots: also draw the PNG figures (the slowest part, a few seconds).
        seed: seeds the bootstrap generator of the paired comparisons.

    Returns:
        The per-planner summary table, printable.

    Raises:
        SuiteError: DIR does not exist or holds no trials.jsonl, or a record line is broken.
    """
    from suite.arena import write_arena_logs
    from suite.records import planners_in, read_manifest, read_trials
    from suite.summary import summary_table, write_summary

    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise SuiteError(f"run directory {str(run_dir)!r} does not exist")
    if not (run_dir / TRIALS_FILE).is_file():
        raise SuiteError(f"run directory {str(run_dir)!r} holds no {TRIALS_FILE}")
    records = read_trials(run_dir / TRIALS_FILE)
    planners = planners_in(records, read_manifest(run_dir))
    written = write_summary(run_dir, records, planners=planners, seed=seed)
    written += write_arena_logs(run_dir, records=records)
    if plots:
        from suite.plots import make_plots

        written += make_plots(run_dir, records=records)
    log.debug("wrote %s", ", ".join(str(p) for p in written))
    return summary_table(records, planners=planners)


def run(args: argparse.Namespace) -> int:
    print(write_report(args.dir, plots=not args.no_plots, seed=args.seed))
    return 0
