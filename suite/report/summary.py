"""Writing a run's summary: summary.md, summary.csv and paired.csv.

The numbers come from `summary_stats` (success rates, metric medians with IQR, paired comparisons),
the tables from `summary_tables`, `summary_search` and `summary_execution`; everything is computed from the saved
trial records alone (see `suite.run.records`).
"""

from __future__ import annotations

import csv
import json
import logging
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from tabulate import tabulate

from suite.execution.execution_records import ExecutionRecord
from suite.execution.moving_bin_records import MovingBinRecord
from suite.report.outcomes import FEW_PROBLEMS
from suite.report.summary_execution import EXECUTION_INTRO, execution_table
from suite.report.summary_search import (
    SEARCH_INTRO,
    post_processing,
    search_rows,
    search_summary,
)
from suite.report.summary_stats import (
    N_RESAMPLES,
    SUMMARY_METRICS,
    GroupSummary,
    MetricStats,
    PairedComparison,
    RunSummary,
    paired_comparisons,
    summarize_run,
)
from suite.report.summary_tables import (
    ATTRIBUTION_INTRO,
    BEST_KNOWN_INTRO,
    CERTIFICATION_INTRO,
    COLD_INTRO,
    REASON_CODE_INTRO,
    attribution_rows,
    attribution_summary,
    best_known_agreement,
    best_known_rows,
    cause_counts,
    certification_counts,
    certification_rows,
    cold_rows,
    cold_start,
    common_rows,
    composition,
    failure_rows,
    group_rows,
    paired_rows,
    reason_code_rows,
)
from suite.run.records import (
    STATUSES,
    TrialRecord,
    planners_in,
    problem_counts,
    statuses_in,
)

log = logging.getLogger(__name__)

#: summary.json's format; a reader refuses a newer one.
SUMMARY_FORMAT_VERSION = 1
#: The success-aware time's name in summary.csv and summary.json.
TIME_TO_SOLVE = "time_to_solve_s"


def _num(v: float) -> float | None:
    return float(v) if isinstance(v, (int, float)) and math.isfinite(v) else None


def _stats_json(s: MetricStats) -> dict[str, Any]:
    return {"median": _num(s.median), "q1": _num(s.q1), "q3": _num(s.q3), "n": s.n}


def _success_json(g: GroupSummary) -> dict[str, Any]:
    return {"k": g.successes, "n": g.n, "rate": _num(g.success_rate), "ci95": [_num(v) for v in g.success_ci95],
            "trials": g.trials}


