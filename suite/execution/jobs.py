"""Physics execution jobs: which plans are executed, in which process, and where results go.

One job = one planner on one scene. Its plans come from a comparison run's records (open loop),
are planned in the job's own process before execution (open loop), or are planned can by can
between cycles from what the simulation's cameras see (`reperceive`, closed loop). Every path
executed passed the same validation and TOPP-RA timing as in a comparison trial.
"""

from __future__ import annotations

import dataclasses
import logging
import sys
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from planners.base import PROBLEM_KINDS
from scenes.scene import Scene
from suite.execution.execution_records import ExecutionRecord
from suite.execution.job_spec import ExecutionJob
from suite.execution.moving_bin_records import MovingBinRecord
from suite.execution.plan_loop import closed_loop, open_loop, plan_open_loop
from suite.execution.simulate import execute_cycles
from suite.run.records import TrialRecord

log = logging.getLogger(__name__)


def run_execution(job: ExecutionJob) -> ExecutionRecord:
    """Plan if needed, execute in physics, write the replay; the outcome as a record (built as its JSON)."""
    from suite.problems.cycle import build_problems
    from suite.run.runner import plan_world_for, scene_task

    scene = job.scene
    induced: list[dict] = []  # perception-induced failures
    worlds: list[dict] = []  # the perceived worlds planned in
    planning_s: list[float] = []  # every problem's planning time

    def first_problems(first_only: bool = False):
        grasps, seen = scene_task(scene, grasps=job.grasps, perception=job.perception, world=job.world)
        if seen is not None:
            worlds.append(seen.summary())
        return build_problems(scene, grasps[:1] if first_only else grasps, time_limit_s=job.time_limit_s,
                              seed=job.seed, world=seen)

    # The arm starts where the first approach starts (above the plate); the goal IK behind it runs
    # once: from the problems this job plans, or from the first grasp's problems alone.
    if job.reperceive:
        provider = closed_loop(job, induced, worlds, planning_s)
        q_home = first_problems(first_only=True)[0].q_start
        worlds.clear()  # the closed loop builds its own (the first from the same frames)
    elif job.cans is None:
        grasps, seen = scene_task(scene, grasps=job.grasps, perception=job.perception, world=job.world)
        if seen is not None:
            worlds.append(seen.summary())
        if not grasps:
            raise RuntimeError(f"no grasps to plan: {job.grasps} grasps found no can")
        planned, q_home = plan_open_loop(scene, grasps, seen, job, induced, planning_s)
        provider = open_loop(planned, skip=job.on_failure == "skip")
    else:
        provider, q_home = open_loop(job.cans), np.asarray(job.q_home, float)
    meshcat = meshcat_for(scene) if job.replay_path else None
    outcome = execute_cycles(scene, provider, q_home=q_home, planner=job.planner, config=job.config,
                             meshcat=meshcat, cameras=job.reperceive and job.grasps == "perceived")
    record = outcome.to_json()
    record.update(grasps=job.grasps, reperceive=job.reperceive, config=dataclasses.asdict(job.config),
                  on_failure=job.on_failure if job.cans is None else "stop")
    record["worlds"] = {"planned": plan_world_for(job.grasps, job.world), "judged": "truth", "physics": "truth"}
    if worlds:
        record["perceived_worlds"] = worlds
    record["perception_induced"] = induced
    record["planning_time_s"] = round(sum(planning_s), 4) if planning_s else None
    if job.perception is not None and job.grasps == "perceived":
        record["perception"] = job.perception.to_json()
    if meshcat is not None:
        Path(job.replay_path).write_text(meshcat.StaticHtml(), encoding="utf-8")
        record["replay"] = Path(job.replay_path).name
    return ExecutionRecord.from_json(record)


def meshcat_for(scene: Scene):
    """A Meshcat for a replay of `scene`, its camera looking at the work area."""
    from pydrake.geometry import Meshcat

    logging.getLogger("drake").setLevel(logging.WARNING)  # "Meshcat listening..." is not news here
    meshcat = Meshcat()
    # Look at the work area (plate, wall, bin) from the front right, a little above the arm.
    spec = scene.spec
    target = np.array([*np.mean(spec.work_xy_m(), axis=0), 0.1])
    meshcat.SetCameraPose(target + np.array([1.3, -0.9, 0.8]), target)
    return meshcat


