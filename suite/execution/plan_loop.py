"""Planning an execution's cans: all before execution (open loop), or each next can between
cycles from what the simulated cameras see (closed loop). A can that cannot be fully planned is
left on the plate and the run goes on (`skip`), or the run ends there (`stop`)."""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from planners.base import PROBLEM_KINDS, PlanningProblem
from scenes.scene import CanPose, Scene
from suite.execution.commands import WorldState, planned_ahead, timed_cycle
from suite.execution.execution_records import FINAL_RETURN_NOT_EXECUTED
from suite.execution.job_spec import ExecutionJob
from suite.execution.monitor import where


def plan_cans(problems: Sequence[PlanningProblem], job: ExecutionJob,
              induced: list | None = None, planning_s: list | None = None) -> list[tuple[int, tuple, str]]:
    """Plan every problem (five per can, in order): per can its paths and first failed status.
    A path free in the planner's perceived world that the judge rejects in the truth is appended to
    `induced` (can, problem kind, where, what it struck, cause); each planning time (s) to `planning_s`."""
    from suite.run.trial import run_problem

    out = []
    for i in range(0, len(problems), len(PROBLEM_KINDS)):
        chunk = problems[i:i + len(PROBLEM_KINDS)]
        paths, failed = [], ""
        for problem in chunk:
            rec = run_problem(problem, planner=job.planner, planner_config=job.planner_config, run_seed=job.seed)
            ok = rec.succeeded
            paths.append(rec.path if ok else None)
            found = rec.stats.get("perception_induced")
            if planning_s is not None and rec.planning_time_s is not None:
                planning_s.append(float(rec.planning_time_s))
            if found is not None and induced is not None:
                induced.append({"can": problem.can_id, "kind": problem.kind, **found})
            if not ok and not failed:
                failed = f"{problem.kind} {rec.status}" + (f" (perception-induced: {found['cause']})" if found else "")
        out.append((chunk[0].can_id, tuple(paths), failed))
    return out