def summary_json(
    records: Sequence[TrialRecord], *, pairs: Sequence[PairedComparison], planners: Sequence[str],
    summary: RunSummary | None = None,
) -> dict[str, Any]:
    """The machine-readable summary: the same numbers as summary.md, NaN written as null.

    Keys: distinct_problems, scenes, trivial_problems, few_problems (fewer than FEW_PROBLEMS),
    planners: {NAME: {success: {k, n, rate, ci95, trials}, status_counts, failure_causes: {CAUSE:
    {FAMILY: trials}} (planners.base.FailureReason), certification: {certified,
    unproved, collision, not checked} (successful trials by exact verdict), best_known {successes,
    equal, beaten: [{problem_id, length_rad, best_known_rad, ratio}]} (certified paths shorter than
    the dataset's best known by more than 0.1%), cold_start {cold_trials,
    warm_trials, planning_time_s: {cold, warm}, setup_time_s: {cold, warm}} (time medians are over
    warm trials), attribution {engine, trials, queries, s_per_query, query_share} (or null for a
    planner that does not count its collision queries), search {trials, post_processing, solve_time_s,
    simplify_time_s, length_before_rad, length_after_rad, length_kept} (OMPL planners; null otherwise),
    post_processing (what the planner does to its first solution, from its config), metrics: {METRIC: {median,
    q1, q3, n}}, time_to_solve_s, common_subset: {METRIC: {median, n}}, by_family: {FAMILY: {success,
    metrics}}, by_kind: {KIND: {success, metrics}}}}, metrics (their definitions), paired: [...],
    contention: {rule, budget_clock, trials, measured, contended, contended_ids, by_planner: {NAME:
    {measured, contended}}, cpu_wait_share, load1: {median, max}} (`suite.run.contention`).
    """
    counts = problem_counts(records)
    summary = summary or summarize_run(records, planners=planners)
    common = summary.common
    out: dict[str, Any] = {
        "format_version": SUMMARY_FORMAT_VERSION,
        "distinct_problems": counts["distinct"],
        "scenes": counts["scenes"],
        "trivial_problems": counts["trivial"] if counts["known_trivial"] else None,
        "few_problems": counts["distinct"] < FEW_PROBLEMS,
        "unit": "distinct problem (repeats of one problem count once)",
        "metrics": {m: SUMMARY_METRICS[m] for m in SUMMARY_METRICS},
        "planners": {},
    }
    split = {"problem": summary.by_kind, "variant": summary.by_family}
    causes = cause_counts(records)
    for g in summary.overall:
        p = g.planner
        out["planners"][p] = {
            "success": _success_json(g),
            "status_counts": g.status_counts,
            "failure_causes": causes.get(p, {}),
            "certification": certification_counts(records, p),
            "best_known": best_known_agreement(records, p),
            "attribution": attribution_summary(records, p),
            "cold_start": cold_start(records, p),
            "search": search_summary(records, p),
            "post_processing": post_processing(next((r.planner_config for r in records
                                                     if r.planner == p), None)),
            "metrics": {m: _stats_json(g.metrics[m]) for m in SUMMARY_METRICS},
            TIME_TO_SOLVE: _stats_json(g.time_to_solve),
            "common_subset": {m: {"median": _num(common[m][p].median), "n": common[m][p].n} for m in SUMMARY_METRICS},
            "by_family": {h.variant: {"success": _success_json(h),
                                      "metrics": {m: _stats_json(h.metrics[m]) for m in SUMMARY_METRICS}}
                          for h in split["variant"] if h.planner == p},
            "by_kind": {h.problem: {"success": _success_json(h),
                                    "metrics": {m: _stats_json(h.metrics[m]) for m in SUMMARY_METRICS}}
                        for h in split["problem"] if h.planner == p},
        }
    from suite.report.summary_contention import contention_json

    out["contention"] = contention_json(records)
    out["paired"] = [
        {"metric": c.metric, "a": c.planner_a, "b": c.planner_b, "n": c.n, "scenes": c.scenes,
         "median_diff": _num(c.median_diff), "ci95": [_num(c.ci_low), _num(c.ci_high)], "p_value": _num(c.p_value),
         "ci_method": "percentile bootstrap resampling scenes", "few": c.few}
        for c in pairs
    ]
    return out


def _csv_rows(groups: Sequence[GroupSummary]) -> tuple[list[str], list[list[Any]]]:
    headers = ["planner", "problem", "variant", "n", "successes", "success_rate", "success_ci95_low",
               "success_ci95_high", "trials"]
    for m in (*SUMMARY_METRICS, TIME_TO_SOLVE):
        headers += [f"{m}_n", f"{m}_median", f"{m}_q1", f"{m}_q3"]
    headers += [f"status_{s}" for s in STATUSES]
    rows = []
    for g in groups:
        row: list[Any] = [g.planner, g.problem, g.variant, g.n, g.successes, g.success_rate, *g.success_ci95,
                          g.trials]
        for s in (*(g.metrics[m] for m in SUMMARY_METRICS), g.time_to_solve):
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


