"""Motion figures: the gripper's paths over a scene (top and side views) and timed joint profiles."""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.patches import Polygon

from suite.report.plots_common import planner_colors, plt, save_figure
from suite.run.records import TrialRecord, is_success, joint_path, problem_number

log = logging.getLogger(__name__)


def densify_joint_path(path: np.ndarray, *, step_rad: float = 0.01) -> np.ndarray:
    """The piecewise-linear joint path resampled so no joint moves more than step_rad per step."""
    pieces = [path[:1]]
    for a, b in zip(path[:-1], path[1:]):
        n = max(1, int(math.ceil(np.max(np.abs(b - a)) / step_rad)))
        f = np.arange(1, n + 1)[:, None] / n
        pieces.append(a + f * (b - a))
    return np.vstack(pieces)


def _recorded_scene(manifest: dict[str, Any], variant: str, scene_seed: int, scene_key: str | None, *, cans_seen: int):
    """The run's scene: from its dataset's stored scenes, or generated again as the run generated it
    (its spec file, can count and seed). None if it cannot be had as recorded."""
    from scenes.generate import generate_scene
    from scenes.spec import load_spec

    dataset = manifest.get("dataset")
    if dataset and scene_key:
        from suite.problems.dataset import dataset_scene

        try:
            return dataset_scene(dataset["name"], scene_key)
        except Exception as exc:  # the drawing is optional; the figure still shows the paths
            log.info("scene %s not found in dataset %s: %s", scene_key, dataset["name"], exc)
            return None
    config = manifest.get("config") or {}
    try:
        spec = load_spec(config.get("spec"), variant=variant)
        count = config.get("cans") if isinstance(config.get("cans"), int) else cans_seen
        scene = generate_scene(spec.with_can_count(count) if count else spec, seed=scene_seed)
    except Exception as exc:
        log.info("cannot regenerate scene %d for drawing: %s", scene_seed, exc)
        return None
    if scene_key and scene.key() != scene_key:
        log.info("scene %d: regenerated scene differs from the run's; not drawing the scene", scene_seed)
        return None
    return scene


#: matplotlib style of each outline kind of `scene_outlines` (family obstacles hatched).
OUTLINE_STYLES: dict[str, dict[str, Any]] = {
    "plate": dict(facecolor="0.85", edgecolor="0.45"),
    "bin": dict(facecolor=(0.1, 0.45, 0.2, 0.25), edgecolor=(0.1, 0.45, 0.2)),
    "wall": dict(facecolor=(0.45, 0.47, 0.55, 0.45), edgecolor="0.3", hatch="//"),
    "shelf": dict(facecolor=(0.45, 0.47, 0.55, 0.45), edgecolor="0.3", hatch="//"),
    "obstacle": dict(facecolor=(0.45, 0.47, 0.55, 0.45), edgecolor="0.3", hatch="//"),
    "distractor": dict(facecolor=(0.2, 0.35, 0.75, 0.35), edgecolor="0.3"),
    "can": dict(facecolor=(0.85, 0.1, 0.1, 0.5), edgecolor="darkred"),
}


def _draw_scene(ax, spec, cans, *, dims: tuple[int, int]) -> None:
    """Plate, bin, walls, the family's obstacles and the cans projected on the plane of world axes `dims`."""
    from suite.report.scene_outlines import scene_outlines

    labelled = set()
    for o in scene_outlines(spec, cans, dims=dims):
        ax.add_patch(Polygon(o.xy_m, closed=True, label=None if o.label in labelled else o.label,
                             **OUTLINE_STYLES[o.kind]))
        labelled.add(o.label)


def plot_gripper_paths(
    records: Sequence[TrialRecord], *, planners: Sequence[str], scene_seed: int, variant: str, manifest: dict[str, Any],
    path: Path,
) -> Path:
    """The gripper's paths (forward kinematics of the saved joint paths) over one scene: top and side view."""
    from scenes.robot_model import load_robot

    colors = planner_colors(planners)
    scene_recs = [r for r in records if int(r.scene_seed) == scene_seed and r.variant == variant]
    key = next((r.scene_key for r in scene_recs if r.scene_key), None)
    scene = _recorded_scene(manifest, variant, scene_seed, key,
                            cans_seen=1 + max((int(r.can_id) for r in scene_recs if r.can_id is not None),
                                              default=-1))
    if scene is None:  # draw the variant's fixed parts at least
        from scenes.spec import load_spec

        spec, cans = load_spec((manifest.get("config") or {}).get("spec"), variant=variant), ()
        spec = dataclasses.replace(spec, family=None)
    else:
        spec, cans = scene.spec, scene.cans
    robot = load_robot(spec.robot)  # the gripper's mount is the scene's robot's
    fig, (ax_top, ax_side) = plt.subplots(1, 2, figsize=(13, 6.2), gridspec_kw={"width_ratios": [1, 1.15]})
    _draw_scene(ax_top, spec, cans, dims=(0, 1))
    _draw_scene(ax_side, spec, cans, dims=(1, 2))
    counts = {}
    for p in planners:
        mine = [r for r in scene_recs if r.planner == p and is_success(r)]
        counts[p] = (len(mine), sum(r.planner == p for r in scene_recs))
        for r in mine:
            q = joint_path(r)
            if q is None:
                continue
            p_WG = robot.gripper_pose(densify_joint_path(q))[:, :3, 3]
            for ax, (i, j) in ((ax_top, (0, 1)), (ax_side, (1, 2))):
                ax.plot(p_WG[:, i], p_WG[:, j], color=colors[p], linewidth=1.3, alpha=0.8)
    # grasp poses, from the recorded goals of the descend motions
    q_grasp = [r.q_goal for r in scene_recs if r.problem == "descend" and r.q_goal]
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
    return save_figure(fig, path)


def _profile_records(records: Sequence[TrialRecord], planners: Sequence[str], kind: str):
    """For one problem (of `kind`, in the first scene where most planners solved it), each planner's record."""
    cands: dict[tuple, dict[str, TrialRecord]] = {}
    for r in records:
        if r.problem == kind and is_success(r) and joint_path(r) is not None:
            key = (int(r.scene_seed), str(r.variant), problem_number(r))
            cands.setdefault(key, {}).setdefault(r.planner, r)
    if not cands:
        return None, {}
    order = {k: i for i, k in enumerate(cands)}
    best = max(cands, key=lambda k: (len(cands[k]), -order[k]))
    return best, {p: cands[best][p] for p in planners if p in cands[best]}


def plot_joint_profiles(records: Sequence[TrialRecord], *, planners: Sequence[str], kind: str, path: Path) -> Path | None:
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
    return save_figure(fig, path)
