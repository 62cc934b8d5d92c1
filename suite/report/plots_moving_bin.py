"""The moving-bin figure: cans in the bin against bin speed per planner, the planners' paired
differences, and why cans were lost."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from suite.execution.moving_bin_records import MovingBinRecord
from suite.report.plots_common import planner_colors, plt, save_figure
from suite.report.summary_moving_bin import speed_cells
from suite.report.summary_moving_bin_paired import paired_differences

#: Colours and markers of the pairs of planners (not the planners' own colours: a pair is neither).
PAIR_STYLES = (("#393b79", "o"), ("#843c39", "s"), ("#637939", "D"), ("#7b4173", "^"), ("#7f7f7f", "v"),
               ("black", "P"))
#: Markers of the latency and release modes when a run mixes them (the planner keeps its colour).
MODE_MARKERS = ("o", "s", "^", "D")


def plot_moving_bin(records: Sequence[MovingBinRecord], *, planners: Sequence[str], path: Path) -> Path | None:
    """Six panels against bin speed (equally spaced categories), one line per planner (and mode):
    cans in the bin per can offered (95% Wilson intervals); the paired differences between
    planners (mean over shared episodes, 95% bootstrap interval; filled where it excludes 0);
    replan latency (median, p95 dashed, the deadline dotted); deadline misses and failed replans per
    can; cans lost per can offered (given up; or not in the bin otherwise: missed, flung, not reached); contacts with the
    bin or the person and near misses per episode."""
    cells = [c for c in speed_cells(records, planners=planners) if c.cans_offered]
    if not cells:
        return None
    shown = list(dict.fromkeys(c.planner for c in cells))
    colors = planner_colors(list(dict.fromkeys([*planners, *shown])))
    speeds = sorted({c.speed_m_s for c in cells})
    at = {v: i for i, v in enumerate(speeds)}
    modes = list(dict.fromkeys((c.latency_mode, c.release_mode) for c in cells))
    deadline = next((r.scenario["replan_deadline_s"] for r in records
                     if isinstance(r.scenario, dict) and "replan_deadline_s" in r.scenario), None)
    fig, axes = plt.subplots(2, 3, figsize=(15, 8.2))
    (a_bin, a_pair, a_lat), (a_miss, a_lost, a_hit) = axes
    lines = [(p, m) for p in shown for m in modes if any(c.planner == p and (c.latency_mode, c.release_mode) == m
                                                         for c in cells)]
    n = len(lines)
    for i, (p, mode) in enumerate(lines):
        mine = [c for c in cells if c.planner == p and (c.latency_mode, c.release_mode) == mode]
        x = np.array([at[c.speed_m_s] for c in mine], float)
        dx = (i - (n - 1) / 2) * min(0.08, 0.5 / n)  # side by side where the intervals overlap
        col, marker = colors[p], MODE_MARKERS[modes.index(mode) % len(MODE_MARKERS)]
        label = p + _mode_label(mode, modes)
        rate = np.array([100 * c.rate for c in mine])
        lo = np.array([100 * c.ci95[0] for c in mine])
        hi = np.array([100 * c.ci95[1] for c in mine])
        yerr = np.maximum(0.0, [rate - lo, hi - rate])  # Wilson: lo <= rate <= hi up to rounding
        a_bin.errorbar(x + dx, rate, yerr=yerr, color=col, marker=marker, capsize=3, lw=1.8, label=label)
        med = [np.median(c.latencies_s) if c.latencies_s else math.nan for c in mine]
        p95 = [np.quantile(c.latencies_s, 0.95) if c.latencies_s else math.nan for c in mine]
        a_lat.plot(x, med, color=col, marker=marker, lw=1.8)
        a_lat.plot(x, p95, color=col, marker=marker, lw=1.0, ls="--", mfc="none")
        per_can = [max(c.cans_offered, 1) for c in mine]
        a_miss.plot(x, [c.deadline_misses / k for c, k in zip(mine, per_can)], color=col, marker=marker, lw=1.8)
        a_miss.plot(x, [c.replan_failures / k for c, k in zip(mine, per_can)], color=col, marker=marker, lw=1.0,
                    ls=":", mfc="none")
        a_lost.plot(x + dx, [100 * c.given_up / k for c, k in zip(mine, per_can)], color=col, marker=marker, lw=1.0,
                    ls="--", mfc="none")
        a_lost.plot(x + dx, [100 * max(0, k - c.cans_in_bin - c.given_up) / k for c, k in zip(mine, per_can)],
                    color=col, marker=marker, lw=1.8)
        episodes = [max(c.episodes - c.errors, 1) for c in mine]
        a_hit.plot(x + dx, [(c.contacts_bin + c.contacts_person) / e for c, e in zip(mine, episodes)], color=col,
                   marker=marker, lw=1.8)
        if any(c.near_misses_person is not None for c in mine):
            a_hit.plot(x + dx, [(c.near_misses_person or 0) / e for c, e in zip(mine, episodes)], color=col,
                       marker=marker, lw=1.0, ls="--", mfc="none")
    _paired_panel(a_pair, records, planners=planners, at=at)
    a_bin.set_ylim(-3, 105)
    a_bin.set_ylabel("cans in the bin per can offered (%)")
    a_bin.set_title("Cans in the bin (95% Wilson intervals)", fontsize=10)
    if deadline is not None:
        a_lat.axhline(deadline, color="black", ls=":", lw=1.2)
        a_lat.text(0.98, deadline, f"deadline {deadline:g} s ", transform=a_lat.get_yaxis_transform(), fontsize=8,
                   ha="right", va="bottom")
    a_lat.set_ylim(0, max(a_lat.get_ylim()[1], 1.15 * (deadline or 0.0)))
    a_lat.set_ylabel("replan latency (s)")
    a_lat.set_title("Replan latency (solid: median, dashed: p95)", fontsize=10)
    a_miss.set_ylabel("per can offered")
    a_miss.set_title("Replans: deadline missed (solid), failed (dotted)", fontsize=10)
    a_lost.set_ylim(-3, 105)
    a_lost.set_ylabel("cans per can offered (%)")
    a_lost.set_title("Cans lost: not in the bin otherwise (solid), given up (dashed)", fontsize=10)
    a_hit.set_ylabel("per episode")
    near = any(c.near_misses_person is not None for c in cells)
    a_hit.set_title("Contacts with the bin or person (solid)" + (", person near misses (dashed)" if near else ""),
                    fontsize=10)
    for ax in (a_miss, a_hit):
        ax.set_ylim(0, max(1.0, ax.get_ylim()[1]))
    for ax in axes.ravel():
        ax.grid(alpha=0.3)
        ax.set_xlabel("bin cruise speed (m/s)")
        if ax is not a_pair:
            ax.set_xticks(range(len(speeds)), [f"{v:g}" for v in speeds])
            ax.set_xlim(-0.5, len(speeds) - 0.5)
    scenes = len({(r.variant, r.scene_seed) for r in records})
    handles, labels = a_bin.get_legend_handles_labels()
    fig.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 0.97), ncol=min(len(labels), 6),
               fontsize=9, frameon=False)
    fig.suptitle(f"Moving bin: {scenes} scene{'s' * (scenes != 1)}, every planner through the same replanning loop "
                 "(one point per planner and speed, over its episodes)", fontsize=11, y=0.995)
    na = {r.planner: r.reason for r in records if r.status == "not_applicable"}
    if na:
        fig.text(0.01, 0.005, "Not applicable: " + "; ".join(f"{p} ({why})" for p, why in na.items()), fontsize=8,
                 ha="left", va="bottom", wrap=True)
    fig.tight_layout(rect=(0, 0.03 if na else 0, 1, 0.945))
    return save_figure(fig, path)


def _mode_label(mode: tuple[str, str], modes: Sequence[tuple[str, str]]) -> str:
    """" (modelled latency, release rest)": only the modes that differ in the run."""
    parts = []
    if len({m[0] for m in modes}) > 1:
        parts.append(f"{mode[0]} latency")
    if len({m[1] for m in modes}) > 1:
        parts.append(f"release {mode[1]}")
    return f" ({', '.join(parts)})" if parts else ""


def _paired_panel(ax, records: Sequence[MovingBinRecord], *, planners: Sequence[str], at: dict[float, int]) -> None:
    """Mean paired difference (pp) per pair of planners against speed, its 95% bootstrap interval;
    filled where the interval excludes 0; "all" pools every speed above 0."""
    diffs = [d for d in paired_differences(records, planners=planners) if d.ci_pp is not None]
    ax.axhline(0, color="black", lw=1.0)
    ax.set_ylabel("A - B, cans in the bin per can offered (pp)")
    ax.set_title("Paired difference A - B over shared episodes\n(mean, 95% bootstrap; the number: episodes paired)",
                 fontsize=10)
    ticks = [f"{v:g}" for v in at]
    if not diffs:
        ax.text(0.5, 0.5, "no two planners share\nan episode with 2+ pairs", transform=ax.transAxes, ha="center",
                va="center", fontsize=9, color="0.4")
        ax.set_xticks(range(len(ticks)), ticks)
        ax.set_xlim(-0.5, len(ticks) - 0.5)
        return
    pooled_x = len(at)
    pairs = list(dict.fromkeys((d.planner_a, d.planner_b) for d in diffs))
    k = len(pairs)
    for i, pair in enumerate(pairs):
        color, marker = PAIR_STYLES[i % len(PAIR_STYLES)]
        dx = (i - (k - 1) / 2) * min(0.1, 0.6 / k)
        mine = [d for d in diffs if (d.planner_a, d.planner_b) == pair]
        for j, d in enumerate(mine):
            x = (pooled_x if d.speed_m_s is None else at[d.speed_m_s]) + dx
            lo, hi = d.ci_pp
            ax.errorbar([x], [d.mean_pp], yerr=[[max(0.0, d.mean_pp - lo)], [max(0.0, hi - d.mean_pp)]],
                        color=color, marker=marker, mfc=color if d.established else "white", capsize=3, lw=1.4,
                        label=f"{pair[0]} - {pair[1]}" if j == 0 else None)
            ax.annotate(f"{d.n}", (x, hi), xytext=(0, 2), textcoords="offset points", ha="center", va="bottom",
                        fontsize=6.5, color=color)
    if any(d.speed_m_s is None for d in diffs):
        ticks.append("all")
        ax.axvline(pooled_x - 0.5, color="0.6", lw=0.8, ls=":")
    ax.set_xticks(range(len(ticks)), ticks)
    ax.set_xlim(-0.5, len(ticks) - 0.5)
    bottom, top = ax.get_ylim()
    span = max(abs(bottom), abs(top), 10.0)
    ax.set_ylim(-1.1 * span, 1.1 * span)
    ax.legend(fontsize=8, loc="best", title="filled: interval excludes 0", title_fontsize=7)
