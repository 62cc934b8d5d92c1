"""The run's figures, drawn from the saved trial records alone (PNG, matplotlib Agg).

Each planner keeps one colour in every figure (`plots_common.planner_colors`). `make_plots(run_dir)`
draws: metric box plots, the natural-poses panel, outcomes by status, the planning-time CDF
(`plots_stats`), success rate and length ratio per scene family (`plots_families`), the gripper's
paths over the scene (top and side views) and the timed joint position and velocity profiles of
one motion (`plots_paths`), where the cans ended in physics (`plots_execution`), and the moving bin
(`plots_moving_bin`).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path

from suite.execution.execution_records import ExecutionRecord
from suite.report.plots_common import PLOTS_DIR
from suite.report.plots_execution import plot_execution
from suite.report.plots_families import (
    plot_length_ratio_by_family,
    plot_success_by_family,
)
from suite.report.plots_paths import plot_gripper_paths, plot_joint_profiles
from suite.report.plots_stats import (
    NATURAL_POSE_METRICS,
    plot_metric_boxes,
    plot_outcomes,
    plot_time_cdf,
)
from suite.run.records import (
    TrialRecord,
    is_success,
    planners_in,
    problem_kinds_in,
    read_manifest,
    read_trials,
)

log = logging.getLogger(__name__)


def make_plots(run_dir: str | Path, *, records: Sequence[TrialRecord] | None = None,
               executions: Sequence[ExecutionRecord] = (), budget_records: Sequence[TrialRecord] = ()) -> list[Path]:
    """Draw every figure of a run into run_dir/plots/.

    Args:
        run_dir: the run directory (with trials.jsonl and, optionally, manifest.json).
        records: the run's records if already read (default: read run_dir/trials.jsonl).
        executions: the run's physics execution records (adds execution.png).
        budget_records: a run at several budgets, with its own planner names (adds budget_curves.png).

    Returns:
        The PNG files written.
    """
    return start_plots(run_dir, records=records, executions=executions, budget_records=budget_records,
                       background=0.0).finish()


def plot_jobs(run_dir: str | Path, *, records: Sequence[TrialRecord] | None = None,
              executions: Sequence[ExecutionRecord] = (), budget_records: Sequence[TrialRecord] = ()) -> list[tuple]:
    """Every figure of a run as (function, args, kwargs), in the order `make_plots` lists them."""
    run_dir = Path(run_dir)
    records = list(records) if records is not None else read_trials(run_dir)
    manifest = read_manifest(run_dir)
    planners = planners_in(records, manifest)
    out_dir = run_dir / PLOTS_DIR
    out_dir.mkdir(parents=True, exist_ok=True)
    if not records:
        log.warning("%s: no trial records, no plots", run_dir)
        return []
    from suite.report.plots_attribution import plot_time_attribution

    common = {"planners": planners}
    jobs: list[tuple] = [
        (plot_metric_boxes, (records,), {**common, "path": out_dir / "metrics_boxplots.png"}),
        (plot_outcomes, (records,), {**common, "path": out_dir / "outcomes.png"}),
        (plot_time_cdf, (records,), {**common, "path": out_dir / "planning_time_cdf.png"}),
        (plot_success_by_family, (records,), {**common, "path": out_dir / "success_by_family.png"}),
        (plot_length_ratio_by_family, (records,), {**common, "path": out_dir / "length_ratio_by_family.png"}),
        (plot_metric_boxes, (records,), {**common, "path": out_dir / "natural_poses.png", "panels": NATURAL_POSE_METRICS,
                                         "title": "Natural poses (the seed paper's question) over each planner's solved problems"}),
    ]
    # the first scene (lowest seed) of each variant: the same file names whatever order trials finished in
    firsts: dict[str, int] = {}
    for r in records:
        v = str(r.variant)
        firsts[v] = min(firsts.get(v, int(r.scene_seed)), int(r.scene_seed))
    for variant, seed in firsts.items():
        jobs.append((plot_gripper_paths, (records,), {**common, "scene_seed": seed, "variant": variant, "manifest": manifest,
                                                      "path": out_dir / f"gripper_paths_seed{seed}_{variant}.png"}))
    kinds = problem_kinds_in(records)
    kind = "transit" if "transit" in kinds else next(
        (k for k in kinds if any(r.problem == k and is_success(r) for r in records)), None)
    if kind is not None:
        jobs.append((plot_joint_profiles, (records,), {**common, "kind": kind, "path": out_dir / f"joint_profiles_{kind}.png"}))
    jobs.append((plot_time_attribution, (records,), {**common, "path": out_dir / "time_attribution.png"}))
    if executions:
        jobs.append((plot_execution, (executions,), {**common, "path": out_dir / "execution.png"}))
    from suite.execution.execution_records import read_moving_bin

    moving = read_moving_bin(run_dir)
    if moving:
        from suite.report.plots_moving_bin import plot_moving_bin

        jobs.append((plot_moving_bin, (moving,), {**common, "path": out_dir / "moving_bin.png"}))
    if budget_records:
        from suite.report.budgets import plot_budget_curves

        jobs.append((plot_budget_curves, (budget_records,), {"planners": planners_in(budget_records, manifest),
                                                             "path": out_dir / "budget_curves.png"}))
    return jobs


def _draw(jobs: Sequence[tuple]) -> list[str | None]:
    return [None if (p := fn(*args, **kwargs)) is None else str(p) for fn, args, kwargs in jobs]


def _draw_into(conn, jobs: Sequence[tuple]) -> None:
    try:
        conn.send(("ok", _draw(jobs)))
    except BaseException as exc:  # reported to the parent, which draws these itself
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
    finally:
        conn.close()


#: How long `finish` waits for the forked process's figures before it kills it and draws them
#: itself (a fork of a process with threads can, rarely, hang on a lock one of them held).
DRAW_TIMEOUT_S = 300.0


class PlotsInProgress:
    """Figures being drawn: a share of them in a forked process (started by `start_plots`), the
    rest by `finish`, which waits for the process and returns every PNG written, in order."""

    def __init__(self, run_dir: Path, jobs: list[tuple], split: int, proc=None, conn=None) -> None:
        self.run_dir, self.jobs, self.split, self.proc, self.conn = run_dir, jobs, split, proc, conn

    def finish(self) -> list[Path]:
        mine = _draw(self.jobs[: self.split])
        theirs: list[str | None] | None = None
        if self.proc is not None:
            try:
                if not self.conn.poll(DRAW_TIMEOUT_S):
                    raise TimeoutError
                status, payload = self.conn.recv()
                theirs = payload if status == "ok" else None
                if status != "ok":
                    log.warning("drawing figures in a second process failed (%s); drawing them here", payload)
            except (EOFError, TimeoutError):
                log.warning("the figure-drawing process gave no answer; drawing its figures here")
                self.proc.kill()
            self.proc.join()
            self.conn.close()
        if theirs is None:
            theirs = _draw(self.jobs[self.split :])
        written = [Path(p) for p in mine + theirs if p is not None]
        log.info("wrote %d plots to %s", len(written), self.run_dir / PLOTS_DIR)
        return written


def start_plots(run_dir: str | Path, *, records: Sequence[TrialRecord] | None = None,
                executions: Sequence[ExecutionRecord] = (), budget_records: Sequence[TrialRecord] = (),
                background: float = 0.6) -> PlotsInProgress:
    """Start drawing a run's figures: the last `background` share of them (by count) in a forked
    process, so that the caller can write its tables meanwhile; `finish()` draws the rest and
    waits. Without fork (not Linux or macOS), or with background 0, all are drawn by `finish`."""
    import multiprocessing as mp

    run_dir = Path(run_dir)
    jobs = plot_jobs(run_dir, records=records, executions=executions, budget_records=budget_records)
    n_bg = int(round(background * len(jobs)))
    if n_bg == 0 or len(jobs) < 2 or "fork" not in mp.get_all_start_methods():
        return PlotsInProgress(run_dir, jobs, len(jobs))
    ctx = mp.get_context("fork")
    parent, child = ctx.Pipe(duplex=False)
    split = len(jobs) - n_bg
    proc = ctx.Process(target=_draw_into, args=(child, jobs[split:]), daemon=True)
    proc.start()
    child.close()
    return PlotsInProgress(run_dir, jobs, split, proc, parent)