def summary_markdown(
    records: Sequence[TrialRecord],
    *,
    pairs: Sequence[PairedComparison],
    planners: Sequence[str] | None = None,
    title: str = "Run summary",
    summary: RunSummary | None = None,
) -> str:
    """summary.md: per-planner, per-kind (and per-variant) tables, failures and paired comparisons.

    `summary` is the run's `summarize_run` when the caller has it (default: computed here)."""
    planners = list(planners) if planners is not None else planners_in(records)
    summary = summary or summarize_run(records, planners=planners)
    md = [
        f"# {title}",
        "",
        f"{len(records)} trials: {len(planners)} planners ({', '.join(planners)}). {composition(records)}",
        "",
        "The unit is the distinct problem: a problem tried several times counts once (success as the share "
        "of its trials solved, each metric as the median of its successful trials; times over warm trials only, "
        "see Cold starts). Success: solved/distinct "
        "problems, rate and its 95% Wilson interval. Time to solve: median [quartiles] over every problem, a "
        "failure counted at its time budget. Other metrics: median [first quartile, third quartile] over each "
        "planner's own solved problems; the common-subset table below measures all planners on the same problems.",
        "",
        "## Per planner",
        "",
    ]
    md.append(tabulate(*reversed(group_rows(summary.overall, key=None)), tablefmt="github"))
    if len(planners) > 1:
        md += ["", "## On the problems every planner solved", "",
               "Medians over the distinct problems that every planner solved (n of them per metric): "
               "no planner is flattered by skipping the hard ones.", ""]
        md.append(tabulate(*reversed(common_rows(summary.common, planners)), tablefmt="github"))
    md += ["", "## Certified paths (successful trials)", "", CERTIFICATION_INTRO, ""]
    md.append(tabulate(*reversed(certification_rows(records, planners)), tablefmt="github"))
    if any(r.reference_length_rad for r in records):
        md += ["", "## Against the best known paths (successful trials)", "", BEST_KNOWN_INTRO, ""]
        md.append(tabulate(*reversed(best_known_rows(records, planners)), tablefmt="github"))
    if any(r.attribution for r in records):
        md += ["", "## Where planning time goes", "", ATTRIBUTION_INTRO, ""]
        md.append(tabulate(*reversed(attribution_rows(records, planners)), tablefmt="github"))
    search = search_rows(records, planners)
    if search[1]:
        md += ["", "## Search and simplification (OMPL planners)", "", SEARCH_INTRO, ""]
        md.append(tabulate(*reversed(search), tablefmt="github"))
    if any(r.warm is not None for r in records):
        md += ["", "## Cold starts", "", COLD_INTRO, ""]
        md.append(tabulate(*reversed(cold_rows(records, planners)), tablefmt="github"))
    md += ["", "## Failures by status (trials)", ""]
    md.append(tabulate(*reversed(failure_rows(summary.overall, statuses_in(records))), tablefmt="github"))
    causes = reason_code_rows(records, planners)
    if causes[1]:
        md += ["", "## Failures by cause, per planner and family (trials)", "", REASON_CODE_INTRO, ""]
        md.append(tabulate(*reversed(causes), tablefmt="github"))
    md += ["", "## Per planner and problem kind", ""]
    md.append(tabulate(*reversed(group_rows(summary.by_kind, key="problem")), tablefmt="github"))
    if len({r.variant for r in records}) > 1:
        md += ["", "## Per planner and scene family", ""]
        md.append(
            tabulate(*reversed(group_rows(summary.by_family, key="variant")), tablefmt="github")
        )
    md += [
        "",
        "## Paired comparisons",
        "",
        "Differences A - B on the distinct problems both planners solved (paired by problem identity): median, "
        f"percentile-bootstrap 95% CI of the median resampling whole scenes ({N_RESAMPLES} resamples; problems of "
        "one scene are not independent; n/a with one scene), two-sided Wilcoxon signed-rank p-value (it treats "
        "problems as independent, so read it beside the CI). Negative means A is lower.",
        "",
    ]
    md.append(tabulate(*reversed(paired_rows(pairs)), tablefmt="github") if pairs else "(fewer than two planners)")
    return "\n".join(md) + "\n"


