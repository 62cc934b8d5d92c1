"""One online plan of the moving-bin loop, the same for every planner: blend, goal IK, plan, validate, time.

`plan_online` starts from the arm's commanded state at the splice time (q_s, v_s, a_s) and returns
the motion to splice in there, or why there is none:

1. the world of the moment: the station with the bin (and the person beside it) where it is
   predicted to be (`scenes.moving_bin.spec_with_bin_at`);
2. the stopping blend from (q_s, v_s, a_s) to rest at q_b (`suite.execution.splice`; nothing
   when the arm is at rest);
3. the goal: Drake's collision-aware IK of the drop pose over the predicted bin (as the dataset's
   goals are posed: `scenes.ik.PoseIk`, near seeds around the previous goal first), or a given
   configuration (the return's);
4. the planner from q_b to the goal, with the budget left (a warm start: the path being executed);
5. the suite's independent validator on blend + path (the blend's dense samples as a polyline,
   then the path) in the python-fcl world of the moment;
6. TOPP-RA timing of the path from rest.

Its wall time is the latency; every step counts in it (the worlds change with the bin, so building
them is part of replanning). No step falls back to anything: a failure is the outcome, with its
reason.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import numpy as np

from planners.base import PlanningProblem, PlanStatus, TaskWaypoint
from scenes.moving_bin import MovingBinScenario, drop_pose, spec_with_bin_at
from scenes.scene import Scene
from suite.execution.splice import BlendTrajectory, stopping_blend

#: The paper's transit lasts 12 time units (`suite.problems.cycle.SCHEDULE`): the nominal
#: waypoints of a replanned motion get times in proportion to their gripper distances at that rate.
TRANSIT_TU = 12.0


@dataclasses.dataclass(frozen=True, eq=False)
class OnlinePlan:
    """What one online plan gave.

    Attributes:
        ok: a validated, timed motion is ready (`blend` then `trajectory`).
        reason: why not ("" when ok): "budget spent before planning", "no stopping blend within
            the limits", "goal IK failed", "planner: STATUS (REASON)", "validator: REASON",
            "timing: REASON".
        latency_s: wall time of the whole of it.
        parts_s: wall time per step (world, blend, ik, plan, validate, timing).
        blend: the stopping blend (duration 0 from rest).
        trajectory: the new motion from the blend's end, timed from rest.
        q_goal: its goal; bin_xy_m: the bin centre it was planned for.
        planner_status: the planner's status (or "" if it did not run).
    """

    ok: bool
    reason: str
    latency_s: float
    parts_s: dict[str, float]
    blend: BlendTrajectory | None = None
    trajectory: Any = None
    path: np.ndarray | None = None
    q_goal: np.ndarray | None = None
    bin_xy_m: np.ndarray | None = None
    planner_status: str = ""


def _waypoints(robot, q_b: np.ndarray, poses: list[np.ndarray], t0: float) -> tuple[TaskWaypoint, ...]:
    """Nominal waypoints from the gripper at q_b through `poses`, timed by gripper distance at the
    paper's transit rate (at least 1 time unit a leg)."""
    X0 = robot.gripper_pose(q_b[None, :])[0]
    all_poses = [X0, *poses]
    out, t = [TaskWaypoint(t0, X0)], t0
    for a, b in zip(all_poses[:-1], all_poses[1:]):
        t += max(1.0, TRANSIT_TU * float(np.linalg.norm(b[:3, 3] - a[:3, 3])) / 0.85)
        out.append(TaskWaypoint(t, b))
    return tuple(out)