def jobs_from_records(trials, records: Sequence[TrialRecord], *, grasps: str, time_limit_s: float,
                      seed: int, reperceive: bool, replay_dir: Path | None,
                      cycle_steps: dict | None = None, shared_steps: dict | None = None,
                      picking_orders: dict | None = None, world: str | None = None) -> list[ExecutionJob]:
    """One job per planner and scene of a comparison run, its plans taken from the trial records.

    Args:
        trials: the run's TrialSpecs in problem order (this gives each scene's picking order).
        records: the run's trial records (paths of the successful, validated trials).
        replay_dir: where to write replay_<planner>.html for each planner's first scene, or None.
        cycle_steps: a dataset's trivial cycle steps left out of its benchmark, (scene key, can
            id, kind) -> (q_start, q_goal): executed along their (validated) straight segment.
        shared_steps: cycle steps identical to a problem the run planned for another scene,
            (scene key, can id, kind) -> problem_id: executed along the planner's path of it.
        picking_orders: a dataset's cans per scene key in picking order; every can of it is picked,
            also one whose steps are all stored outside the benchmark (default: the cans planned,
            in id order).
    """

    by_id = {r.trial_id: r for r in records}
    groups: dict[tuple[str, str], list] = {}
    scenes: dict[str, Scene] = {}
    configs: dict[str, dict] = {}
    for t in trials:
        key = t.problem.scene.key()
        groups.setdefault((t.planner, key), []).append(t)
        scenes[key] = t.problem.scene
        configs[t.planner] = t.planner_config
    steps = cycle_steps or {}
    shared = shared_steps or {}
    by_problem = {(r.planner, r.problem_id): r for r in records if r.problem_id}
    jobs, replayed = [], set()
    for (planner, key), specs in groups.items():
        by_can: dict[int, dict[str, Any]] = {}
        for t in specs:
            rec = by_id.get(t.trial_id)
            status = rec.status if rec else "not run"
            by_can.setdefault(t.problem.can_id, {})[t.problem.kind] = (rec.path if status == "success" else None,
                                                                     t.problem.q_start, status)
        cans: dict[int, list] = {}
        q_home = None
        for can_id in (picking_orders or {}).get(key) or sorted(by_can):
            paths, failed = [], ""
            for kind in PROBLEM_KINDS:
                if kind in by_can.get(can_id, {}):
                    path, q_start, status = by_can[can_id][kind]
                elif (key, can_id, kind) in steps:  # a trivial step stored outside the benchmark
                    q_start, q_goal = steps[(key, can_id, kind)]
                    path, status = [list(q_start), list(q_goal)], "success"
                elif (planner, shared.get((key, can_id, kind))) in by_problem:  # planned once, for another scene
                    rec = by_problem[(planner, shared[(key, can_id, kind)])]
                    status = rec.status
                    path, q_start = (rec.path if status == "success" else None), rec.q_start
                else:
                    path, q_start, status = None, None, "not in the dataset"
                if q_home is None and q_start is not None:
                    q_home = q_start
                paths.append(path)
                if path is None and not failed:
                    failed = f"{kind} {status}"
            cans[can_id] = [paths, failed]
        replay = None
        if replay_dir is not None and planner not in replayed:
            replay, _ = str(Path(replay_dir) / f"replay_{planner}.html"), replayed.add(planner)
        jobs.append(ExecutionJob(
            planner=planner, planner_config=configs[planner], scene=scenes[key], grasps=grasps,
            time_limit_s=time_limit_s, seed=seed, reperceive=reperceive, replay_path=replay,
            cans=None if reperceive else tuple((c, tuple(p), f) for c, (p, f) in cans.items()),
            q_home=None if q_home is None else tuple(float(v) for v in q_home), world=world,
        ))
    return jobs


def run_jobs(jobs: Sequence[Any], *, workers: int, progress_bar: bool = True, run=None,
             desc: str = "execution") -> list[ExecutionRecord | MovingBinRecord]:
    """Run execution jobs in `workers` spawned processes; records in the jobs' order. `run` is the
    module-level function that runs one job and returns its record (default `run_execution`; it
    catches its own errors, as `suite.execution.moving_bin.run_moving_bin_job` does)."""
    import concurrent.futures as cf
    import multiprocessing as mp

    from tqdm import tqdm

    from suite.run.interrupt import signals_blocked
    from suite.run.runner import worker_init

    results: list[ExecutionRecord | MovingBinRecord | None] = [None] * len(jobs)
    bar = tqdm(total=len(jobs), desc=desc, unit="run", disable=not progress_bar,
               file=sys.stderr, dynamic_ncols=True)
    if workers <= 1 or len(jobs) <= 1:
        worker_init()
        for i, job in enumerate(jobs):
            results[i] = _guarded(job) if run is None else run(job)
            bar.update(1)
    else:
        with cf.ProcessPoolExecutor(max_workers=min(workers, len(jobs)), mp_context=mp.get_context("spawn"),
                                    initializer=worker_init) as pool:
            with signals_blocked():  # the pool spawns its workers as jobs are submitted
                futures = {pool.submit(_guarded if run is None else run, job): i for i, job in enumerate(jobs)}
            for fut in cf.as_completed(futures):
                i = futures[fut]
                try:
                    results[i] = fut.result()
                except Exception as exc:  # the worker process died
                    message = f"{type(exc).__name__}: {exc}"
                    # a moving-bin episode's record (its job makes it), else an execution's
                    results[i] = jobs[i].record("error", message) if run is not None else _failed(jobs[i], message)
                rec = results[i]
                bar.set_postfix_str(f"{rec.planner} seed {rec.scene_seed}: {rec.cans_in_bin}/{rec.cans_total} in bin",
                                    refresh=False)
                bar.update(1)
    bar.close()
    return [r for r in results if r is not None]


def _guarded(job: ExecutionJob) -> ExecutionRecord:
    try:
        return run_execution(job)
    except Exception as exc:  # one failed simulation is that run's error, not the whole run's
        log.debug("execution of %s on seed %d failed", job.planner, job.scene.seed, exc_info=True)
        return _failed(job, f"{type(exc).__name__}: {exc}")


def _failed(job: ExecutionJob, message: str) -> ExecutionRecord:
    """The record of an execution that raised: the counts it knew and the error."""
    perceived = getattr(job, "perception", None) is not None and getattr(job, "grasps", None) == "perceived"
    return ExecutionRecord.from_json({
        "planner": job.planner, "scene_seed": job.scene.seed, "variant": job.scene.variant,
        "cans_total": len(job.scene.cans), "error": message, "grasps": getattr(job, "grasps", None),
        "reperceive": getattr(job, "reperceive", False),
        **({"perception": job.perception.to_json()} if perceived else {})})
