"""Summary tables: the terminal table and summary.md (per planner, kind and variant, failures, pairs)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from tabulate import tabulate

from suite.report.summary_stats import (
    N_RESAMPLES,
    SUMMARY_METRICS,
    GroupSummary,
    MetricStats,
    PairedComparison,
    summarize,
)
from suite.run.records import SUCCESS, planners_in, problem_counts, statuses_in


def format_number(v: float) -> str:
    """A table cell's number: 3 significant digits (exponent form if very large or small), "n/a" if not finite."""
    if not math.isfinite(v):
        return "n/a"
    if v == 0:
        return "0"
    if abs(v) >= 1000 or abs(v) < 0.001:
        return f"{v:.2e}"
    return f"{v:.3g}"


def _stat(s: MetricStats) -> str:
    if s.n == 0:
        return "n/a"
    return f"{format_number(s.median)} [{format_number(s.q1)}, {format_number(s.q3)}]"


def _rate(g: GroupSummary) -> str:
    pct = f" ({100 * g.success_rate:.0f}%)" if g.n else ""
    return f"{g.successes}/{g.n}{pct}"


def _rows(groups: Sequence[GroupSummary], *, key: str | None) -> tuple[list[str], list[list[str]]]:
    headers = ["planner"] + ([key] if key else []) + ["success"] + list(SUMMARY_METRICS.values())
    rows = []
    for g in groups:
        row = [g.planner] + ([getattr(g, key)] if key else []) + [_rate(g)]
        rows.append(row + [_stat(g.metrics[m]) for m in SUMMARY_METRICS])
    return headers, rows


def summary_table(records: Sequence[dict[str, Any]], *, planners: Sequence[str] | None = None) -> str:
    """The per-planner table for the terminal: success k/n and median [IQR] of each metric."""
    if not records:
        return "no trial records"
    headers, rows = _rows(summarize(records, planners=planners), key=None)
    return tabulate(rows, headers=headers, tablefmt="simple") + "\n" + composition(records)


def composition(records: Sequence[dict[str, Any]]) -> str:
    """One line: on how many distinct problems (how many trivial) and scenes the figures rest."""
    c = problem_counts(records)
    trivial = (f", {c['trivial']} of them trivial (the straight joint segment is already valid)"
               if c["known_trivial"] else "")
    return f"{c['distinct']} distinct problems from {c['scenes']} scenes{trivial}."


def _failure_rows(groups: Sequence[GroupSummary], statuses: Sequence[str]) -> tuple[list[str], list[list[Any]]]:
    failures = [s for s in statuses if s != SUCCESS]
    headers = ["planner", "trials", "failed"] + failures
    rows = [
        [g.planner, g.n, g.n - g.successes] + [g.status_counts.get(s, 0) for s in failures] for g in groups
    ]
    return headers, rows


def _paired_rows(pairs: Sequence[PairedComparison]) -> tuple[list[str], list[list[Any]]]:
    headers = ["metric", "A - B", "n", "median diff", "95% CI", "Wilcoxon p"]
    rows = []
    for c in pairs:
        ci = "n/a" if not math.isfinite(c.ci_low) else f"[{format_number(c.ci_low)}, {format_number(c.ci_high)}]"
        p = "n/a" if not math.isfinite(c.p_value) else f"{c.p_value:.3g}"
        rows.append([SUMMARY_METRICS.get(c.metric, c.metric), f"{c.planner_a} - {c.planner_b}", c.n, format_number(c.median_diff), ci, p])
    return headers, rows


def summary_markdown(
    records: Sequence[dict[str, Any]],
    *,
    pairs: Sequence[PairedComparison],
    planners: Sequence[str] | None = None,
    title: str = "Run summary",
) -> str:
    """summary.md: per-planner, per-kind (and per-variant) tables, failures and paired comparisons."""
    planners = list(planners) if planners is not None else planners_in(records)
    md = [
        f"# {title}",
        "",
        f"{len(records)} trials: {len(planners)} planners ({', '.join(planners)}). {composition(records)} "
        "Metrics are over successful trials only: median [first quartile, third quartile].",
        "",
        "## Per planner",
        "",
    ]
    md.append(tabulate(*reversed(_rows(summarize(records, planners=planners), key=None)), tablefmt="github"))
    md += ["", "## Failures by status", ""]
    groups = summarize(records, planners=planners)
    md.append(tabulate(*reversed(_failure_rows(groups, statuses_in(records))), tablefmt="github"))
    md += ["", "## Per planner and problem kind", ""]
    md.append(tabulate(*reversed(_rows(summarize(records, by="problem", planners=planners), key="problem")), tablefmt="github"))
    if len({r["variant"] for r in records}) > 1:
        md += ["", "## Per planner and scene variant", ""]
        md.append(
            tabulate(*reversed(_rows(summarize(records, by="variant", planners=planners), key="variant")), tablefmt="github")
        )
    md += [
        "",
        "## Paired comparisons",
        "",
        "Differences A - B on the problems both planners solved (paired by problem identity): median, "
        f"percentile-bootstrap 95% CI of the median ({N_RESAMPLES} "
        "resamples), two-sided Wilcoxon signed-rank p-value. Negative means A is lower.",
        "",
    ]
    md.append(tabulate(*reversed(_paired_rows(pairs)), tablefmt="github") if pairs else "(fewer than two planners)")
    return "\n".join(md) + "\n"
