"""Where planning time goes: collision queries against the rest, per planner and family."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from suite.report.outcomes import family_of, is_cold
from suite.report.plots_common import planner_colors, plt, save_figure
from suite.run.records import SUCCESS


def plot_time_attribution(records: Sequence[dict], *, planners: Sequence[str], path: Path) -> Path | None:
    """Stacked bars per planner in each family: the share of planning time spent in collision
    queries and in the rest (medians over warm successful trials that carry `attribution`), the
    median planning time written above; a planner that does not count its queries gets a hatched
    bar marked "not counted". None if no record carries an attribution."""
    if not any(r.get("attribution") for r in records):
        return None
    warm = [r for r in records if r.get("status") == SUCCESS and not is_cold(r)]
    families = sorted({family_of(r) for r in warm})
    if not families:
        return None
    fig, ax = plt.subplots(figsize=(max(7.0, 0.9 * len(families) * max(1, len(planners))), 4.2))
    width = 0.8 / max(1, len(planners))
    x = np.arange(len(families))
    colors = planner_colors(planners)
    for k, planner in enumerate(planners):
        color = colors[planner]
        pos = x + (k - (len(planners) - 1) / 2) * width
        for i, fam in enumerate(families):
            mine = [r for r in warm if r["planner"] == planner and family_of(r) == fam]
            if not mine:
                continue
            att = [r["attribution"] for r in mine if r.get("attribution")]
            t = float(np.median([r["planning_time_s"] for r in mine]))
            if att:
                share = float(np.median([a["query_share"] for a in att]))
                ax.bar(pos[i], share, width, color=color, label=f"{planner}: collision queries" if i == 0 else None)
                ax.bar(pos[i], 1 - share, width, bottom=share, color=color, alpha=0.3,
                       label=f"{planner}: the rest" if i == 0 else None)
            else:
                ax.bar(pos[i], 1, width, color="white", edgecolor=color, hatch="//",
                       label=f"{planner}: not counted" if i == 0 else None)
            ax.text(pos[i], 1.01, f"{t:.2g} s", ha="center", va="bottom", fontsize=7, rotation=90)
    ax.set_xticks(x)
    ax.set_xticklabels(families)
    ax.set_ylim(0, 1.25)
    ax.set_ylabel("share of planning time (median)")
    ax.set_title("Where planning time goes (warm successful trials; median planning time above each bar)", fontsize=10)
    ax.legend(fontsize=7, ncol=3, loc="upper center", bbox_to_anchor=(0.5, -0.1))
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    return save_figure(fig, path)
