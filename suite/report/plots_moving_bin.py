"""The moving-bin figure: cans in the bin against bin speed per planner, and why cans were lost."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from suite.report.plots_common import planner_colors, plt, save_figure
from suite.report.summary_moving_bin import speed_cells


def plot_moving_bin(records: Sequence[dict], *, planners: Sequence[str], path: Path) -> Path | None:
    """Four panels against bin speed, one line per planner: cans in the bin (95% Wilson intervals),
    replan latency (median, p95 dashed, the deadline dotted), deadline misses and failed replans
    per can, and contacts with the bin or the person per episode."""
    cells = [c for c in speed_cells(records, planners=planners) if c.cans_total]
    if not cells:
        return None
    shown = list(dict.fromkeys(c.planner for c in cells))
    colors = planner_colors(list(dict.fromkeys([*planners, *shown])))
    speeds = sorted({c.speed_m_s for c in cells})
    deadline = next((r["scenario"]["replan_deadline_s"] for r in records if r.get("scenario")), None)
    fig, axes = plt.subplots(2, 2, figsize=(10.5, 7.2), sharex=True)
    (a_bin, a_lat), (a_miss, a_hit) = axes
    n = len(shown)
    for i, p in enumerate(shown):
        mine = [c for c in cells if c.planner == p]
        x = np.array([c.speed_m_s for c in mine])
        dx = (i - (n - 1) / 2) * 0.004  # side by side where the intervals overlap
        rate = np.array([100 * c.rate for c in mine])
        lo = np.array([100 * c.ci95[0] for c in mine])
        hi = np.array([100 * c.ci95[1] for c in mine])
        col = colors[p]
        yerr = np.maximum(0.0, [rate - lo, hi - rate])  # Wilson: lo <= rate <= hi up to rounding
        a_bin.errorbar(x + dx, rate, yerr=yerr, color=col, marker="o", capsize=3, lw=1.8, label=p)
        med = [np.median(c.latencies_s) if c.latencies_s else math.nan for c in mine]
        p95 = [np.quantile(c.latencies_s, 0.95) if c.latencies_s else math.nan for c in mine]
        a_lat.plot(x, med, color=col, marker="o", lw=1.8, label=f"{p} median")
        a_lat.plot(x, p95, color=col, marker="^", lw=1.0, ls="--", label=f"{p} p95")
        per_can = [max(c.cans_attempted, 1) for c in mine]
        a_miss.plot(x, [c.deadline_misses / k for c, k in zip(mine, per_can)], color=col, marker="o", lw=1.8,
                    label=f"{p} missed")
        a_miss.plot(x, [c.replan_failures / k for c, k in zip(mine, per_can)], color=col, marker="x", lw=1.0,
                    ls=":", label=f"{p} failed")
        a_hit.plot(x + dx, [(c.contacts_bin + c.contacts_person) / max(c.episodes, 1) for c in mine], color=col,
                   marker="o", lw=1.8, label=p)
    a_bin.set_ylim(-3, 105)
    a_bin.set_ylabel("cans in the bin (%)")
    a_bin.set_title("Cans delivered (95% Wilson intervals)", fontsize=10)
    a_bin.legend(fontsize=8, loc="lower left")
    if deadline is not None:
        a_lat.axhline(deadline, color="black", ls=":", lw=1.2)
        a_lat.text(0.98, deadline, f"deadline {deadline:g} s ", transform=a_lat.get_yaxis_transform(), fontsize=8,
                   ha="right", va="bottom")
    a_lat.set_ylim(bottom=0)
    a_lat.set_ylabel("replan latency (s)")
    a_lat.set_title("Replan latency (solid: median, dashed: p95)", fontsize=10)
    a_miss.set_ylabel("per can attempted")
    a_miss.set_title("Deadline misses (solid) and failed replans (dotted)", fontsize=10)
    a_miss.legend(fontsize=7, ncol=2)
    a_hit.set_ylabel("per episode")
    a_hit.set_title("Contacts of the robot or the carried can with the bin or person", fontsize=10)
    for ax in (a_miss, a_hit):
        ax.set_ylim(0, max(1.0, ax.get_ylim()[1]))
    for ax in axes.ravel():
        ax.grid(alpha=0.3)
        ax.set_xticks(speeds)
    for ax in axes[1]:
        ax.set_xlabel("bin speed (m/s)")
    scenes = len({(r["variant"], r["scene_seed"]) for r in records})
    fig.suptitle(f"Moving bin: {scenes} scene{'s' * (scenes != 1)}, every planner through the same replanning loop",
                 fontsize=11)
    na = {r["planner"]: r["reason"] for r in records if r.get("status") == "not_applicable"}
    if na:
        fig.text(0.01, 0.005, "Not applicable: " + "; ".join(f"{p} ({why})" for p, why in na.items()), fontsize=8,
                 ha="left", va="bottom", wrap=True)
    fig.tight_layout(rect=(0, 0.03 if na else 0, 1, 1))
    return save_figure(fig, path)
