"""The run's figures, drawn from the saved trial records alone (PNG, matplotlib Agg).

Each planner keeps one colour in every figure (`planner_colors`). `make_plots(run_dir)` draws:
metric box plots, outcomes by status, the planning-time CDF, the gripper's paths over the scene
(top and side views) and the timed joint position and velocity profiles of one motion.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Circle, Patch, Rectangle  # noqa: E402

from suite.run.records import (  # noqa: E402
    BACK_ON_PLATE,
    BIN,
    CAN_FATES,
    ELSEWHERE,
    NOT_ATTEMPTED,
    SUCCESS,
    fate_counts,
    is_success,
    joint_path,
    metric_values,
    planners_in,
    problem_kinds_in,
    read_manifest,
    read_trials,
    statuses_in,
)

log = logging.getLogger(__name__)

PLOTS_DIR = "plots"
DPI = 110

#: Fixed colours of the built-in planners; other planners take the spare ones in order.
BUILTIN_COLORS = {
    "ik": "#1f77b4",
    "rrt": "#ff7f0e",
    "trajopt": "#2ca02c",
    "rrtstar": "#d62728",
    "bitstar": "#9467bd",
    "aorrtc": "#8c564b",
    "prm": "#e377c2",
}
SPARE_COLORS = ("#17becf", "#bcbd22", "#7f7f7f", "#393b79", "#637939", "#843c39", "#7b4173")

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
    "ee_path_length_m": ("Gripper path length", "length (m)", False),
    "smoothness": ("Smoothness", "smoothness (lower is smoother)", False),
    "clearance_min_m": ("Minimum clearance", "clearance (m)", False),
    "duration_s": ("Trajectory duration (TOPP-RA)", "duration (s)", False),
}


def planner_colors(planners: Sequence[str]) -> dict[str, str]:
    """One colour per planner: the built-ins' fixed colours, then spare colours in order."""
    spare = iter(c for c in SPARE_COLORS)
    out = {}
    for p in planners:
        out[p] = BUILTIN_COLORS.get(p) or next(spare, "#7f7f7f")
    return out


def _save(fig, path: Path) -> Path:
    fig.savefig(path, dpi=DPI, bbox_inches="tight")
    plt.close(fig)
    log.debug("wrote %s", path)
    return path


def _no_data(ax, text: str = "no successful trials") -> None:
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, color="0.4")


# --- statistics figures ---------------------------------------------------------------------------


def plot_metric_boxes(records: Sequence[dict], *, planners: Sequence[str], path: Path) -> Path:
    """Box plots of each metric by planner over successful trials, with the points and n shown."""
    colors = planner_colors(planners)
    names = [m for m in BOX_METRICS if any(len(metric_values([r for r in records if r["planner"] == p], m)) for p in planners)]
    names = names or list(BOX_METRICS)[:1]
    ncols = min(3, len(names))
    nrows = math.ceil(len(names) / ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.6 * ncols, 3.9 * nrows), squeeze=False)
    rng = np.random.default_rng(0)  # jitter of the points only
    for ax, name in zip(axes.flat, names):
        title, ylabel, log_y = BOX_METRICS[name]
        data = [metric_values([r for r in records if r["planner"] == p], name) for p in planners]
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
        ax.set_title(title)
        ax.set_ylabel(ylabel)
        ax.grid(axis="y", alpha=0.3)
    for ax in list(axes.flat)[len(names):]:
        ax.set_visible(False)
    fig.suptitle("Metrics of the successful trials by planner (box: quartiles and median; dots: trials)")
    fig.tight_layout()
    return _save(fig, path)


