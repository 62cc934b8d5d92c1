"""Writing a run's summary: summary.md, summary.csv and paired.csv.

The numbers come from `summary_stats` (success rates, metric medians with IQR, paired comparisons),
the tables from `summary_tables` and `summary_execution`; everything is computed from the saved
trial records alone (see `suite.run.records`).
"""

from __future__ import annotations

import csv
import logging
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from suite.report.summary_execution import EXECUTION_INTRO, execution_table
from suite.report.summary_stats import (
    SUMMARY_METRICS,
    GroupSummary,
    paired_comparisons,
    summarize,
)
from suite.report.summary_tables import summary_markdown
from suite.run.records import STATUSES, planners_in

log = logging.getLogger(__name__)


def _csv_rows(groups: Sequence[GroupSummary]) -> tuple[list[str], list[list[Any]]]:
    headers = ["planner", "problem", "variant", "n", "successes", "success_rate"]
    for m in SUMMARY_METRICS:
        headers += [f"{m}_n", f"{m}_median", f"{m}_q1", f"{m}_q3"]
    headers += [f"status_{s}" for s in STATUSES]
    rows = []
    for g in groups:
        row: list[Any] = [g.planner, g.problem, g.variant, g.n, g.successes, g.success_rate]
        for m in SUMMARY_METRICS:
            s = g.metrics[m]
            row += [s.n, s.median, s.q1, s.q3]
        row += [g.status_counts.get(s, 0) for s in STATUSES]
        rows.append(row)
    return headers, rows


def _write_csv(path: Path, headers: list[str], rows: list[list[Any]]) -> None:
    with path.open("w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(headers)
        for row in rows:
            w.writerow(["" if isinstance(v, float) and not math.isfinite(v) else v for v in row])


def write_summary(
    run_dir: str | Path,
    records: Sequence[dict[str, Any]],
    *,
    planners: Sequence[str] | None = None,
    seed: int = 0,
    title: str | None = None,
    executions: Sequence[dict[str, Any]] = (),
) -> list[Path]:
    """Write summary.md, summary.csv (per planner, per planner x kind, per planner x variant) and paired.csv.

    Args:
        run_dir: the run directory to write into.
        records: the run's trial records.
        planners: planners in display order (default: order of appearance).
        seed: seeds the bootstrap's generator, so the written CIs are reproducible.
        title: the summary's heading (default: "Run summary: <run directory name>").
        executions: the run's physics execution records (execution.json), if it was executed.

    Returns:
        The written files.
    """
    run_dir = Path(run_dir)
    planners = list(planners) if planners is not None else planners_in(records)
    pairs = paired_comparisons(records, rng=np.random.default_rng(seed), planners=planners)
    md_path, csv_path, paired_path = run_dir / "summary.md", run_dir / "summary.csv", run_dir / "paired.csv"
    md = summary_markdown(records, pairs=pairs, planners=planners, title=title or f"Run summary: {run_dir.name}")
    if executions:
        md += "\n" + EXECUTION_INTRO + "\n" + execution_table(executions, planners=planners) + "\n"
    md_path.write_text(md, encoding="utf-8")
    groups = [
        *summarize(records, planners=planners),
        *summarize(records, by="problem", planners=planners),
        *summarize(records, by="variant", planners=planners),
    ]
    _write_csv(csv_path, *_csv_rows(groups))
    _write_csv(
        paired_path,
        ["metric", "planner_a", "planner_b", "n", "median_diff", "ci95_low", "ci95_high", "wilcoxon_p"],
        [[c.metric, c.planner_a, c.planner_b, c.n, c.median_diff, c.ci_low, c.ci_high, c.p_value] for c in pairs],
    )
    log.info("wrote %s, %s, %s", md_path, csv_path, paired_path)
    return [md_path, csv_path, paired_path]