def plan_online(
    *,
    planner,
    template: PlanningProblem,
    scenario: MovingBinScenario,
    bin_xy_m: np.ndarray,
    q_s: np.ndarray,
    v_s: np.ndarray,
    a_s: np.ndarray,
    budget_s: float,
    q_goal: np.ndarray | None = None,
    q_goal_seed: np.ndarray | None = None,
    via: list[np.ndarray] | None = None,
    warm_start: np.ndarray | None = None,
    rng: np.random.Generator,
) -> OnlinePlan:
    """Plan the motion to splice in at the commanded state (q_s, v_s, a_s) (module docstring).

    Args:
        planner: a planner instance (its caches persist between an episode's plans).
        template: the motion's problem as the cycle poses it (kind, scene, can, held can, opening,
            cans gone); its start, goal and waypoints are replaced here.
        bin_xy_m: where the bin is predicted to be when the motion ends.
        budget_s: the wall time it may take in all (the replan deadline, or the planning budget of
            a motion the arm waits for at rest).
        q_goal: a fixed goal (the return's); None for the drop pose's IK, seeded at q_goal_seed.
        via: nominal gripper poses between the start and the goal (the task's middle waypoint
            while the arm has not passed it).
        warm_start: the path being executed (trajopt starts from it).
        rng: the IK's restarts.
    """
    from planners.worlds import collision_world, drake_plan_scene
    from scenes.ik import IkOptions, PoseIk
    from scenes.robot_model import load_robot
    from suite.problems.cycle import GOAL_CLEARANCE_M
    from suite.scoring.timing import time_parameterize
    from suite.scoring.validate import validate_path

    t0 = time.perf_counter()
    parts: dict[str, float] = {}
    mark = [t0]

    def lap(name: str) -> None:
        now = time.perf_counter()
        parts[name] = now - mark[0]
        mark[0] = now

    def done(ok: bool, reason: str, **kw) -> OnlinePlan:
        return OnlinePlan(ok, reason, time.perf_counter() - t0, parts, **kw)

    robot = load_robot(template.scene.spec.robot)
    spec = template.scene.spec
    scene = Scene(spec_with_bin_at(scenario, spec, bin_xy_m), template.scene.seed, template.scene.cans)
    problem = template.with_(scene=scene)
    lap("world")
    blend = stopping_blend(q_s, v_s, a_s, v_lim=robot.velocity_limits_rad_s, a_lim=robot.acceleration_limits_rad_s2,
                           q_lo=robot.lower_rad, q_hi=robot.upper_rad)
    lap("blend")
    if blend is None:
        return done(False, "no stopping blend within the limits", bin_xy_m=bin_xy_m)
    q_b = blend.q[-1].copy()
    X_goal = template.X_WG_goal
    if q_goal is None:
        X_goal = drop_pose(spec, bin_xy_m)
        ik = PoseIk(drake_plan_scene(problem))
        q_goal = ik.solve(X_goal, q_seed=q_goal_seed if q_goal_seed is not None else q_b, rng=rng,
                          options=IkOptions(min_distance_m=GOAL_CLEARANCE_M, restarts=0,
                                            near_sigmas_rad=(0.05, 0.1, 0.25)))
        lap("ik")
        if q_goal is None:
            return done(False, "goal IK failed", blend=blend, bin_xy_m=bin_xy_m)
    left = budget_s - (time.perf_counter() - t0)
    if left <= 0:
        return done(False, "budget spent before planning", blend=blend, bin_xy_m=bin_xy_m)
    waypoints = _waypoints(robot, q_b, [*(via or []), X_goal], template.waypoints[0].t)
    problem = problem.with_(q_start=q_b, q_goal=np.asarray(q_goal, float), X_WG_goal=X_goal, waypoints=waypoints,
                            time_limit_s=left, warm_start=warm_start, pre_status=None)
    planner.prepare(problem)
    result = planner.plan(problem)
    lap("plan")
    status = PlanStatus(result.status).value
    if result.status != PlanStatus.SUCCESS or result.path is None:
        why = result.stats.get("reason") or result.stats.get("reason_code") or ""
        return done(False, f"planner: {status}" + (f" ({why})" if why else ""), blend=blend, bin_xy_m=bin_xy_m,
                    q_goal=q_goal, planner_status=status)
    path = np.asarray(result.path, float)
    polyline = np.vstack([blend.q[:-1], path]) if blend.duration_s > 0 else path
    world = collision_world(problem)
    reason = validate_path(problem.with_(q_start=np.asarray(q_s, float)), polyline, world)
    lap("validate")
    if reason is not None:
        return done(False, f"validator: {reason}", blend=blend, bin_xy_m=bin_xy_m, q_goal=q_goal,
                    planner_status=status)
    timed = time_parameterize(path, robot=robot)
    lap("timing")
    if not timed.ok:
        return done(False, f"timing: {timed.reason}", blend=blend, bin_xy_m=bin_xy_m, q_goal=q_goal,
                    planner_status=status)
    return done(True, "", blend=blend, trajectory=timed, path=path, q_goal=np.asarray(q_goal, float),
                bin_xy_m=np.asarray(bin_xy_m, float), planner_status=status)