def plot_outcomes(records: Sequence[dict], *, planners: Sequence[str], path: Path) -> Path:
    """Stacked bars of trial outcomes by status for each planner: over all motions and per kind."""
    statuses = statuses_in(records)
    kinds = problem_kinds_in(records)
    groups = [("all motions", list(records))] + [(k, [r for r in records if r["problem"] == k]) for k in kinds]
    fig, axes = plt.subplots(1, len(groups), figsize=(2.0 + 0.8 * len(planners) * len(groups), 4.4),
                             squeeze=False, gridspec_kw={"width_ratios": [1.4] + [1] * (len(groups) - 1)})
    x = np.arange(len(planners))
    for ax, (label, recs) in zip(axes[0], groups):
        bottom = np.zeros(len(planners))
        totals = np.array([sum(r["planner"] == p for r in recs) for p in planners], float)
        frac_den = np.maximum(totals, 1)
        for s in statuses:
            counts = np.array([sum(r["planner"] == p and r["status"] == s for r in recs) for p in planners], float)
            ax.bar(x, counts / frac_den * 100, bottom=bottom, color=STATUS_COLORS.get(s, "#bbbbbb"),
                   edgecolor="white", linewidth=0.5, width=0.7)
            bottom += counts / frac_den * 100
        for i, p in enumerate(planners):
            k = sum(r["planner"] == p and r["status"] == SUCCESS for r in recs)
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
    return _save(fig, path)


def plot_time_cdf(records: Sequence[dict], *, planners: Sequence[str], path: Path) -> Path:
    """Share of each planner's trials solved within a planning time (log time axis)."""
    colors = planner_colors(planners)
    fig, ax = plt.subplots(figsize=(7.5, 4.6))
    all_t = [t for t in metric_values(records, "planning_time_s") if t > 0]
    t_min = min(all_t) if all_t else 1e-3
    limits = sorted({float(r["time_limit_s"]) for r in records if r.get("time_limit_s")})
    t_max = max([max(all_t, default=1.0)] + limits)
    for p in planners:
        mine = [r for r in records if r["planner"] == p]
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
    return _save(fig, path)


# --- scene figures --------------------------------------------------------------------------------


def densify_joint_path(path: np.ndarray, *, step_rad: float = 0.01) -> np.ndarray:
    """The piecewise-linear joint path resampled so no joint moves more than step_rad per step."""
    pieces = [path[:1]]
    for a, b in zip(path[:-1], path[1:]):
        n = max(1, int(math.ceil(np.max(np.abs(b - a)) / step_rad)))
        f = np.arange(1, n + 1)[:, None] / n
        pieces.append(a + f * (b - a))
    return np.vstack(pieces)


def _scene_spec(manifest: dict[str, Any], variant: str, *, cans_seen: int):
    """The run's scene spec (the manifest's spec file and can count; else the default spec with
    as many cans as the records name)."""
    from scenes.spec import load_spec

    config = manifest.get("config") or {}
    spec = load_spec(config.get("spec"), variant=variant)
    count = config.get("cans") if isinstance(config.get("cans"), int) else cans_seen
    return spec.with_can_count(count) if count else spec


def _scene_cans(spec, scene_seed: int, scene_key: str | None):
    """The scene's cans if regenerating them (without the reachability check) gives the recorded scene."""
    from scenes.generate import generate_scene

    try:
        scene = generate_scene(spec, seed=scene_seed, check_reachable=False)
    except Exception as exc:  # the drawing is optional; the figure still shows the paths
        log.info("cannot regenerate scene %d for drawing: %s", scene_seed, exc)
        return ()
    if scene_key and scene.key() != scene_key:
        log.info("scene %d: cans redrawn for reachability in the run; not drawing them", scene_seed)
        return ()
    return scene.cans


def _draw_box(ax, center, size, *, dims: tuple[int, int], **kw) -> None:
    i, j = dims
    ax.add_patch(Rectangle((center[i] - size[i] / 2, center[j] - size[j] / 2), size[i], size[j], **kw))


