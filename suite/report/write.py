"""Everything derived from a run's saved records, written into its directory in one call."""

from __future__ import annotations

import logging
from pathlib import Path

from scenes.errors import SuiteError
from suite.run.records import TRIALS_FILE

log = logging.getLogger(__name__)


def write_report(run_dir: str | Path, *, plots: bool = True, html: bool = True, seed: int = 0,
                 wide: bool = False) -> str:
    """Write summary.md/.csv, paired.csv, the OMPL benchmark logs (arena/), the plots (plots/) and
    report.html (which inlines those plots, so it is written last).

    Args:
        run_dir: the run directory (trials.jsonl, optionally manifest.json).
        plots: also draw the PNG figures (the slowest part, a few seconds).
        html: also write report.html (`suite.report.html`).
        seed: seeds the bootstrap generator of the paired comparisons.
        wide: the terminal table with every metric and its quartiles (`compare --wide`).

    Returns:
        The per-planner summary table, printable.

    Raises:
        SuiteError: run_dir does not exist or holds no trials.jsonl, or a record line is broken.
    """
    from suite.report.arena import write_arena_logs
    from suite.report.summary import write_summary
    from suite.report.summary_tables import summary_table
    from suite.run.records import planners_in, read_manifest, read_trials

    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise SuiteError(f"run directory {str(run_dir)!r} does not exist")
    if not (run_dir / TRIALS_FILE).is_file():
        raise SuiteError(f"run directory {str(run_dir)!r} holds no {TRIALS_FILE}")
    from suite.report.budgets import budgets_in, by_budget_view

    raw = read_trials(run_dir / TRIALS_FILE)
    records = by_budget_view(raw)  # several budgets: each (planner, budget) is its own entry
    budget_records = raw if len(budgets_in(raw)) > 1 else []
    planners = planners_in(records, read_manifest(run_dir))
    import numpy as np

    from suite.execution.execution_records import read_execution
    from suite.report.summary_execution import execution_table
    from suite.report.summary_stats import paired_comparisons, summarize_run

    executions = read_execution(run_dir)
    from suite.execution.execution_records import read_moving_bin
    from suite.report.summary_moving_bin import moving_bin_table

    moving = read_moving_bin(run_dir)
    drawing = None
    if plots:  # the figures start first, most of them in a second process, while the tables are written
        from suite.report.plots import start_plots

        drawing = start_plots(run_dir, records=records, executions=executions, budget_records=budget_records)
    summary = summarize_run(records, planners=planners)
    pairs = paired_comparisons(records, rng=np.random.default_rng(seed), planners=planners)
    written = write_summary(run_dir, records, planners=planners, seed=seed, executions=executions,
                            budget_records=budget_records, summary=summary, pairs=pairs, moving_bin=moving)
    written += write_arena_logs(run_dir, records=records)
    if drawing is not None:
        written += drawing.finish()
    if html:
        from suite.report.html import write_html

        written.append(write_html(run_dir, records=records, planners=planners, summary=summary, pairs=pairs,
                                  executions=executions))
    log.debug("wrote %s", ", ".join(str(p) for p in written))
    table = summary_table(records, planners=planners, wide=wide)
    if executions:
        table += "\n\nExecution in physics:\n" + execution_table(executions, planners=planners, tablefmt="simple")
    if moving:
        table += "\n\nMoving bin:\n" + moving_bin_table(moving, planners=planners, tablefmt="simple")
    return table
