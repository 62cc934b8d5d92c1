"""report.html: one self-contained page per run, from the headline to a single problem.

The page holds the run's settings and provenance, the summary's tables (per planner with intervals,
per family and kind, failures by status and by stated reason, certification, paired comparisons),
the PNG figures `make_plots` drew (inlined, not drawn again), a filterable and sortable problem
table and one drill-down per problem (scene from above and the side with every planner's gripper
path, statuses, reasons, timings, metrics, joint paths), and execution in physics when the run has
it. CSS, JavaScript, images and drawing data are all inline: it opens from the file system with no
network and no server. Everything comes from the run directory's files (`suite.run.records`).

The 3-D replay of a problem is not inlined: a Meshcat static page is about 3.5 MB, a hundred would
be hundreds of MB. `python -m suite replay RUN PROBLEM` writes one on demand (`suite.report.replay`).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from pathlib import Path

from scenes.errors import SuiteError
from suite.execution.execution_records import ExecutionRecord
from suite.report.html.page import REPORT_FILE, render
from suite.run.records import TRIALS_FILE, TrialRecord

log = logging.getLogger(__name__)

__all__ = ["REPORT_FILE", "write_html"]


def write_html(
    run_dir: str | Path,
    *,
    records: Sequence[TrialRecord] | None = None,
    planners: Sequence[str] | None = None,
    summary=None,
    pairs=None,
    executions: Sequence[ExecutionRecord] | None = None,
    seed: int = 0,
) -> Path:
    """Write run_dir/report.html from the run's saved files.

    Args:
        run_dir: the run directory (trials.jsonl; manifest.json, plots/, execution.json if present).
        records, planners, summary, pairs, executions: what the caller already computed from the same
            files (`write_report` passes them, so nothing is computed twice); read or computed here if None.
        seed: seeds the paired comparisons' bootstrap when they are computed here.

    Returns:
        The written report.html.

    Raises:
        SuiteError: run_dir is not a run directory, or its records cannot be read.
    """
    import numpy as np

    from suite.execution.execution_records import read_execution
    from suite.report.budgets import by_budget_view
    from suite.report.summary_stats import paired_comparisons, summarize_run
    from suite.run.records import planners_in, read_manifest, read_trials

    t0 = time.perf_counter()
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise SuiteError(f"run directory {str(run_dir)!r} does not exist")
    if records is None:
        if not (run_dir / TRIALS_FILE).is_file():
            raise SuiteError(f"run directory {str(run_dir)!r} holds no {TRIALS_FILE}: the report is built from "
                             "a run's trial records")
        records = by_budget_view(read_trials(run_dir / TRIALS_FILE))
    if not records:
        raise SuiteError(f"{str(run_dir / TRIALS_FILE)!r} holds no trial record yet: nothing to report")
    manifest = read_manifest(run_dir)
    planners = list(planners) if planners is not None else planners_in(records, manifest)
    summary = summary or summarize_run(records, planners=planners)
    if pairs is None:
        pairs = paired_comparisons(records, rng=np.random.default_rng(seed), planners=planners)
    executions = read_execution(run_dir) if executions is None else executions
    page = render(run_dir, records=records, manifest=manifest, planners=planners, summary=summary, pairs=pairs,
                  executions=executions, command_dir=str(run_dir))
    path = run_dir / REPORT_FILE
    path.write_text(page, encoding="utf-8")
    log.info("wrote %s (%.1f MB) in %.1f s", path, path.stat().st_size / 1e6, time.perf_counter() - t0)
    return path