def _draw_scene(ax, spec, cans, *, dims: tuple[int, int]) -> None:
    """Plate, bin, wall (and cans) projected on the plane of world axes `dims`."""
    _draw_box(ax, spec.plate.center_m, spec.plate.size_m, dims=dims, facecolor="0.85", edgecolor="0.45", label="plate")
    for k, box in enumerate(spec.bin.boxes().values()):
        _draw_box(ax, box.center_m, box.size_m, dims=dims, facecolor=(0.1, 0.45, 0.2, 0.25),
                  edgecolor=(0.1, 0.45, 0.2), label="bin" if k == 0 else None)
    if spec.wall is not None:
        _draw_box(ax, spec.wall.center_m, spec.wall.size_m, dims=dims, facecolor=(0.45, 0.47, 0.55, 0.45),
                  edgecolor="0.3", hatch="//", label="wall")
    r, h = spec.can.radius_m, spec.can.height_m
    for k, can in enumerate(cans):
        c = np.asarray(can.p_WC_m)
        if dims == (0, 1) and not can.lying:
            ax.add_patch(Circle(c[:2], r, facecolor=(0.85, 0.1, 0.1, 0.5), edgecolor="darkred",
                                label="can" if k == 0 else None))
        else:
            # a lying can's outline: its axis along yaw, or an upright can seen from the side
            if can.lying:
                a = np.array([math.cos(can.axis_yaw_rad), math.sin(can.axis_yaw_rad), 0.0])
                half = np.abs(a) * h / 2 + (1 - np.abs(a)) * r
                half[2] = r
            else:
                half = np.array([r, r, h / 2])
            _draw_box(ax, c, 2 * half, dims=dims, facecolor=(0.85, 0.1, 0.1, 0.5), edgecolor="darkred",
                      label="can" if k == 0 else None)


