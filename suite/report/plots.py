"""The run's figures, drawn from the saved trial records alone (PNG, matplotlib Agg).

Each planner keeps one colour in every figure (`plots_common.planner_colors`). `make_plots(run_dir)`
draws: metric box plots, the natural-poses panel, outcomes by status, the planning-time CDF
(`plots_stats`), success rate and length ratio per scene family (`plots_families`), the gripper's
paths over the scene (top and side views) and the timed joint position and velocity profiles of
one motion (`plots_paths`), and where the cans ended in physics (`plots_execution`).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path

from suite.report.plots_common import PLOTS_DIR
from suite.report.plots_execution import plot_execution
from suite.report.plots_paths import plot_gripper_paths, plot_joint_profiles
from suite.report.plots_families import plot_length_ratio_by_family, plot_success_by_family
from suite.report.plots_stats import NATURAL_POSE_METRICS, plot_metric_boxes, plot_outcomes, plot_time_cdf
from suite.run.records import (
    is_success,
    planners_in,
    problem_kinds_in,
    read_manifest,
    read_trials,
)

log = logging.getLogger(__name__)


def make_plots(run_dir: str | Path, *, records: Sequence[dict] | None = None,
               executions: Sequence[dict] = (), budget_records: Sequence[dict] = ()) -> list[Path]:
    """Draw every figure of a run into run_dir/plots/.

    Args:
        run_dir: the run directory (with trials.jsonl and, optionally, manifest.json).
        records: the run's records if already read (default: read run_dir/trials.jsonl).
        executions: the run's physics execution records (adds execution.png).
        budget_records: a run at several budgets, with its own planner names (adds budget_curves.png).

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
        plot_success_by_family(records, planners=planners, path=out_dir / "success_by_family.png"),
        plot_length_ratio_by_family(records, planners=planners, path=out_dir / "length_ratio_by_family.png"),
        plot_metric_boxes(records, planners=planners, path=out_dir / "natural_poses.png", panels=NATURAL_POSE_METRICS,
                          title="Natural poses (the seed paper's question) over each planner's solved problems"),
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
    from suite.report.plots_attribution import plot_time_attribution

    p = plot_time_attribution(records, planners=planners, path=out_dir / "time_attribution.png")
    if p is not None:
        written.append(p)
    if executions:
        written.append(plot_execution(executions, planners=planners, path=out_dir / "execution.png"))
    if budget_records:
        from suite.report.budgets import plot_budget_curves

        written.append(plot_budget_curves(budget_records, planners=planners_in(budget_records, manifest),
                                          path=out_dir / "budget_curves.png"))
    log.info("wrote %d plots to %s", len(written), out_dir)
    return written
