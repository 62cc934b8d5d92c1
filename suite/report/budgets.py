"""Runs at several planning budgets (`compare --budgets`): success and length ratio versus budget.

A record's budget is its `time_limit_s`. When a run holds more than one, the tables treat each
(planner, budget) as its own entry, named "PLANNER@Bs" (`by_budget_view`), so that no statistic
mixes budgets; the curves (`plot_budget_curves`) and the per-family table (`budget_table`) keep the
planner and put the budget on the axis.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from matplotlib.ticker import NullFormatter
from tabulate import tabulate

from suite.report.outcomes import family_of, outcomes, solved_count, wilson_interval
from suite.report.plots_common import planner_colors, plt, save_figure
from suite.run.records import TrialRecord, metric


def budgets_in(records: Sequence[TrialRecord]) -> list[float]:
    """The distinct budgets (time_limit_s) of the records, ascending."""
    return sorted({float(r.time_limit_s) for r in records if r.time_limit_s is not None})


def budget_label(planner: str, budget_s: float) -> str:
    return f"{planner}@{budget_s:g}s"


def by_budget_view(records: Sequence[TrialRecord]) -> list[TrialRecord]:
    """The records with each planner renamed PLANNER@Bs when the run holds several budgets (else as is)."""
    if len(budgets_in(records)) < 2:
        return list(records)
    return [r.with_(planner=budget_label(str(r.planner), float(r.time_limit_s))) for r in records]


def _cell(records: Sequence[TrialRecord], planner: str, budget: float, family: str | None,
          metric: str = "length_ratio"):
    mine = [r for r in records if r.planner == planner and float(r.time_limit_s) == budget
            and (family is None or family_of(r) == family)]
    oc = list(outcomes(mine, metrics=(metric,)).values())
    ratios = np.array([o.metrics[metric] for o in oc], float)
    ratios = ratios[np.isfinite(ratios)]
    return solved_count(oc), len(oc), ratios


def budget_table(records: Sequence[TrialRecord], *, planners: Sequence[str], tablefmt: str = "github") -> str:
    """Success (with its Wilson interval) and median length ratio of every planner at every budget,
    over all families and per family."""
    families = [None, *sorted({family_of(r) for r in records})]
    rows = []
    for p in planners:
        for b in budgets_in([r for r in records if r.planner == p]):
            row = [p, f"{b:g}"]
            for fam in families:
                k, n, ratios = _cell(records, p, b, fam)
                if not n:
                    row.append("-")
                    continue
                lo, hi = wilson_interval(k, n)
                ratio = f"{np.median(ratios):.3g}" if len(ratios) else "n/a"
                row.append(f"{k:g}/{n} [{100 * lo:.0f}-{100 * hi:.0f}%], {ratio}")
            rows.append(row)
    headers = ["planner", "budget (s)"] + ["all families" if f is None else f for f in families]
    return tabulate(rows, headers=headers, tablefmt=tablefmt)


def plot_budget_curves(records: Sequence[TrialRecord], *, planners: Sequence[str], path) -> Any:
    """Success rate (with its 95% Wilson band) and median length ratio (with its quartiles) of each
    planner against the planning budget, log budget axis."""
    colors = planner_colors(planners)
    # generated scenes carry no reference length: their curve shows the joint path length instead
    has_ratio = any(math.isfinite(v) for v in (metric(r, "length_ratio") for r in records))
    name = "length_ratio" if has_ratio else "path_length_rad"
    fig, (ax_s, ax_l) = plt.subplots(1, 2, figsize=(12, 4.6))
    for p in planners:
        budgets = budgets_in([r for r in records if r.planner == p])
        rates, lows, highs, med, q1, q3 = [], [], [], [], [], []
        for b in budgets:
            k, n, ratios = _cell(records, p, b, None, name)
            lo, hi = wilson_interval(k, n)
            rates.append(100 * k / n if n else math.nan)
            lows.append(100 * lo)
            highs.append(100 * hi)
            qs = np.percentile(ratios, [25, 50, 75]) if len(ratios) else [math.nan] * 3
            q1.append(qs[0])
            med.append(qs[1])
            q3.append(qs[2])
        ax_s.plot(budgets, rates, "-o", color=colors[p], label=p, markersize=4)
        ax_s.fill_between(budgets, lows, highs, color=colors[p], alpha=0.15, linewidth=0)
        ax_l.plot(budgets, med, "-o", color=colors[p], label=p, markersize=4)
        ax_l.fill_between(budgets, q1, q3, color=colors[p], alpha=0.15, linewidth=0)
    ticks = budgets_in(records)
    for ax in (ax_s, ax_l):
        ax.set_xscale("log")
        ax.set_xticks(ticks, [f"{b:g}" for b in ticks])
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel("planning budget per problem (s, log)")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    ax_s.set_ylim(0, 102)
    ax_s.set_ylabel("problems solved (%)")
    ax_s.set_title("Success vs budget (band: 95% Wilson interval)")
    if has_ratio:
        ax_l.axhline(1.0, color="0.3", linestyle="--", linewidth=1)
    ax_l.set_ylabel("length / reference (1 = best known)" if has_ratio else "joint path length (rad)")
    ax_l.set_title("Path length vs budget (median; band: quartiles; solved problems)")
    fig.tight_layout()
    return save_figure(fig, path)