def plot_gripper_paths(
    records: Sequence[dict], *, planners: Sequence[str], scene_seed: int, variant: str, manifest: dict[str, Any],
    path: Path,
) -> Path:
    """The gripper's paths (forward kinematics of the saved joint paths) over one scene: top and side view."""
    from scenes.robot_model import load_robot

    robot = load_robot()
    colors = planner_colors(planners)
    scene_recs = [r for r in records if int(r["scene_seed"]) == scene_seed and r["variant"] == variant]
    spec = _scene_spec(manifest, variant, cans_seen=1 + max((int(r["can_id"]) for r in scene_recs), default=-1))
    key = next((r.get("scene_key") for r in scene_recs if r.get("scene_key")), None)
    cans = _scene_cans(spec, scene_seed, key)
    fig, (ax_top, ax_side) = plt.subplots(1, 2, figsize=(13, 6.2), gridspec_kw={"width_ratios": [1, 1.15]})
    _draw_scene(ax_top, spec, cans, dims=(0, 1))
    _draw_scene(ax_side, spec, cans, dims=(1, 2))
    counts = {}
    for p in planners:
        mine = [r for r in scene_recs if r["planner"] == p and is_success(r)]
        counts[p] = (len(mine), sum(r["planner"] == p for r in scene_recs))
        for r in mine:
            q = joint_path(r)
            if q is None:
                continue
            p_WG = robot.gripper_pose(densify_joint_path(q))[:, :3, 3]
            for ax, (i, j) in ((ax_top, (0, 1)), (ax_side, (1, 2))):
                ax.plot(p_WG[:, i], p_WG[:, j], color=colors[p], linewidth=1.3, alpha=0.8)
    # grasp poses, from the recorded goals of the descend motions
    q_grasp = [r["q_goal"] for r in scene_recs if r["problem"] == "descend" and r.get("q_goal")]
    if q_grasp:
        p_grasp = robot.gripper_pose(np.asarray(q_grasp, float))[:, :3, 3]
        for ax, (i, j) in ((ax_top, (0, 1)), (ax_side, (1, 2))):
            ax.scatter(p_grasp[:, i], p_grasp[:, j], marker="x", color="black", s=30, zorder=4, label="grasp pose")
    ax_top.set_xlabel("x (m)")
    ax_top.set_ylabel("y (m)")
    ax_top.set_title("Top view")
    ax_side.set_xlabel("y (m)")
    ax_side.set_ylabel("z (m)")
    ax_side.set_title("Side view (from +x)")
    for ax in (ax_top, ax_side):
        ax.set_aspect("equal")
        ax.autoscale_view()
        ax.grid(alpha=0.3)
    ax_side.set_ylim(bottom=-0.02)
    handles = [plt.Line2D([], [], color=colors[p], linewidth=2, label=f"{p} ({counts[p][0]}/{counts[p][1]} solved)")
               for p in planners]
    h2, l2 = ax_top.get_legend_handles_labels()
    seen = set()
    extra = [(h, lab) for h, lab in zip(h2, l2) if not (lab in seen or seen.add(lab))]
    ax_side.legend(handles=handles + [h for h, _ in extra], labels=[h.get_label() for h in handles] + [lab for _, lab in extra],
                   loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    fig.suptitle(f"Gripper paths of every motion, scene seed {scene_seed} ({variant})")
    fig.tight_layout()
    return _save(fig, path)


def _profile_records(records: Sequence[dict], planners: Sequence[str], kind: str):
    """For one problem (of `kind`, in the first scene where most planners solved it), each planner's record."""
    cands: dict[tuple, dict[str, dict]] = {}
    for r in records:
        if r["problem"] == kind and is_success(r) and joint_path(r) is not None:
            key = (int(r["scene_seed"]), str(r["variant"]), int(r["can_id"]))
            cands.setdefault(key, {}).setdefault(r["planner"], r)
    if not cands:
        return None, {}
    order = {k: i for i, k in enumerate(cands)}
    best = max(cands, key=lambda k: (len(cands[k]), -order[k]))
    return best, {p: cands[best][p] for p in planners if p in cands[best]}


def plot_joint_profiles(records: Sequence[dict], *, planners: Sequence[str], kind: str, path: Path) -> Path | None:
    """Joint positions and velocities of each planner's timed trajectory of one motion, with limits dashed.

    The saved joint paths are timed again with `suite.scoring.timing.time_parameterize` (TOPP-RA), as the
    trial did. Returns None if no planner solved a motion of this kind.
    """
    from scenes.robot_model import load_robot
    from suite.scoring.timing import time_parameterize

    key, chosen = _profile_records(records, planners, kind)
    if not chosen:
        return None
    robot = load_robot()
    colors = planner_colors(planners)
    lo, hi, vmax = robot.lower_rad, robot.upper_rad, robot.velocity_limits_rad_s
    fig, axes = plt.subplots(7, 2, figsize=(12, 14), sharex=True)
    durations = {}
    for p, r in chosen.items():
        traj = time_parameterize(joint_path(r), robot=robot)
        if not traj.ok:
            log.info("%s %s: timing failed (%s); not drawn", p, kind, traj.reason)
            continue
        durations[p] = traj.duration_s
        for j in range(7):
            axes[j, 0].plot(traj.t_s, traj.q[:, j], color=colors[p], linewidth=1.6)
            axes[j, 1].plot(traj.t_s, traj.qd[:, j], color=colors[p], linewidth=1.6)
    for j in range(7):
        for ax, (a, b) in ((axes[j, 0], (lo[j], hi[j])), (axes[j, 1], (-vmax[j], vmax[j]))):
            ax.axhline(a, color="0.35", linestyle="--", linewidth=1)
            ax.axhline(b, color="0.35", linestyle="--", linewidth=1)
            span = b - a
            ax.set_ylim(a - 0.08 * span, b + 0.08 * span)
            ax.grid(alpha=0.3)
        axes[j, 0].set_ylabel(f"joint {j + 1}\nq (rad)")
        axes[j, 1].set_ylabel(f"q̇{j + 1} (rad/s)")
    axes[0, 0].set_title("Joint positions (dashed: joint limits)")
    axes[0, 1].set_title("Joint velocities (dashed: velocity limits)")
    axes[-1, 0].set_xlabel("time (s)")
    axes[-1, 1].set_xlabel("time (s)")
    handles = [plt.Line2D([], [], color=colors[p], linewidth=2,
                          label=f"{p} ({durations[p]:.2f} s)" if p in durations else f"{p} (timing failed)")
               for p in chosen]
    fig.legend(handles=handles, loc="upper center", ncol=len(handles), bbox_to_anchor=(0.5, 0.965), frameon=False)
    seed, variant, can = key
    fig.suptitle(f"Timed trajectories (TOPP-RA) of the {kind} motion: scene seed {seed} ({variant}), can {can}")
    fig.tight_layout(rect=(0, 0, 1, 0.955))
    return _save(fig, path)


# --- all of them ----------------------------------------------------------------------------------


def plot_execution(executions: Sequence[dict], *, planners: Sequence[str], path: Path) -> Path:
    """Cans recycled per planner after physics execution: stacked bars of where the cans ended."""
    planners = [p for p in planners if any(e["planner"] == p for e in executions)]
    colors = {BIN: "#2e8b57", BACK_ON_PLATE: "#f0a202", ELSEWHERE: "#d62728", NOT_ATTEMPTED: "#c8c8c8"}
    labels = {ELSEWHERE: "dropped elsewhere", NOT_ATTEMPTED: "not attempted (plan incomplete)"}
    fig, ax = plt.subplots(figsize=(3.0 + 1.1 * len(planners), 4.6))
    x = np.arange(len(planners))
    bottom = np.zeros(len(planners))
    totals = np.array([sum(e["cans_total"] for e in executions if e["planner"] == p) for p in planners], float)
    counts = {p: fate_counts(e for e in executions if e["planner"] == p) for p in planners}
    for fate in CAN_FATES:
        n = np.array([counts[p][fate] for p in planners], float)
        ax.bar(x, n / np.maximum(totals, 1) * 100, bottom=bottom, color=colors[fate], label=labels.get(fate, fate),
               width=0.6, edgecolor="white", linewidth=0.5)
        bottom += n / np.maximum(totals, 1) * 100
    for i, p in enumerate(planners):
        runs = [e for e in executions if e["planner"] == p]
        k = sum(e.get("cans_in_bin", 0) for e in runs)
        hits = sum(e.get("collisions", 0) for e in runs)
        ax.text(i, 101.5, f"{k}/{int(totals[i])}\n{hits} collision{'s' * (hits != 1)}", ha="center",
                va="bottom", fontsize=8)
    ax.set_xticks(x, planners)
    for tick, p in zip(ax.get_xticklabels(), planners):
        tick.set_color(planner_colors(planners)[p])
        tick.set_fontweight("bold")
    ax.set_ylim(0, 118)
    ax.set_ylabel("share of cans (%)")
    ax.grid(axis="y", alpha=0.3)
    scenes = len({(e["scene_seed"], e["variant"]) for e in executions})
    ax.set_title(f"Cans recycled in physics ({scenes} scene{'s' * (scenes != 1)})\nlabels: cans in bin / cans, "
                 "unintended contacts", fontsize=10)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, frameon=False, fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


def make_plots(run_dir: str | Path, *, records: Sequence[dict] | None = None,
               executions: Sequence[dict] = ()) -> list[Path]:
    """Draw every figure of a run into run_dir/plots/.

    Args:
        run_dir: the run directory (with trials.jsonl and, optionally, manifest.json).
        records: the run's records if already read (default: read run_dir/trials.jsonl).
        executions: the run's physics execution records (adds execution.png).

    Returns:
        The PNG files written.
    """
    run_dir = Path(run_dir)
    records = list(records) if records is not None else read_trials(run_dir)
    manifest = read_manifest(run_dir)
    planners = planners_in(records, manifest)
    out_dir = run_dir / PLOTS_DIR
    out_dir.mkdir(parents=True, exist_ok=True)
    if not records:
        log.warning("%s: no trial records, no plots", run_dir)
        return []
    written = [
        plot_metric_boxes(records, planners=planners, path=out_dir / "metrics_boxplots.png"),
        plot_outcomes(records, planners=planners, path=out_dir / "outcomes.png"),
        plot_time_cdf(records, planners=planners, path=out_dir / "planning_time_cdf.png"),
    ]
    # the first scene (lowest seed) of each variant: the same file names whatever order trials finished in
    firsts: dict[str, int] = {}
    for r in records:
        v = str(r["variant"])
        firsts[v] = min(firsts.get(v, int(r["scene_seed"])), int(r["scene_seed"]))
    for variant, seed in firsts.items():
        written.append(
            plot_gripper_paths(records, planners=planners, scene_seed=seed, variant=variant, manifest=manifest,
                               path=out_dir / f"gripper_paths_seed{seed}_{variant}.png")
        )
    kinds = problem_kinds_in(records)
    kind = "transit" if "transit" in kinds else next(
        (k for k in kinds if any(r["problem"] == k and is_success(r) for r in records)), None)
    if kind is not None:
        p = plot_joint_profiles(records, planners=planners, kind=kind, path=out_dir / f"joint_profiles_{kind}.png")
        if p is not None:
            written.append(p)
    if executions:
        written.append(plot_execution(executions, planners=planners, path=out_dir / "execution.png"))
    log.info("wrote %d plots to %s", len(written), out_dir)
    return written