def write_summary(
    run_dir: str | Path,
    records: Sequence[TrialRecord],
    *,
    planners: Sequence[str] | None = None,
    seed: int = 0,
    title: str | None = None,
    executions: Sequence[ExecutionRecord] = (),
    budget_records: Sequence[TrialRecord] = (),
    summary: RunSummary | None = None,
    pairs: Sequence[PairedComparison] | None = None,
    moving_bin: Sequence[MovingBinRecord] = (),
) -> list[Path]:
    """Write summary.md, summary.json, summary.csv (per planner, per planner x kind, per planner x
    family) and paired.csv.

    Args:
        run_dir: the run directory to write into.
        records: the run's trial records.
        planners: planners in display order (default: order of appearance).
        seed: seeds the bootstrap's generator, so the written CIs are reproducible.
        title: the summary's heading (default: "Run summary: <run directory name>").
        executions: the run's physics execution records (execution.json), if it was executed.
        moving_bin: the run's moving-bin episodes (moving_bin.json), if it ran any.
        budget_records: a run at several budgets: its records with their own planner names (adds
            the per-budget table; `records` then name each planner and budget apart).
        summary, pairs: the records' `summarize_run` and `paired_comparisons` if the caller has them
            (default: computed here).

    Returns:
        The written files.
    """
    run_dir = Path(run_dir)
    planners = list(planners) if planners is not None else planners_in(records)
    if pairs is None:
        pairs = paired_comparisons(records, rng=np.random.default_rng(seed), planners=planners)
    md_path, csv_path, paired_path = run_dir / "summary.md", run_dir / "summary.csv", run_dir / "paired.csv"
    json_path = run_dir / "summary.json"
    summary = summary or summarize_run(records, planners=planners)
    md = summary_markdown(records, pairs=pairs, planners=planners, title=title or f"Run summary: {run_dir.name}",
                          summary=summary)
    from suite.report.summary_contention import contention_markdown, contention_warning

    warning = contention_warning(records)
    if warning:  # under the title, before any figure it concerns
        head, _, rest = md.partition("\n")
        md = f"{head}\n\n{warning}\n{rest}"
    md += "\n" + contention_markdown(records, planners)
    if budget_records:
        from suite.report.budgets import budget_table

        md += ("\n## By budget\n\nEach planner at each budget (`compare --budgets`): distinct problems solved, "
               "the 95% Wilson interval of the rate, and the median length / reference of the solved ones, over "
               "all families and per family.\n\n"
               + budget_table(budget_records, planners=planners_in(budget_records)) + "\n")
    if executions:
        md += "\n" + EXECUTION_INTRO + "\n" + execution_table(executions, planners=planners) + "\n"
    if moving_bin:
        from suite.report.summary_moving_bin import MOVING_BIN_INTRO, moving_bin_table

        md += "\n" + MOVING_BIN_INTRO + "\n" + moving_bin_table(moving_bin, planners=planners) + "\n"
    md_path.write_text(md, encoding="utf-8")
    json_path.write_text(json.dumps(summary_json(records, pairs=pairs, planners=planners, summary=summary), indent=1)
                         + "\n", encoding="utf-8")
    _write_csv(csv_path, *_csv_rows([*summary.overall, *summary.by_kind, *summary.by_family]))
    _write_csv(
        paired_path,
        ["metric", "planner_a", "planner_b", "n", "scenes", "median_diff", "ci95_low", "ci95_high", "wilcoxon_p"],
        [[c.metric, c.planner_a, c.planner_b, c.n, c.scenes, c.median_diff, c.ci_low, c.ci_high, c.p_value]
         for c in pairs],
    )
    log.info("wrote %s, %s, %s, %s", md_path, json_path, csv_path, paired_path)
    return [md_path, json_path, csv_path, paired_path]

