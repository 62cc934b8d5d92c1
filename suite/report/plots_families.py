"""Figures per scene family: success rate with its 95% Wilson interval, and the length ratio.

Both count distinct problems (`suite.report.outcomes`): a problem tried several times is one bar
count and one dot.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.ticker import NullFormatter

from suite.report.outcomes import family_of, outcomes, solved_count, wilson_interval
from suite.report.plots_common import planner_colors, plt, save_figure
from suite.run.records import TrialRecord

ALL_FAMILIES = "all"


def _families(records: Sequence[TrialRecord]) -> list[str]:
    return sorted({family_of(r) for r in records})


def _per_family(records: Sequence[TrialRecord], planner: str, family: str, metrics: Sequence[str]):
    mine = [r for r in records if r.planner == planner and (family == ALL_FAMILIES or family_of(r) == family)]
    return list(outcomes(mine, metrics=metrics).values())


def plot_success_by_family(records: Sequence[TrialRecord], *, planners: Sequence[str], path: Path) -> Path:
    """Grouped bars: each planner's success rate over the distinct problems of each family (and all),
    with its 95% Wilson interval and the count solved/problems above the bar."""
    colors = planner_colors(planners)
    groups = [ALL_FAMILIES, *_families(records)]
    width = 0.8 / max(len(planners), 1)
    fig, ax = plt.subplots(figsize=(max(6.5, 1.25 * len(groups) * max(len(planners), 2) * 0.55 + 2), 4.6))
    x = np.arange(len(groups))
    for i, p in enumerate(planners):
        rates, lows, highs, labels = [], [], [], []
        for fam in groups:
            oc = _per_family(records, p, fam, ())
            n, k = len(oc), solved_count(oc)
            lo, hi = wilson_interval(k, n)
            rate = k / n if n else math.nan
            rates.append(100 * rate)
            lows.append(max(0.0, 100 * (rate - lo)) if n else 0)
            highs.append(max(0.0, 100 * (hi - rate)) if n else 0)
            labels.append(f"{k:g}/{n}" if n else "-")
        xs = x - 0.4 + width * (i + 0.5)
        ax.bar(xs, rates, width=width * 0.92, color=colors[p], alpha=0.85, label=p)
        ax.errorbar(xs, rates, yerr=[lows, highs], fmt="none", ecolor="0.15", elinewidth=1, capsize=2.5)
        for xi, r, h, lab in zip(xs, rates, highs, labels):
            if math.isfinite(r):
                ax.text(xi, min(r + h, 100) + 1.5, lab, ha="center", va="bottom", fontsize=7, rotation=90)
    ax.axvline(0.5, color="0.6", linewidth=0.8)
    ax.set_xticks(x, [f"{g}\n(all families)" if g == ALL_FAMILIES else g for g in groups])
    ax.set_ylim(0, 125)
    ax.set_yticks(range(0, 101, 20))
    ax.set_ylabel("problems solved (%)")
    ax.set_title("Success rate by scene family (distinct problems; bars: 95% Wilson interval; labels: solved/problems)")
    ax.grid(axis="y", alpha=0.3)
    ax.legend(loc="upper right", ncol=len(planners), fontsize=8)
    fig.tight_layout()
    return save_figure(fig, path)


def plot_length_ratio_by_family(records: Sequence[TrialRecord], *, planners: Sequence[str], path: Path) -> Path:
    """Per family, each planner's length ratio (joint path / the problem's best known), one dot per
    solved distinct problem, with its median as a bar; 1 is the reference, and the axis reaches
    down to any ratio below it (a path shorter than the reference)."""
    colors = planner_colors(planners)
    groups = _families(records)
    width = 0.8 / max(len(planners), 1)
    fig, ax = plt.subplots(figsize=(max(6.5, 1.1 * len(groups) * max(len(planners), 2) * 0.55 + 2), 4.6))
    rng = np.random.default_rng(0)  # jitter only
    any_value = False
    top = bottom = 1.0
    for i, p in enumerate(planners):
        for j, fam in enumerate(groups):
            vals = np.array([o.metrics["length_ratio"] for o in _per_family(records, p, fam, ("length_ratio",))])
            vals = vals[np.isfinite(vals)]
            xc = j - 0.4 + width * (i + 0.5)
            if not len(vals):
                ax.text(xc, 1.0, "-", ha="center", va="bottom", fontsize=8, color="0.4")
                continue
            any_value = True
            top = max(top, float(np.max(vals)))
            bottom = min(bottom, float(np.min(vals)))  # a planner that beat the reference
            ax.scatter(xc + rng.uniform(-width * 0.3, width * 0.3, len(vals)), vals, s=10, color=colors[p],
                       alpha=0.8, linewidths=0, zorder=3)
            med = float(np.median(vals))
            ax.plot([xc - width * 0.4, xc + width * 0.4], [med, med], color="black", linewidth=1.8, zorder=4)
    ax.axhline(1.0, color="0.3", linestyle="--", linewidth=1)
    ax.set_xticks(np.arange(len(groups)), groups)
    ax.set_yscale("log")
    low, high = min(0.9, bottom / 1.15), max(2.0, top * 1.3)
    ax.set_ylim(low, high)
    ticks = [t for t in (0.1, 0.25, 0.5, 0.75, 1, 1.25, 1.5, 2, 3, 5, 10, 20, 50) if low <= t <= high]
    ax.set_yticks(ticks, [f"{t:g}" for t in ticks])
    ax.yaxis.set_minor_formatter(NullFormatter())
    ax.set_ylabel("length / reference (log; 1 = best known)")
    ax.set_title("Optimality by scene family: joint path length over the best known (dots: solved problems; "
                 "bar: median)", fontsize=10)
    ax.grid(axis="y", alpha=0.3, which="both")
    handles = [plt.Line2D([], [], marker="o", linestyle="", color=colors[p], label=p) for p in planners]
    ax.legend(handles=handles, loc="upper right", ncol=len(planners), fontsize=8)
    if not any_value:
        ax.text(0.5, 0.5, "no length ratios: the problems carry no reference length", ha="center", va="center",
                transform=ax.transAxes, color="0.4")
    fig.tight_layout()
    return save_figure(fig, path)
