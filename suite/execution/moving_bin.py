"""A moving bin in physics: running the replanning loop's episodes, one job each.

The loop is `suite.execution.moving_bin_episode` (its docstring says what it does); the job and the
record are `suite.execution.moving_bin_records`. Here: running one job (`run_moving_bin`, and
`run_moving_bin_job` for a worker: an exception is that episode's error record, with the state
the simulation was in), a job planned on the spot (`plan_scene_job`), and a comparison's sweep
(`sweep_jobs`): per selected scene, bin path and speed, one job per planner; every planner meets
the same bin paths (`episode_seed`), so their episodes are paired.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from typing import Any

from scenes.grasp_rule import truth_grasp
from scenes.moving_bin import MovingBinScenario
from scenes.moving_bin_check import check_scenario
from scenes.scene import Scene
from suite.execution.config import ExecutionConfig
from suite.execution.moving_bin_records import (
    NOT_APPLICABLE,
    MovingBinJob,
    MovingBinRecord,
    episode_seed,
)

log = logging.getLogger(__name__)


def run_moving_bin(job: MovingBinJob, *, planner=None) -> MovingBinRecord:
    """Run one episode (`planner`: an instance to use instead of the job's, e.g. a test's)."""
    from suite.execution.moving_bin_episode import Episode

    if job.planner in NOT_APPLICABLE and planner is None:
        return job.record("not_applicable", NOT_APPLICABLE[job.planner])
    check_scenario(job.scenario, job.scene.spec, reach=False)
    if len(job.q_home) != 7:
        return job.record("error", "no plan of this scene to execute")
    if planner is None:
        from planners.registry import planner_class
        from suite.run.trial import make_config

        cls = planner_class(job.planner)
        planner = cls(make_config(cls, job.planner_config))
    meshcat = None
    if job.replay_path:
        from suite.execution.jobs import meshcat_for

        meshcat = meshcat_for(job.scene)
    episode = Episode(job, planner, meshcat=meshcat)
    if meshcat is not None:
        meshcat.StartRecording(frames_per_second=job.config.publish_hz)
    record = episode.run()
    if meshcat is not None:
        from pathlib import Path

        meshcat.StopRecording()
        meshcat.PublishRecording()
        Path(job.replay_path).write_text(meshcat.StaticHtml(), encoding="utf-8")
        record = dataclasses.replace(record, replay=Path(job.replay_path).name)
    return record


def run_moving_bin_job(job: MovingBinJob) -> MovingBinRecord:
    """`run_moving_bin`'s record; an exception is that episode's error record."""
    try:
        return run_moving_bin(job)
    except Exception as exc:  # one failed episode is its record's error, not the whole run's
        log.debug("moving bin episode of %s on seed %d failed", job.planner, job.scene.seed, exc_info=True)
        return job.record("error", f"{type(exc).__name__}: {exc}",
                          error_state=getattr(exc, "moving_bin_state", None))


def plan_scene_job(scene: Scene, scenario: MovingBinScenario, *, planner: str, planner_config: dict[str, Any],
                   time_limit_s: float, seed: int, replay_path: str | None = None,
                   config: ExecutionConfig = ExecutionConfig()) -> MovingBinJob:  # noqa: B008 (frozen)
    """A job whose approach, descend and lift are planned here, as a trial plans them (ground-truth
    grasps; `python -m suite execute --moving-bin`, tests)."""
    from planners.base import PROBLEM_KINDS
    from suite.problems.cycle import build_problems
    from suite.run.trial import run_problem

    problems = build_problems(scene, [truth_grasp(scene, c) for c in scene.cans], time_limit_s=time_limit_s, seed=seed)
    cans = []
    for i in range(0, len(problems), len(PROBLEM_KINDS)):
        chunk = problems[i:i + len(PROBLEM_KINDS)]
        paths, failed = [], ""
        for problem in chunk[:3]:  # approach, descend, lift; the transit and return are planned online
            rec = run_problem(problem, planner=planner, planner_config=planner_config, run_seed=seed)
            ok = rec.succeeded
            paths.append(rec.path if ok else None)
            failed = failed or ("" if ok else f"{problem.kind} {rec.status}")
        cans.append((chunk[0].can_id, (*paths, None, None), failed))
    scenario = dataclasses.replace(scenario, seed=episode_seed(seed, scene.seed, 0, scenario.seed))
    return MovingBinJob(planner=planner, planner_config=planner_config, scene=scene, scenario=scenario,
                        cans=tuple(cans), q_home=tuple(float(v) for v in problems[0].q_start),
                        time_limit_s=time_limit_s, seed=seed, replay_path=replay_path, config=config)


def select_scenes(jobs: Sequence[Any], count: int) -> list[str]:
    """The keys of up to `count` open or wall scenes among execution jobs: the first of each
    family in turn (an open and a wall station before a second open), in the jobs' order."""
    by_family: dict[str, list[str]] = {}
    for job in jobs:
        key = job.scene.key()
        if job.scene.variant in ("open", "wall") and key not in by_family.setdefault(job.scene.variant, []):
            by_family[job.scene.variant].append(key)
    out: list[str] = []
    while len(out) < count and any(by_family.values()):
        for family in ("open", "wall"):
            if by_family.get(family) and len(out) < count:
                out.append(by_family[family].pop(0))
    return out


def sweep_jobs(exec_jobs: Sequence[Any], *, speeds: Sequence[float], scenario: MovingBinScenario, scenes: int,
               paths: int = 1, replay_dir=None, replay_speed: float | None = None) -> list[MovingBinJob]:
    """One moving-bin job per planner, selected scene, bin path and speed, from a comparison's
    execution jobs (`suite.execution.jobs.jobs_from_records`: their approach, descend and lift
    paths). Path k of a scene has the bin seed `episode_seed(run seed, scene seed, k, scenario seed)`, the same
    for every planner and speed. Each planner's episode on the first scene's first path at
    `replay_speed` records a Meshcat replay into `replay_dir` (replay_moving_bin_<planner>.html)."""
    from pathlib import Path

    keys = select_scenes(exec_jobs, scenes)
    out, replayed = [], set()
    for key in keys:
        for job in (j for j in exec_jobs if j.scene.key() == key):
            for k in range(paths):
                seed = episode_seed(job.seed, job.scene.seed, k, scenario.seed)
                for speed in speeds:
                    replay = None
                    if replay_dir is not None and speed == replay_speed and job.planner not in replayed:
                        replayed.add(job.planner)
                        replay = str(Path(replay_dir) / f"replay_moving_bin_{job.planner}.html")
                    out.append(MovingBinJob(
                        planner=job.planner, planner_config=job.planner_config, scene=job.scene,
                        scenario=dataclasses.replace(scenario, speed_m_s=float(speed), seed=seed), cans=job.cans or (),
                        q_home=job.q_home or (), time_limit_s=job.time_limit_s, seed=job.seed, replay_path=replay,
                        config=job.config, path_index=k))
    return out
