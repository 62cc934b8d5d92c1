"""One online plan of the moving-bin loop, the same for every planner: goal, plan, join, validate.

`plan_online` starts from the arm's commanded state at the splice time (q_s, v_s, a_s) and returns
the motion to splice in there, or why there is none (its `stage`):

1. the world of the moment: the station with the bin (and the person beside it) where it is
   predicted to be (`scenes.moving_bin.spec_with_bin_at`); a start in collision there ("start":
   the person or the bin walked into the arm) is the loop's failure, not the planner's;
2. the goal ("goal_ik"): Drake's collision-aware IK of the drop pose over the predicted bin, its
   yaw free (a can drops the same whichever way the gripper turns), seeded at the previous goal
   (`scenes.ik.PoseIk`), or a given configuration (a return's, a put-down's). The goal pose the
   planner is given is the gripper's pose at that solution (its yaw as solved): `ik`'s nominal
   waypoints end there, and must end within its goal tolerance of the configuration;
3. the planner ("planner") from q_s to the goal, with the budget left and a warm start: the path
   being executed;
4. the join ("join"): the path bent onto the arriving motion without stopping
   (`suite.execution.splice.join_path`, timed by TOPP-RA from a moving start);
5. the suite's independent validator ("validator") on the join's polyline (the blend's samples,
   then the path) in the python-fcl world of the moment;
6. the person over the motion's timing ("person"): a swept check against the person's predicted
   positions (the caller's `person_check`).

Its wall time is the latency; every step counts in it (the worlds change with the bin, so building
them is part of replanning). No step falls back to anything: a failure is the outcome, with its
stage and reason.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any, Callable

import numpy as np

from planners.base import PlanningProblem, PlanStatus, TaskWaypoint
from scenes.moving_bin import MovingBinScenario, drop_pose, region, spec_with_bin_at
from scenes.scene import Scene
from suite.execution.splice import BlendTrajectory, join_path

#: The online goal IK: the dataset goals' clearance, the yaw free, the previous goal and two seeds
#: near it (no random restarts: a goal on another IK branch would swing the arm), and SNOPT's
#: major iterations capped at 60 instead of the dataset's 150 (a failing seed otherwise spends
#: 0.1-0.4 s: the goal IK's p95 in the measured runs; docs/moving-bin.md counts its failures).
ONLINE_IK_ITERATIONS = 60

#: Wall time kept from the planner's budget for the steps after it (join, validation, swept check):
#: their p95 sum was 0.07 s in the first runs of this loop on a loaded 2-core machine; without it a
#: planner that used its whole budget missed every deadline.
POST_PLAN_RESERVE_S = 0.06

#: The stages of an online plan, in order (a failure names its stage).
STAGES = ("budget", "start", "goal_ik", "planner", "join", "validator", "person")

#: The paper's transit lasts 12 time units (`suite.problems.cycle.SCHEDULE`): the nominal
#: waypoints of a replanned motion get times in proportion to their gripper distances at that rate.
TRANSIT_TU = 12.0


@dataclasses.dataclass(frozen=True, eq=False)
class OnlinePlan:
    """What one online plan gave.

    Attributes:
        ok: a validated, timed motion is ready (`blend` then `trajectory`).
        reason: why not ("" when ok).
        latency_s: wall time of the whole of it.
        parts_s: wall time per step (world, ik, plan, join, validate, person).
        stage: where it failed (one of STAGES; "" when ok).
        blend: the join's quintic (duration 0 from rest).
        trajectory: the path's remainder from the blend's end, timed by TOPP-RA.
        at_rest: the join ends at rest (no moving join was within the limits).
        q_goal: its goal; bin_xy_m: the bin centre it was planned for.
        planner_status: the planner's status (or "" if it did not run).
    """

    ok: bool
    reason: str
    latency_s: float
    parts_s: dict[str, float]
    stage: str = ""
    blend: BlendTrajectory | None = None
    trajectory: Any = None
    path: np.ndarray | None = None
    at_rest: bool = False
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


def moment_scene(template: PlanningProblem, scenario: MovingBinScenario, bin_xy_m, *, person: bool = True) -> Scene:
    """The scene of the moment: the template's station with the bin centre at bin_xy_m, and the
    person beside it (or, with `person` False, without them)."""
    spec = template.scene.spec
    if person:
        spec = spec_with_bin_at(scenario, spec, bin_xy_m)
    else:
        spec = dataclasses.replace(spec, bin=dataclasses.replace(
            spec.bin, center_xy_m=(float(bin_xy_m[0]), float(bin_xy_m[1]))))
    return Scene(spec, template.scene.seed, template.scene.cans)


def start_free(template: PlanningProblem, scenario: MovingBinScenario, bin_xy_m, q: np.ndarray) -> bool:
    """Is q free in the world of the moment (the bin and the person where bin_xy_m puts them)?"""
    from planners.worlds import collision_world

    scene = moment_scene(template, scenario, bin_xy_m)
    return collision_world(template.with_(scene=scene)).is_free(np.asarray(q, float))


def loop_motion_reason(template: PlanningProblem, scenario: MovingBinScenario, bin_xy_m, polyline: np.ndarray, *,
                  leading_collisions: bool = True) -> str | None:
    """The validator's verdict on a motion the loop makes itself (an escape, a release's tracking;
    its dense polyline) in the world of the moment without the person (the station with the bin at
    bin_xy_m; the person is the swept check's and the monitor's). An escape starts where the person
    or the bin has come into the arm's margins and leads out, so with `leading_collisions` its
    first samples may collide: from its first free sample on it must be free, and it must reach
    one; without, every sample must be free."""
    from planners.worlds import collision_world
    from suite.scoring.validate import validate_path

    scene = moment_scene(template, scenario, bin_xy_m, person=False)
    polyline = np.asarray(polyline, float)
    problem = template.with_(scene=scene, q_start=polyline[0], q_goal=polyline[-1])
    world = collision_world(problem)
    if not leading_collisions:
        return validate_path(problem, polyline, world)
    free = world.states_free(polyline)
    if not free.any():
        return "no sample of the escape is free"
    first = int(np.argmax(free))
    rest = polyline[first:]
    return validate_path(problem.with_(q_start=rest[0]), rest, world)


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
    person_check: Callable[[list], str | None] | None = None,
    drop_offset_m: np.ndarray | None = None,
    rng: np.random.Generator,
) -> OnlinePlan:
    """Plan the motion to splice in at the commanded state (q_s, v_s, a_s) (module docstring).

    Args:
        planner: a planner instance (its caches persist between an episode's plans).
        template: the motion's problem as the cycle poses it (kind, scene, can, held can, opening,
            cans gone); its start, goal and waypoints are replaced here.
        bin_xy_m: where the bin is predicted to be when the motion ends.
        budget_s: the wall time the planner may take, with the steps before it (the replan
            deadline in measured mode; a generous cap when latency is modelled).
        q_goal: a fixed goal (a return's, a put-down's); None for the drop pose's IK, seeded at
            q_goal_seed.
        via: nominal gripper poses between the start and the goal (the task's middle waypoint
            while the arm has not passed it).
        warm_start: the path being executed (trajopt starts from it).
        person_check: given the motion's pieces [blend, trajectory] (timed from the splice), why
            it comes too close to the person, or None.
        drop_offset_m: where the drop pose is aimed relative to the predicted bin centre (xy; the
            release ramp's lag), zero by default.
        rng: the IK's restarts.
    """
    from planners.worlds import collision_world, drake_plan_scene
    from scenes.ik import IkOptions, PoseIk
    from scenes.robot_model import load_robot
    from suite.problems.cycle import GOAL_CLEARANCE_M
    from suite.scoring.validate import validate_path

    ONLINE_IK = IkOptions(min_distance_m=GOAL_CLEARANCE_M, restarts=0, free_yaw=True, near_sigmas_rad=(0.05, 0.2),
                          major_iterations=ONLINE_IK_ITERATIONS)

    t0 = time.perf_counter()
    parts: dict[str, float] = {}
    mark = [t0]

    def lap(name: str) -> None:
        now = time.perf_counter()
        parts[name] = now - mark[0]
        mark[0] = now

    def done(ok: bool, stage: str, reason: str, **kw) -> OnlinePlan:
        return OnlinePlan(ok, reason, time.perf_counter() - t0, parts, stage, bin_xy_m=bin_xy_m, **kw)

    robot = load_robot(template.scene.spec.robot)
    spec = template.scene.spec
    scene = moment_scene(template, scenario, bin_xy_m)
    problem = template.with_(scene=scene)
    q_s = np.asarray(q_s, float)
    world = collision_world(problem)
    lap("world")
    if not world.is_free(q_s):
        return done(False, "start", "the start is in collision in the world of the moment")
    X_goal = template.X_WG_goal
    if q_goal is None:
        # the aim stays over the bin's region: the bin never leaves it (and the arm's reach is
        # checked over it, `scenes.moving_bin_check.check_scenario`)
        lo, hi = region(scenario, spec)
        aim = np.asarray(bin_xy_m, float) + (0.0 if drop_offset_m is None else np.asarray(drop_offset_m, float))
        aim = np.clip(aim, lo, hi)
        X_goal = drop_pose(spec, aim)
        ik = PoseIk(drake_plan_scene(problem))
        q_goal = ik.solve(X_goal, q_seed=q_goal_seed if q_goal_seed is not None else q_s, rng=rng,
                          options=ONLINE_IK)
        lap("ik")
        if q_goal is None:
            return done(False, "goal_ik", f"goal IK failed (drop over {aim[0]:.3f}, {aim[1]:.3f} m)")
        X_goal = robot.gripper_pose(np.asarray(q_goal, float)[None, :])[0]  # the yaw as solved
    left = budget_s - (time.perf_counter() - t0) - POST_PLAN_RESERVE_S
    if left <= 0:
        return done(False, "budget", "budget spent before planning", q_goal=q_goal)
    waypoints = _waypoints(robot, q_s, [*(via or []), X_goal], template.waypoints[0].t)
    problem = problem.with_(q_start=q_s, q_goal=np.asarray(q_goal, float), X_WG_goal=X_goal, waypoints=waypoints,
                            time_limit_s=left, warm_start=warm_start, pre_status=None)
    planner.prepare(problem)
    result = planner.plan(problem)
    lap("plan")
    status = PlanStatus(result.status).value
    if result.status != PlanStatus.SUCCESS or result.path is None:
        why = result.stats.get("reason") or result.stats.get("reason_code") or ""
        return done(False, "planner", f"planner: {status}" + (f" ({why})" if why else ""), q_goal=q_goal,
                    planner_status=status)
    path = np.asarray(result.path, float)
    join = join_path(q_s, v_s, a_s, path, robot=robot)
    lap("join")
    if join is None:
        return done(False, "join", "no join of the path onto the motion within the limits", q_goal=q_goal,
                    planner_status=status)
    reason = validate_path(problem, join.polyline, world)
    lap("validate")
    if reason is not None:
        return done(False, "validator", f"validator: {reason}", q_goal=q_goal, planner_status=status)
    if person_check is not None:
        reason = person_check([join.blend, join.trajectory])
        lap("person")
        if reason is not None:
            return done(False, "person", f"person: {reason}", q_goal=q_goal, planner_status=status)
    return done(True, "", "", blend=join.blend, trajectory=join.trajectory, path=path, at_rest=join.at_rest,
                q_goal=np.asarray(q_goal, float), planner_status=status)
