"""The seed paper's planner (Section IV): IK along a nominal end-effector trajectory.

The nominal gripper trajectory runs through the problem's task waypoints on the paper's schedule
(`TaskWaypoint.t`, time units): translation interpolated linearly, rotation by slerp (Drake's
`PiecewisePose.MakeLinear`). Every `knot_dt_tu` time units a knot is solved with Drake's
InverseKinematics and SNOPT:

    min ||q - q_prev||^2
    s.t. gripper position within a box around the nominal one, gripper orientation within an
         angle of the nominal one (both tight near the cans, loose in transit, as in the paper),
         |q - q_prev| <= v_max * dt  (joint velocity limits; dt = knot spacing in seconds),
         minimum distance to the scene (and self) >= min_distance_m (a small bound near the
         cans, where the goals themselves are that close, a larger margin in transit),
         joint limits.

Drake's distance constraint holds at the knots only; the straight joint-space step between two
knots is checked with the python-fcl world (the validator's engine) at `segment_check_rad`, and a
step that collides, or a knot that fails, is split in two at the middle time (up to
`max_refinements` levels), so the path is refined where the nominal trajectory passes close to
something. Before that, a knot SNOPT fails from q_prev (it stalls now and then: iteration limit,
"current point cannot be improved") is retried from other initial guesses in the same joint-step
box: the previous step continued, then `knot_retries` uniform draws from a generator seeded by
the problem (seed, kind, can), so a problem's path depends on the problem alone. Retries and
refinements stop at the problem's `time_limit_s` (status TIMEOUT).

The first knot is q_start. At the last knot the cost pulls towards the shared q_goal instead of
q_prev (the goal pose is the same; this picks q_goal's arm posture among the redundant ones),
and the path ends at q_goal if that solution lies within `goal_tolerance_rad` of it.

One InverseKinematics program is built per collision world and reused for every knot of every
problem in that world: only the position bounds, the step bounds, the cost and the orientation
constraint (which Drake cannot re-target, so it is swapped) change per knot.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from typing import ClassVar

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.inverse_kinematics import (
    InverseKinematics,
    MinimumDistanceLowerBoundConstraint,
    OrientationConstraint,
)
from pydrake.solvers import SnoptSolver, SolverOptions
from pydrake.trajectories import PiecewisePose

from planners.drake_queries import EvaluationCounter, query_stats
from planners.base import ALL_KINDS, Budget, FailureReason, PlannerBase, PlanningProblem, PlanResult, PlanStatus
from scenes.errors import SuiteError
from planners.worlds import drake_plan_scene, remember

log = logging.getLogger(__name__)

#: Kinds whose whole motion is close to the can (pre-grasp -> grasp).
_NEAR_KINDS = ("descend",)
_OUT_OF_TIME = "time limit reached"


@dataclasses.dataclass(frozen=True)
class NominalIkConfig:
    """Settings of the nominal-trajectory IK planner.

    Attributes:
        knot_dt_tu: spacing of IK knots along the schedule (time units).
        seconds_per_time_unit: the schedule's time unit in seconds (the joint-step bound is
            v_max * knot_dt_tu * seconds_per_time_unit).
        position_tolerance_near_m: half-width of the gripper position box near the cans.
        orientation_tolerance_near_rad: gripper orientation tolerance near the cans.
        position_tolerance_transit_m: half-width of the position box in transit.
        orientation_tolerance_transit_rad: orientation tolerance in transit.
        near_window_tu: how long after leaving / before reaching a can the tight tolerances hold
            (the end of `approach`, the start of `lift`; all of `descend`), time units.
        min_distance_near_m: minimum signed distance between robot and scene (and self) near
            the cans and at the last knot (the shared goals were solved with 1 mm), metres.
        min_distance_transit_m: the same in transit, metres.
        influence_distance_m: distance below which pairs enter the distance constraint.
        goal_tolerance_rad: the last knot's largest joint deviation from q_goal that may be
            closed by a straight joint-space step.
        major_iterations: SNOPT major iteration limit per knot.
        segment_check_rad: joint resolution of the python-fcl check of each step between knots.
        max_refinements: how many times a failing step may be halved.
        knot_retries: how many other initial guesses a knot that SNOPT fails from q_prev gets
            (the previous step continued, then uniform draws in the joint-step box).
    """

    knot_dt_tu: float = 0.5
    seconds_per_time_unit: float = 1.0
    position_tolerance_near_m: float = 0.005
    orientation_tolerance_near_rad: float = 0.05
    position_tolerance_transit_m: float = 0.05
    orientation_tolerance_transit_rad: float = 0.3
    near_window_tu: float = 1.0
    min_distance_near_m: float = 0.001
    min_distance_transit_m: float = 0.003
    influence_distance_m: float = 0.05
    goal_tolerance_rad: float = 0.05
    major_iterations: int = 100
    segment_check_rad: float = 0.01
    max_refinements: int = 3
    knot_retries: int = 4

    def __post_init__(self):
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if f.name in ("max_refinements", "knot_retries"):
                if not (isinstance(v, int) and v >= 0):
                    raise SuiteError(f"ik config {f.name}={v!r} must be a non-negative integer")
            elif not (np.isfinite(v) and v > 0):
                raise SuiteError(f"ik config {f.name}={v!r} must be a positive number")


class _KnotProgram:
    """One InverseKinematics program on a plan-mode Drake scene, re-targeted per knot."""

    def __init__(self, drake_scene, config: NominalIkConfig) -> None:
        self.plant = plant = drake_scene.plant
        self.context = drake_scene.diagram.CreateDefaultContext()
        self.plant_context = plant.GetMyMutableContextFromRoot(self.context)
        self.G = plant.GetFrameByName("body", drake_scene.wsg)
        self.W = plant.world_frame()
        self.ik = ik = InverseKinematics(plant, self.plant_context)
        self.q = ik.q()
        self.prog = prog = ik.get_mutable_prog()
        self.position = ik.AddPositionConstraint(self.G, np.zeros(3), self.W, np.zeros(3), np.zeros(3))
        self.orientation = None
        self.step = prog.AddBoundingBoxConstraint(plant.GetPositionLowerLimits(),
                                                  plant.GetPositionUpperLimits(), self.q)
        self.distance = {}
        for near, bound in ((True, config.min_distance_near_m), (False, config.min_distance_transit_m)):
            influence = max(config.influence_distance_m, bound + 0.01)
            self.distance[near] = MinimumDistanceLowerBoundConstraint(plant, bound, self.plant_context,
                                                                      None, influence)
        self.distance_binding = None
        self.distance_near = None
        self.cost = prog.AddQuadraticErrorCost(np.eye(7), np.zeros(7), self.q)
        self.evaluations = EvaluationCounter()  # one distance query per evaluation (drake_queries)
        prog.AddVisualizationCallback(self.evaluations, self.q)
        self.solver = SnoptSolver()
        self.options = SolverOptions()
        self.options.SetOption(SnoptSolver.id(), "Major iterations limit", config.major_iterations)

    def solve(self, *, X_WG: RigidTransform, pos_tol_m: float, rot_tol_rad: float, near: bool,
              q_lo: np.ndarray, q_hi: np.ndarray, q_desired: np.ndarray, q_guess: np.ndarray):
        """Solve one knot. Returns (success, q, solver_status, cost)."""
        if self.distance_near is not near:
            if self.distance_binding is not None:
                self.prog.RemoveConstraint(self.distance_binding)
            self.distance_binding = self.prog.AddConstraint(self.distance[near], self.q)
            self.distance_near = near
        p = X_WG.translation()
        self.position.evaluator().set_bounds(p - pos_tol_m, p + pos_tol_m)
        if self.orientation is not None:
            self.prog.RemoveConstraint(self.orientation)
        self.orientation = self.prog.AddConstraint(
            OrientationConstraint(self.plant, self.W, X_WG.rotation(), self.G, RotationMatrix(),
                                  rot_tol_rad, self.plant_context),
            self.q,
        )
        self.step.evaluator().set_bounds(q_lo, q_hi)
        # ||q - q_d||^2 = q'q - 2 q_d'q + q_d'q_d, as 0.5 q'Qq + b'q + c.
        self.cost.evaluator().UpdateCoefficients(2 * np.eye(7), -2 * q_desired, float(q_desired @ q_desired))
        self.prog.SetInitialGuess(self.q, np.clip(q_guess, q_lo, q_hi))
        result = self.solver.Solve(self.prog, None, self.options)
        status = result.get_solution_result().name
        return result.is_success(), result.GetSolution(self.q), status, float(result.get_optimal_cost())


def knot_times(waypoint_times: np.ndarray, dt_tu: float) -> np.ndarray:
    """Knots every dt_tu from the first to the last waypoint time, every waypoint time included."""
    t0, t1 = float(waypoint_times[0]), float(waypoint_times[-1])
    n = max(1, int(round((t1 - t0) / dt_tu)))
    grid = np.linspace(t0, t1, n + 1)
    return np.unique(np.round(np.concatenate([grid, waypoint_times]), 9))


def _problem_seed(problem: PlanningProblem) -> list[int]:
    """The seed of a problem's retry draws: its `seed` and identity (kind, can or free transit's task)."""
    number = problem.can_id if problem.task_index is None else problem.task_index
    return [int(problem.seed) & 0xFFFFFFFF, ALL_KINDS.index(problem.kind), int(number) & 0xFFFFFFFF]


class NominalIkPlanner(PlannerBase):
    """The paper's method: IK knot by knot along the nominal gripper trajectory."""

    name: ClassVar[str] = "ik"
    Config: ClassVar[type] = NominalIkConfig
    search_space: ClassVar[dict[str, tuple]] = {
        "knot_dt_tu": (0.5, 0.25), "position_tolerance_transit_m": (0.05, 0.1),
        "orientation_tolerance_transit_rad": (0.3, 0.6)}

    def __init__(self, config: NominalIkConfig | None = None) -> None:
        super().__init__(config)
        self._programs: dict[tuple, _KnotProgram] = {}

    def _program(self, problem: PlanningProblem) -> _KnotProgram:
        key = problem.world_key()
        prog = self._programs.get(key)
        if prog is None:
            prog = remember(self._programs, key, _KnotProgram(drake_plan_scene(problem), self.config), max_items=16)
        return prog

    def prepare(self, problem: PlanningProblem) -> None:
        """Build the knot IK program of the problem's world (the orchestrator calls this before it
        starts the clock: it depends on the world only, as the sampling planners' collision world)."""
        self._program(problem)

    def _is_near(self, kind: str, t: float, t0: float, t1: float) -> bool:
        w = self.config.near_window_tu
        return (kind in _NEAR_KINDS or (kind == "approach" and t >= t1 - w - 1e-9)
                or (kind == "lift" and t <= t0 + w + 1e-9))

    def solve(self, problem: PlanningProblem, world, budget: Budget) -> PlanResult:
        """`_plan`, with its Drake distance queries counted and timed (`planners.drake_queries`)."""
        program = self._program(problem)
        calls0 = program.evaluations.calls
        program.evaluations.restart()
        result = self._plan(problem, world, budget)
        queries = program.evaluations.calls - calls0  # the iterates are q itself, one binding
        result.stats.update(query_stats(queries, program.distance[False], program.evaluations.sample))
        return result

    def _plan(self, problem: PlanningProblem, world, budget: Budget) -> PlanResult:
        cfg = self.config
        t_start = time.perf_counter()
        wp_t = np.array([w.t for w in problem.waypoints], float)
        if len(wp_t) < 2 or np.any(np.diff(wp_t) <= 0):
            return PlanResult(PlanStatus.ERROR, None, {"reason": "waypoints need >= 2 increasing times",
                                                       "reason_code": FailureReason.PLANNER_ERROR.value})
        nominal = PiecewisePose.MakeLinear(list(wp_t), [RigidTransform(w.X_WG) for w in problem.waypoints])
        times = knot_times(wp_t, cfg.knot_dt_tu)
        prog = self._program(problem)
        lower = prog.plant.GetPositionLowerLimits()
        upper = prog.plant.GetPositionUpperLimits()
        v_max = prog.plant.GetVelocityUpperLimits()
        q_goal = np.asarray(problem.q_goal, float)
        t_end = float(times[-1])
        counts = {"ik_solves": 0, "retries": 0, "refinements": 0, "cost": 0.0}
        stats: dict = {"solver": "SNOPT", "knot_dt_tu": cfg.knot_dt_tu}
        rng = np.random.default_rng(_problem_seed(problem))

        def solve_knot(before: tuple | None, t_a: float, q_a: np.ndarray,
                       t_b: float) -> tuple[bool, np.ndarray | None, str]:
            """Knot t_b from knot (t_a, q_a); `before` is the knot (t, q) before that, if any."""
            last = abs(t_b - t_end) < 1e-9
            near = last or self._is_near(problem.kind, t_b, wp_t[0], wp_t[-1])
            step = v_max * (t_b - t_a) * cfg.seconds_per_time_unit
            q_lo, q_hi = np.maximum(lower, q_a - step), np.minimum(upper, q_a + step)
            knot = dict(
                X_WG=RigidTransform(nominal.GetPose(t_b).GetAsMatrix4()),
                pos_tol_m=cfg.position_tolerance_near_m if near else cfg.position_tolerance_transit_m,
                rot_tol_rad=cfg.orientation_tolerance_near_rad if near else cfg.orientation_tolerance_transit_rad,
                near=near, q_lo=q_lo, q_hi=q_hi, q_desired=q_goal if last else q_a,
            )
            # SNOPT sometimes stalls from q_prev (iteration limit, "cannot be improved") where
            # another start in the same step box converges: continue the previous step, then draw.
            guesses = [q_goal if last else q_a]
            if before is not None:
                guesses.append(q_a + (q_a - before[1]) * (t_b - t_a) / (t_a - before[0]))
            ok, q, status = False, None, ""
            for i in range(1 + cfg.knot_retries):
                if i > 0 and budget.expired():
                    break
                guess = guesses[i] if i < len(guesses) else q_lo + rng.random(7) * (q_hi - q_lo)
                ok, q, status, cost = prog.solve(q_guess=guess, **knot)
                counts["ik_solves"] += 1
                if ok:
                    counts["retries"] += i
                    counts["cost"] += cost
                    break
            return ok, q if ok else None, status

        def segment(knots: list, t_b: float, depth: int) -> list | str:
            """Knots (t, q) after the last of `knots` up to t_b, or the reason of a failure."""
            (t_a, q_a), before = knots[-1], (knots[-2] if len(knots) > 1 else None)
            ok, q_b, status = solve_knot(before, t_a, q_a, t_b)
            stats["solver_status"] = status
            if ok and world.motion_free(q_a, q_b, resolution_rad=cfg.segment_check_rad):
                return [(t_b, q_b)]
            if budget.expired():
                return _OUT_OF_TIME
            if depth >= cfg.max_refinements:
                return f"IK failed ({status})" if not ok else "step between knots collides"
            counts["refinements"] += 1
            t_m = 0.5 * (t_a + t_b)
            left = segment(knots, t_m, depth + 1)
            if isinstance(left, str):
                return left
            right = segment(knots + left, t_b, depth + 1)
            return right if isinstance(right, str) else left + right

        knots = [(float(times[0]), np.asarray(problem.q_start, float))]
        for i in range(1, len(times)):
            out = segment(knots, float(times[i]), 0)
            if isinstance(out, str):
                stats.update(counts, knots=len(knots), failed_knot=i, failed_t=float(times[i]),
                             solve_time_s=time.perf_counter() - t_start,
                             reason=f"knot {i} (t={times[i]:g}): {out}",
                             reason_code=(FailureReason.BUDGET_SPENT if out == _OUT_OF_TIME
                                          else FailureReason.NO_IK_AT_KNOT).value)
                status = PlanStatus.TIMEOUT if out == _OUT_OF_TIME else PlanStatus.NO_SOLUTION
                return PlanResult(status, None, stats)
            knots += out
        path = [q for _, q in knots]
        goal_dev = float(np.max(np.abs(path[-1] - q_goal)))
        stats.update(counts, knots=len(knots), goal_deviation_rad=goal_dev,
                     solve_time_s=time.perf_counter() - t_start)
        if goal_dev > cfg.goal_tolerance_rad:
            stats.update(failed_knot=len(times) - 1, failed_t=t_end,
                         reason=f"last knot {goal_dev:.3f} rad from q_goal",
                         reason_code=FailureReason.GOAL_NOT_REACHED.value)
            return PlanResult(PlanStatus.NO_SOLUTION, None, stats)
        if goal_dev < 1e-4:
            path[-1] = q_goal  # the last knot is q_goal up to solver tolerance
        elif world.motion_free(path[-1], q_goal, resolution_rad=cfg.segment_check_rad):
            path.append(q_goal)
        else:
            stats.update(reason="step from the last knot to q_goal collides",
                         reason_code=FailureReason.GOAL_NOT_REACHED.value)
            return PlanResult(PlanStatus.NO_SOLUTION, None, stats)
        return PlanResult(PlanStatus.SUCCESS, np.array(path), stats)
