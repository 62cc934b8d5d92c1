"""A comparison run's plans executed in physics, after its trials (`compare --execute`,
`--reperceive`, `--moving-bin`): one execution job per planner and scene, its plans read from the
run's trials.jsonl, written to execution.json; or the moving-bin sweep over the run's open and
wall scenes, written to moving_bin.json.

On a dataset, the cycle steps the dataset stores once under another scene (identical content) are
found by posing each scene's cycle again, so that every scene is executed cycle by cycle.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING

from suite.run.runner import TRIALS_FILE

if TYPE_CHECKING:
    from suite.run.runner import CompareConfig


def _execution_jobs(trials, out: Path, config: CompareConfig, *, reperceive: bool, replay_dir):
    """One execution job per planner and scene, its plans from the run's records."""
    from suite.execution.jobs import jobs_from_records
    from suite.run.records import read_trials

    steps, shared, orders = None, None, None
    if config.dataset:
        from suite.problems.dataset import load_dataset
        from suite.run.build_dataset import pose_settings

        dataset = load_dataset(config.dataset)
        steps, orders = dataset.cycle_steps, dataset.picking_orders
        shared = _shared_steps(trials, steps, pose=pose_settings(dataset.manifest))
    return jobs_from_records(trials, read_trials(out / TRIALS_FILE), grasps=config.grasps,
                             time_limit_s=config.time_limit_s, seed=config.seed, reperceive=reperceive,
                             replay_dir=replay_dir, cycle_steps=steps, shared_steps=shared, picking_orders=orders,
                             world=config.world)


def execute_run(trials, out: Path, config: CompareConfig, *, reperceive: bool, progress_bar: bool) -> None:
    """Execute every planner's plans for every scene in physics; write execution.json."""
    from suite.execution.execution_records import write_execution
    from suite.execution.jobs import run_jobs

    jobs = _execution_jobs(trials, out, config, reperceive=reperceive, replay_dir=out)
    print(f"executing {len(jobs)} plan(s) in physics ({'closed loop' if reperceive else 'open loop'})...",
          file=sys.stderr)
    write_execution(out, run_jobs(jobs, workers=config.jobs, progress_bar=progress_bar))


def execute_moving_bin(trials, out: Path, config: CompareConfig, *, speeds, scenario, scenes: int, paths: int,
                       progress_bar: bool) -> None:
    """The moving-bin sweep: every planner on the run's first open and wall scenes, on `paths` bin
    paths each, at every speed; write moving_bin.json (and a replay of each planner's episode on
    the first scene at the middle speed); the manifest records the scenario (its latency mode)."""
    from suite.execution.execution_records import write_moving_bin
    from suite.execution.jobs import run_jobs
    from suite.execution.moving_bin import run_moving_bin_job, sweep_jobs
    from suite.execution.moving_bin_records import modelled_latency
    from suite.run.manifest import update_manifest

    mine = [t for t in trials if t.problem.scene.variant in ("open", "wall")]
    base = _execution_jobs(mine, out, config, reperceive=False, replay_dir=None)
    replay_speed = speeds[len(speeds) // 2]
    jobs = sweep_jobs(base, speeds=speeds, scenario=scenario, scenes=scenes, paths=paths, replay_dir=out,
                      replay_speed=replay_speed)
    n_scenes = len({j.scene.key() for j in jobs})
    latency = {p: modelled_latency(scenario, p) for p in config.planners} if scenario.latency_mode == "modelled" \
        else None
    update_manifest(out, moving_bin={"speeds_m_s": list(speeds), "scenes": n_scenes, "paths_per_scene": paths,
                                     "latency_mode": scenario.latency_mode, "modelled_latency_s": latency,
                                     "scenario": scenario.to_json()})
    print(f"moving bin: {len(jobs)} episode(s) ({n_scenes} scene(s) x {paths} bin path(s) x {len(speeds)} speed(s) "
          f"x {len(config.planners)} planner(s), latency {scenario.latency_mode})...", file=sys.stderr)
    write_moving_bin(out, run_jobs(jobs, workers=config.jobs, progress_bar=progress_bar, run=run_moving_bin_job,
                                   desc="moving bin"))


def _shared_steps(trials, steps, *, pose: dict) -> dict:
    """Cycle steps of the run's scenes stored in the dataset once, under another scene (identical
    content, e.g. the last return of a fixed station): (scene key, can id, kind) -> problem_id.
    Found by posing each scene's cycle again (goal IK, as the dataset was built: `pose`, the
    dataset's `pose_settings`). A posed step is matched to a planned problem by the current
    identity rule applied to both, so that last-bit noise of the posing (which differs between
    machines) does not hide a match, whatever rule the dataset's own ids were made with."""
    from scenes.grasp_rule import truth_grasp
    from suite.problems.cycle import build_problems
    from suite.problems.identity import problem_id

    scenes = {t.problem.scene.key(): t.problem.scene for t in trials}
    planned = {(t.problem.scene.key(), t.problem.can_id, t.problem.kind) for t in trials}
    stored_id = {problem_id(t.problem): t.meta["problem_id"] for t in trials if t.meta.get("problem_id")}
    shared = {}
    for key, scene in scenes.items():
        for p in build_problems(scene, [truth_grasp(scene, c) for c in scene.cans], time_limit_s=1.0, seed=scene.seed,
                                **pose):
            k = (key, p.can_id, p.kind)
            if p.pre_status is None and k not in planned and k not in steps:
                pid = stored_id.get(problem_id(p))
                if pid is not None:
                    shared[k] = pid
    return shared
