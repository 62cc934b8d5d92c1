"""Statistics figures of a run: metric box plots, outcomes by status and the planning-time CDF."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.patches import Patch

from suite.report.outcomes import outcomes
from suite.report.plots_common import planner_colors, plt, save_figure
from suite.run.records import SUCCESS, TrialRecord, metric_values, problem_kinds_in, statuses_in

STATUS_COLORS = {
    "success": "#59a14f",
    "no_solution": "#e15759",
    "timeout": "#f28e2b",
    "invalid_start": "#b07aa1",
    "invalid_goal": "#ff9da7",
    "ik_failed": "#9c755f",
    "error": "#79706e",
    "invalid_solution": "#edc948",
    "timing_failed": "#76b7b2",
    "crash": "#222222",
    "killed_timeout": "#a0cbe8",
}

#: Box-plot panels: metric -> (title, axis label, log scale).
BOX_METRICS = {
    "planning_time_s": ("Planning time", "time (s)", True),
    "path_length_rad": ("Joint path length", "length (rad)", False),
    "length_ratio": ("Length / reference (optimality)", "ratio (1 = best known)", False),
    "turning_angle_rad": ("Turning angle (geometric smoothness)", "total turning (rad; 0 = straight)", False),
    "sparc": ("SPARC of joint speed (timed smoothness)", "SPARC (higher is smoother)", False),
    "clearance_min_m": ("Minimum clearance", "clearance (m)", False),
    "duration_s": ("Trajectory duration (TOPP-RA)", "duration (s)", False),
    "ee_path_length_m": ("Gripper path length", "length (m)", False),
}

#: The "natural poses" panel (the seed paper's question): metric -> (title, axis label, log scale).
NATURAL_POSE_METRICS = {
    "joint_margin_min_frac": ("Smallest joint-limit margin", "fraction of the joint's range (higher: better)", False),
    "posture_distance_mean_rad": ("Mean distance from the comfortable posture", "rad (lower: better)", False),
    "manipulability_min_m3": ("Smallest manipulability", "sqrt(det J J^T) (m^3; higher: better)", False),
    "can_tilt_max_deg": ("Carried can's largest tilt", "deg from vertical (lower: better)", False),
}


def _no_data(ax, text: str = "no successful trials") -> None:
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, color="0.4")


def _problem_values(records: Sequence[TrialRecord], planner: str, name: str) -> np.ndarray:
    """One value per distinct problem the planner solved (the median of its successful trials)."""
    vals = np.array([o.metrics[name] for o in outcomes([r for r in records if r.planner == planner],
                                                        metrics=(name,)).values()], dtype=float)
    return vals[np.isfinite(vals)]


def plot_metric_boxes(records: Sequence[TrialRecord], *, planners: Sequence[str], path: Path,
                      panels: dict[str, tuple[str, str, bool]] | None = None, title: str | None = None) -> Path:
    """Box plots of each metric by planner, one dot per solved distinct problem, with n shown.

    Args:
        panels: metric -> (title, axis label, log scale); default `BOX_METRICS`.
        title: the figure's title.
    """
    panels = panels or BOX_METRICS
    colors = planner_colors(planners)
    values = {(p, m): _problem_values(records, p, m) for p in planners for m in panels}
    names = [m for m in panels if any(len(values[p, m]) for p in planners)]
    names = names or list(panels)[:1]
    ncols = min(3, len(names))
    nrows = math.ceil(len(names) / ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.6 * ncols, 3.9 * nrows), squeeze=False)
    rng = np.random.default_rng(0)  # jitter of the points only
    for ax, name in zip(axes.flat, names):
        panel_title, ylabel, log_y = panels[name]
        data = [values.get((p, name), np.array([])) for p in planners]
        pos = np.arange(1, len(planners) + 1)
        shown = [i for i, d in enumerate(data) if len(d)]
        if shown:
            bp = ax.boxplot([data[i] for i in shown], positions=pos[shown], widths=0.55, patch_artist=True,
                            showfliers=False, medianprops={"color": "black", "linewidth": 1.5})
            for patch, i in zip(bp["boxes"], shown):
                patch.set_facecolor(colors[planners[i]])
                patch.set_alpha(0.45)
            for i in shown:
                x = pos[i] + rng.uniform(-0.14, 0.14, size=len(data[i]))
                ax.scatter(x, data[i], s=9, color=colors[planners[i]], alpha=0.85, zorder=3, linewidths=0)
        else:
            _no_data(ax)
        ax.set_xticks(pos, [f"{p}\nn={len(d)}" for p, d in zip(planners, data)])
        ax.set_xlim(0.4, len(planners) + 0.6)
        if log_y and shown and all(np.all(data[i] > 0) for i in shown):
            ax.set_yscale("log")
        ax.set_title(panel_title)
        ax.set_ylabel(ylabel)
        ax.grid(axis="y", alpha=0.3)
    for ax in list(axes.flat)[len(names):]:
        ax.set_visible(False)
    fig.suptitle(title or "Metrics by planner over its solved problems (box: quartiles and median; "
                 "dots: distinct problems)")
    fig.tight_layout()
    return save_figure(fig, path)


def plot_outcomes(records: Sequence[TrialRecord], *, planners: Sequence[str], path: Path) -> Path:
    """Stacked bars of trial outcomes by status for each planner: over all motions and per kind."""
    statuses = statuses_in(records)
    kinds = problem_kinds_in(records)
    groups = [("all motions", list(records))] + [(k, [r for r in records if r.problem == k]) for k in kinds]
    fig, axes = plt.subplots(1, len(groups), figsize=(2.0 + 0.8 * len(planners) * len(groups), 4.4),
                             squeeze=False, gridspec_kw={"width_ratios": [1.4] + [1] * (len(groups) - 1)})
    x = np.arange(len(planners))
    for ax, (label, recs) in zip(axes[0], groups):
        bottom = np.zeros(len(planners))
        totals = np.array([sum(r.planner == p for r in recs) for p in planners], float)
        frac_den = np.maximum(totals, 1)
        for s in statuses:
            counts = np.array([sum(r.planner == p and r.status == s for r in recs) for p in planners], float)
            ax.bar(x, counts / frac_den * 100, bottom=bottom, color=STATUS_COLORS.get(s, "#bbbbbb"),
                   edgecolor="white", linewidth=0.5, width=0.7)
            bottom += counts / frac_den * 100
        for i, p in enumerate(planners):
            k = sum(r.planner == p and r.status == SUCCESS for r in recs)
            ax.text(i, 101.5, f"{k}/{int(totals[i])}", ha="center", va="bottom", fontsize=8)
        ax.set_xticks(x, planners, rotation=30 if len(planners) > 3 else 0)
        for tick, p in zip(ax.get_xticklabels(), planners):
            tick.set_color(planner_colors(planners)[p])
            tick.set_fontweight("bold")
        ax.set_ylim(0, 110)
        ax.set_title(label)
        ax.grid(axis="y", alpha=0.3)
    axes[0][0].set_ylabel("share of trials (%)")
    handles = [Patch(color=STATUS_COLORS.get(s, "#bbbbbb"), label=s.replace("_", " ")) for s in statuses]
    fig.legend(handles=handles, loc="lower center", ncol=min(len(handles), 6), frameon=False,
               bbox_to_anchor=(0.5, -0.02))
    fig.suptitle("Trial outcomes by planner (labels: successes / trials)")
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    return save_figure(fig, path)


def plot_time_cdf(records: Sequence[TrialRecord], *, planners: Sequence[str], path: Path) -> Path:
    """Share of each planner's trials solved within a planning time (log time axis)."""
    colors = planner_colors(planners)
    fig, ax = plt.subplots(figsize=(7.5, 4.6))
    all_t = [t for t in metric_values(records, "planning_time_s") if t > 0]
    t_min = min(all_t) if all_t else 1e-3
    limits = sorted({float(r.time_limit_s) for r in records if r.time_limit_s})
    t_max = max([max(all_t, default=1.0)] + limits)
    for p in planners:
        mine = [r for r in records if r.planner == p]
        t = np.sort(metric_values(mine, "planning_time_s"))
        k, n = len(t), len(mine)
        xs = np.concatenate([[t_min / 2], t, [t_max * 1.5]])
        ys = np.concatenate([[0.0], np.arange(1, k + 1) / max(n, 1), [k / max(n, 1)]]) * 100
        ax.step(xs, ys, where="post", color=colors[p], linewidth=2, label=f"{p} ({k}/{n} solved)")
    for lim in limits:
        ax.axvline(lim, color="0.3", linestyle="--", linewidth=1)
        ax.text(lim, 2, f" time limit {lim:g} s", rotation=90, va="bottom", ha="right", fontsize=8, color="0.3")
    ax.set_xscale("log")
    ax.set_xlim(t_min / 2, t_max * 1.5)
    ax.set_ylim(0, 102)
    ax.set_xlabel("planning time (s, log scale)")
    ax.set_ylabel("problems solved (% of trials)")
    ax.set_title("Share of problems solved within a planning time")
    ax.grid(alpha=0.3, which="both")
    ax.legend(loc="upper left")
    fig.tight_layout()
    return save_figure(fig, path)