def plan_open_loop(scene: Scene, grasps, seen, job: ExecutionJob, induced: list, planning_s: list
                   ) -> tuple[list[tuple[int, tuple, str]], np.ndarray]:
    """Every grasp's cycle planned before execution, in order (`plan_cans`), and where the first
    starts. A can not fully planned stays on the plate: with `skip`, the cans after it are posed and
    planned again from above the plate with it there (the cans recycled before it gone); with
    `stop`, nothing after it."""
    from suite.problems.cycle import build_problems

    out: list[tuple[int, tuple, str]] = []
    todo, removed, seen_removed, q_home = list(grasps), (), (), None
    while todo:
        problems = build_problems(scene, todo, time_limit_s=job.time_limit_s, seed=job.seed, world=seen,
                                  removed=removed, seen_removed=seen_removed)
        q_home = problems[0].q_start if q_home is None else q_home
        k = len(PROBLEM_KINDS)
        for n in range(len(problems) // k):  # can by can: nothing after a failure is planned (and counted) twice
            (can_id, paths, failed), = plan_cans(problems[n * k:(n + 1) * k], job, induced, planning_s)
            out.append((can_id, paths, failed))
            last = len(out) == len(grasps)
            if (failed or any(p is None for p in paths)) and not (last and _only_return_missing(paths)):
                todo = todo[n + 1:] if job.on_failure == "skip" else []
                break
            transit = problems[n * k + PROBLEM_KINDS.index("transit")]
            removed = transit.removed_can_ids
            seen_removed = () if transit.plan_world is None else transit.plan_world.removed_can_ids
        else:
            todo = []
    return out, q_home


def _only_return_missing(paths) -> bool:
    return paths[-1] is None and all(p is not None for p in paths[:-1])


def open_loop(cans: Sequence[tuple[int, tuple, str]], *, skip: bool = False):
    """Cycles in order. A can not fully planned ends the run (later plans assumed it gone), or with
    `skip` (its later cans planned around it: `plan_open_loop`) is left on the plate."""
    cycles, stopped, skipped = [], "", []
    for i, (can_id, paths, failed) in enumerate(cans):
        if i == len(cans) - 1 and _only_return_missing(paths):
            # the last can's return (after the drop) is missing: its can still goes in the bin; the
            # arm stays over the bin, and the record says the return was not executed
            paths = paths[:-1]
            stopped = f"can {can_id}: {FINAL_RETURN_NOT_EXECUTED} ({failed or 'not planned'})"
        elif failed or any(p is None for p in paths):
            if skip:
                skipped.append(f"can {can_id}: {failed or 'not planned'}")
                continue
            stopped = f"can {can_id}: {failed or 'not planned'}"
            break
        cycle = timed_cycle(can_id, paths)
        if cycle is None:
            if skip:
                skipped.append(f"can {can_id}: timing failed")
                continue
            stopped = f"can {can_id}: timing failed"
            break
        cycles.append(cycle)
    if skipped:
        stopped = "; ".join([f"skipped {s}" for s in skipped] + ([stopped] if stopped else []))
    return planned_ahead(cycles, stopped)


def _ended(skipped: list[str], reason: str) -> str:
    """Why a run ended, with the cans it skipped."""
    return "; ".join([f"skipped {s}" for s in skipped] + ([reason] if reason else []))


def can_pose_from(can_id: int, X_WC: np.ndarray) -> CanPose:
    """The scene model of a can from its simulated pose (upright or lying, whichever is nearer)."""
    axis = X_WC[:3, 2]
    lying = bool(abs(axis[2]) < math.cos(math.pi / 4))
    yaw = float(math.atan2(axis[1], axis[0]) if lying else math.atan2(X_WC[1, 0], X_WC[0, 0]))
    return CanPose(can_id, tuple(float(v) for v in X_WC[:3, 3]), lying, yaw)


def closed_loop(job: ExecutionJob, induced: list, worlds: list, planning_s: list):
    """Between cycles: look again, rebuild the scene from where the cans now are, plan the next
    can, and hand its cycle to the simulation. In a perceived world, the world is rebuilt from
    every camera's fresh frame (the arm, at its pose when they were taken, left out). With perceived
    grasps the truth of where the cans are builds the judge's scene only; the loop ends when the
    cameras see no can where none was tried. Perception-induced failures go to `induced`, each
    world's summary to `worlds`."""
    from perception.pipeline import (
        GRASP_CAMERA,
        PerceptionSetup,
        detect_cans,
        detect_in_frames,
        noise_rng,
    )
    from perception.side_view import SIDE_CAMERAS
    from scenes.grasp_rule import truth_grasp
    from scenes.render import render
    from suite.problems.cycle import build_problems
    from suite.run.runner import plan_world_for

    spec = job.scene.spec
    tried: set[int] = set()
    perceived_world = plan_world_for(job.grasps, job.world) == "perceived"

    skipped: list[str] = []  # cans left on the plate after a failure (`on_failure="skip"`)
    tried_xy: list[np.ndarray] = []  # where grasps were tried (perceived: a detection there is not tried again)

    def provide(world: WorldState):
        # The truth of where the cans are builds the judge's scene; with perceived grasps nothing else
        # reads it: what is left to try, and when to stop, are what the cameras see.
        on_plate = [can_pose_from(i, X) for i, X in sorted(world.X_WCans.items()) if where(spec, X[:3, 3]) == "plate"]
        cans = [c for c in on_plate if c.id not in tried]
        if job.grasps == "truth" and not cans:
            return None, _ended(skipped, "")
        now = Scene(spec, job.scene.seed, tuple(on_plate))  # a can tried and left there is in the way
        seen = None
        if job.grasps == "truth":
            grasps = [truth_grasp(now, c) for c in cans]
        elif perceived_world:
            from perception.world import perceive_world

            rng = noise_rng(job.scene.seed, *([len(tried)] if tried else []))
            detections, seen = perceive_world(now if world.images is None else job.scene,
                                              setup=job.perception or PerceptionSetup(), rng=rng,
                                              images=world.images, q_robot=world.q_images)
            worlds.append(seen.summary())
            grasps = [d.grasp for d in detections]
        else:
            # Before the first pick the arm has not yet moved into view (as in open loop); later
            # frames were taken from the simulation just after the last release over the bin.
            setup = job.perception
            robust = setup is not None and setup.pipeline == "robust"
            cams = [GRASP_CAMERA] + ([c for c in SIDE_CAMERAS if c in spec.cameras.poses] if robust else [])
            images = world.images if world.images is not None else render(job.scene, cameras=cams)
            if setup is None:
                detections, _ = detect_cans(images[GRASP_CAMERA], spec)
            else:  # a fresh noise draw per frame; the first frame's is `perceive`'s
                rng = noise_rng(job.scene.seed, *([len(tried)] if tried else []))
                detections = detect_in_frames(images, spec, setup=setup, rng=rng)
            grasps = [d.grasp for d in detections]
        # a grasp where one was already tried is not tried again (the robot knows where it reached)
        r = spec.can.radius_m
        grasps = [g for g in grasps if all(np.hypot(*(g.X_WG[:2, 3] - p)) > r for p in tried_xy)]
        if not grasps:
            return None, _ended(skipped, "")  # as far as the robot knows, the plate is cleared
        for grasp in grasps:
            problems = build_problems(now, [grasp], time_limit_s=job.time_limit_s, seed=job.seed,
                                      q_home=world.q_command, world=seen)
            (can_id, paths, failed), = plan_cans(problems, job, induced, planning_s)
            tried.add(can_id)
            tried_xy.append(grasp.X_WG[:2, 3].copy())
            cycle = None if failed else timed_cycle(can_id, paths)
            if cycle is not None:
                return cycle, ""
            reason = f"can {can_id}: {failed or 'timing failed'}"
            if job.on_failure == "stop":
                return None, reason
            skipped.append(reason)
        return None, _ended(skipped, "")

    return provide
