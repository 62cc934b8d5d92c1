"""The physics execution figure: where each planner's cans ended, with its unintended contacts."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from suite.execution.execution_records import (
    BACK_ON_PLATE,
    BIN,
    CAN_FATES,
    ELSEWHERE,
    NOT_ATTEMPTED,
    ExecutionRecord,
    fate_counts,
)
from suite.report.plots_common import planner_colors, plt, save_figure


def plot_execution(executions: Sequence[ExecutionRecord], *, planners: Sequence[str], path: Path) -> Path:
    """Cans recycled per planner after physics execution: stacked bars of where the cans ended."""
    planners = [p for p in planners if any(e.planner == p for e in executions)]
    colors = {BIN: "#2e8b57", BACK_ON_PLATE: "#f0a202", ELSEWHERE: "#d62728", NOT_ATTEMPTED: "#c8c8c8"}
    labels = {ELSEWHERE: "dropped elsewhere", NOT_ATTEMPTED: "not attempted (plan incomplete)"}
    fig, ax = plt.subplots(figsize=(3.0 + 1.1 * len(planners), 4.6))
    x = np.arange(len(planners))
    bottom = np.zeros(len(planners))
    totals = np.array([sum(e.cans_total for e in executions if e.planner == p) for p in planners], float)
    counts = {p: fate_counts(e for e in executions if e.planner == p) for p in planners}
    for fate in CAN_FATES:
        n = np.array([counts[p][fate] for p in planners], float)
        ax.bar(x, n / np.maximum(totals, 1) * 100, bottom=bottom, color=colors[fate], label=labels.get(fate, fate),
               width=0.6, edgecolor="white", linewidth=0.5)
        bottom += n / np.maximum(totals, 1) * 100
    for i, p in enumerate(planners):
        runs = [e for e in executions if e.planner == p]
        k = sum(e.cans_in_bin for e in runs)
        hits = sum(e.collisions for e in runs)
        ax.text(i, 101.5, f"{k}/{int(totals[i])}\n{hits} collision{'s' * (hits != 1)}", ha="center",
                va="bottom", fontsize=8)
    ax.set_xticks(x, planners)
    for tick, p in zip(ax.get_xticklabels(), planners):
        tick.set_color(planner_colors(planners)[p])
        tick.set_fontweight("bold")
    ax.set_ylim(0, 118)
    ax.set_ylabel("share of cans (%)")
    ax.grid(axis="y", alpha=0.3)
    scenes = len({(e.scene_seed, e.variant) for e in executions})
    ax.set_title(f"Cans recycled in physics ({scenes} scene{'s' * (scenes != 1)})\nlabels: cans in bin / cans, "
                 "unintended contacts", fontsize=10)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, frameon=False, fontsize=8)
    fig.tight_layout()
    return save_figure(fig, path)
