"""Kinematic trajectory optimization (Drake's KinematicTrajectoryOptimization) with a dense re-check.

A B-spline path r(s), s in [0, 1], scaled to a duration T: start and goal positions, zero end
velocities, joint position bounds, joint velocity bounds (Drake's AddVelocityBounds bounds
q̇(t) = ṙ(s) / T itself, so the plant's limits go in as they are), duration and path-length
costs, and Drake's MinimumDistanceLowerBoundConstraint at sample points along s. Solved by SNOPT.

The distance constraint holds only at its samples, and SNOPT happily reports success on a path
that passes through the wall between two of them. So the result is sampled densely, the straight
segments between those samples are checked with the python-fcl world at `check_resolution_rad`
(what the validator does), and where they collide, constraint samples are added at the colliding
s values and the problem is re-solved from the previous solution, until the path is free or the
budget (`problem.time_limit_s`, `max_resolves`) runs out.

SNOPT cannot be interrupted from outside and Drake's build ignores its "Time limit" option, so a
solve started before the deadline used to run on past it (up to 3 s over a 5 s budget, 40 of 74
CPU-seconds on the quick tier's `window` problems at a 1 s budget). The program carries a callback,
evaluated with the costs and constraints, that raises once the deadline has passed: Drake then
aborts the solve, and the trial ends as a TIMEOUT at its budget (a path that late would not count).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from typing import ClassVar

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.inverse_kinematics import InverseKinematics, MinimumDistanceLowerBoundConstraint
from pydrake.planning import KinematicTrajectoryOptimization
from pydrake.solvers import SnoptSolver, SolverOptions
from pydrake.trajectories import BsplineTrajectory

from planners.base import Budget, FailureReason, PlannerBase, PlanningProblem, PlanResult, PlanStatus, warm_start_guess
from planners.drake_queries import EvaluationCounter, query_stats
from scenes.errors import SuiteError
from planners.worlds import drake_plan_scene, remember

log = logging.getLogger(__name__)

INITIAL_GUESSES = ("straight", "via_waypoints")


@dataclasses.dataclass(frozen=True)
class TrajoptConfig:
    """Settings of the kinematic trajectory optimization.

    Attributes:
        num_control_points: B-spline control points.
        spline_order: B-spline order (4 = cubic).
        num_collision_samples: initial distance-constraint samples, evenly spaced in s.
        min_distance_m: the distance constraint's lower bound (robot-scene and self), metres: a
            margin against the dips between samples (the arm's own capsules come within 4.5 mm
            of each other in ordinary postures, which caps it).
        influence_distance_m: pairs farther than this do not enter the constraint, metres.
        min_duration_s, max_duration_s: bounds on the duration T.
        duration_cost: weight of T in the cost.
        path_length_cost: weight of the path length (sum of control-point steps) in the cost.
        initial_guess: "straight" (joint-space line q_start -> q_goal) or "via_waypoints"
            (through an IK solution of the problem's middle task waypoint, when it has one).
        output_samples: points of the returned path, evenly spaced in s.
        check_resolution_rad: joint resolution of the dense python-fcl check.
        max_resolves: re-solves after the first solve.
        samples_per_hit: constraint samples added per colliding stretch of s.
        major_iterations: SNOPT major iteration limit per solve (roughly 20-40 ms per
            iteration); the budget stops a solve in its course (see the module's docstring).
        via_position_tolerance_m, via_orientation_tolerance_rad: tolerances of the via point's IK
            (the paper's loose transit tolerances).
    """

    num_control_points: int = 10
    spline_order: int = 4
    num_collision_samples: int = 15
    min_distance_m: float = 0.004
    influence_distance_m: float = 0.05
    min_duration_s: float = 0.5
    max_duration_s: float = 10.0
    duration_cost: float = 1.0
    path_length_cost: float = 1.0
    initial_guess: str = "straight"
    output_samples: int = 100
    check_resolution_rad: float = 0.01
    max_resolves: int = 8
    samples_per_hit: int = 3
    major_iterations: int = 100
    via_position_tolerance_m: float = 0.05
    via_orientation_tolerance_rad: float = 0.3

    def __post_init__(self):
        if self.initial_guess not in INITIAL_GUESSES:
            raise SuiteError(
                f"trajopt initial_guess={self.initial_guess!r}; allowed: {', '.join(INITIAL_GUESSES)}"
            )
        if self.spline_order < 2 or self.num_control_points < self.spline_order:
            raise SuiteError(
                f"trajopt needs 2 <= spline_order <= num_control_points, got order "
                f"{self.spline_order} with {self.num_control_points} control points"
            )
        for name in ("num_collision_samples", "output_samples", "major_iterations", "samples_per_hit"):
            if getattr(self, name) < 1:
                raise SuiteError(f"trajopt {name}={getattr(self, name)!r} must be >= 1")
        if self.max_resolves < 0:
            raise SuiteError(f"trajopt max_resolves={self.max_resolves!r} must be >= 0")
        if not 0 < self.min_duration_s < self.max_duration_s:
            raise SuiteError(
                f"trajopt duration bounds ({self.min_duration_s}, {self.max_duration_s}) must satisfy 0 < min < max"
            )
        for name in ("min_distance_m", "influence_distance_m", "check_resolution_rad"):
            if not getattr(self, name) > 0:
                raise SuiteError(f"trajopt {name}={getattr(self, name)!r} must be positive")
        if self.influence_distance_m <= self.min_distance_m:
            raise SuiteError("trajopt influence_distance_m must exceed min_distance_m")


class _OutOfTime(Exception):
    """Raised inside SNOPT's evaluations once a trial's deadline has passed (aborts the solve)."""


def colliding_s(world, path: np.ndarray, s: np.ndarray, *, resolution_rad: float) -> np.ndarray:
    """The s values of the dense samples (as the validator interpolates `path`) that collide.

    Args:
        world: the python-fcl CollisionWorld.
        path: (N, 7) joint path.
        s: (N,) path parameter of each row of `path`.
        resolution_rad: joint resolution of the straight-segment interpolation.
    """
    # A tiny s column rides along the interpolation without changing its sample counts.
    scale = 1e-9
    dense = world.interpolate(np.column_stack([path, s * scale]), resolution_rad)
    free = world.states_free(dense[:, :7])
    return dense[~free, 7] / scale


def _stretches(s_bad: np.ndarray, per_hit: int, gap: float) -> list[float]:
    """New sample points for colliding s values: `per_hit` points spread over each stretch."""
    if len(s_bad) == 0:
        return []
    s_bad = np.sort(s_bad)
    cuts = np.nonzero(np.diff(s_bad) > gap)[0]
    out = []
    for run in np.split(s_bad, cuts + 1):
        lo, hi = float(run[0]), float(run[-1])
        out += list(np.linspace(lo, hi, per_hit)) if hi - lo > 1e-6 else [lo]
    return out


class TrajoptPlanner(PlannerBase):
    """Drake's KinematicTrajectoryOptimization with dense python-fcl re-checks."""

    name: ClassVar[str] = "trajopt"
    Config: ClassVar[type] = TrajoptConfig
    search_space: ClassVar[dict[str, tuple]] = {
        "num_control_points": (10, 16), "num_collision_samples": (15, 30),
        "initial_guess": ("straight", "via_waypoints")}
    tuning_objective: ClassVar[str] = "length"

    def __init__(self, config: TrajoptConfig | None = None) -> None:
        super().__init__(config)
        self._contexts: dict[tuple, tuple] = {}

    def _plant(self, problem: PlanningProblem):
        key = problem.world_key()
        hit = self._contexts.get(key)
        if hit is None:
            ds = drake_plan_scene(problem)
            context = ds.diagram.CreateDefaultContext()
            hit = remember(self._contexts, key, (ds, context, ds.plant.GetMyMutableContextFromRoot(context)),
                           max_items=16)
        return hit

    def prepare(self, problem: PlanningProblem) -> None:
        """Build the plan-mode Drake scene and context of the problem's world (before the clock
        starts: it depends on the world only, as the sampling planners' collision world)."""
        self._plant(problem)

    def _via_point(self, problem: PlanningProblem, plant, plant_context, G, counter=None) -> np.ndarray | None:
        """A configuration near the problem's middle task waypoint, or None.

        Loose IK (position within `via_position_tolerance_m`, orientation within
        `via_orientation_tolerance_rad`, the distance constraint) closest to the start-goal midpoint;
        `counter` counts its evaluations (one distance query each).
        """
        if len(problem.waypoints) < 3:
            return None
        cfg = self.config
        X = RigidTransform(problem.waypoints[len(problem.waypoints) // 2].X_WG)
        q_mid = 0.5 * (problem.q_start + problem.q_goal)
        ik = InverseKinematics(plant, plant_context)
        tol = np.full(3, cfg.via_position_tolerance_m)
        ik.AddPositionConstraint(G, np.zeros(3), plant.world_frame(), X.translation() - tol, X.translation() + tol)
        ik.AddOrientationConstraint(G, RotationMatrix(), plant.world_frame(), X.rotation(),
                                    cfg.via_orientation_tolerance_rad)
        ik.AddMinimumDistanceLowerBoundConstraint(cfg.min_distance_m, cfg.influence_distance_m)
        prog = ik.get_mutable_prog()
        prog.AddQuadraticErrorCost(np.eye(7), q_mid, ik.q())
        prog.SetInitialGuess(ik.q(), q_mid)
        if counter is not None:
            prog.AddVisualizationCallback(counter, ik.q())
        result = SnoptSolver().Solve(prog)
        return result.GetSolution(ik.q()) if result.is_success() else None

    def _initial_control_points(self, problem: PlanningProblem, ds, plant_context, counter) -> tuple[np.ndarray, str]:
        """The initial guess's control points (num_control_points, 7) and its name: the joint-space
        line, or a bend through `_via_point` (`counter` counts its evaluations); a problem's warm
        start (the path being executed when it replans) comes first, mapped onto its ends. A
        subclass may seed the optimization otherwise (`suite.run.polish.SeededTrajopt`: from a
        given path)."""
        cfg = self.config
        warm = warm_start_guess(problem, cfg.num_control_points)
        if warm is not None:
            return warm, "warm_start"
        q_start = np.asarray(problem.q_start, float)
        q_goal = np.asarray(problem.q_goal, float)
        via = None
        if cfg.initial_guess == "via_waypoints":
            via = self._via_point(problem, ds.plant, plant_context, ds.plant.GetFrameByName("body", ds.wsg), counter)
        if via is not None:
            u = np.linspace(0, 1, cfg.num_control_points)[:, None]
            return np.where(u < 0.5, q_start + 2 * u * (via - q_start), via + (2 * u - 1) * (q_goal - via)), \
                "via_waypoints"
        return np.linspace(q_start, q_goal, cfg.num_control_points), "straight"

    def _queries(self, trajopt, prog, distance, evaluations, samples: list, queries: int) -> dict:
        """`planners.drake_queries.query_stats`: the count, and the seconds replayed at the sampled
        iterates, each at one of the constraint's path samples (in turn)."""
        cps = trajopt.control_points()
        idx = np.array(prog.FindDecisionVariableIndices(cps.flatten(order="F"))).reshape(cps.shape, order="F")
        at = []
        for k, x in enumerate(evaluations.sample):
            traj = BsplineTrajectory(trajopt.basis(), [x[idx[:, j]][:, None] for j in range(cps.shape[1])])
            at.append(traj.value(samples[k % len(samples)]).ravel())
        return query_stats(queries, distance, np.array(at), num_derivatives=self.config.spline_order * cps.shape[0])

    def solve(self, problem: PlanningProblem, world, budget: Budget) -> PlanResult:
        cfg = self.config
        t0 = time.perf_counter()
        ds, _, plant_context = self._plant(problem)
        plant = ds.plant
        q_start = np.asarray(problem.q_start, float)
        q_goal = np.asarray(problem.q_goal, float)
        n = plant.num_positions()

        trajopt = KinematicTrajectoryOptimization(n, cfg.num_control_points, cfg.spline_order, 1.0)
        prog = trajopt.get_mutable_prog()
        trajopt.AddDurationCost(cfg.duration_cost)
        trajopt.AddPathLengthCost(cfg.path_length_cost)
        trajopt.AddPositionBounds(plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits())
        trajopt.AddVelocityBounds(plant.GetVelocityLowerLimits(), plant.GetVelocityUpperLimits())
        trajopt.AddDurationConstraint(cfg.min_duration_s, cfg.max_duration_s)
        trajopt.AddPathPositionConstraint(q_start, q_start, 0)
        trajopt.AddPathPositionConstraint(q_goal, q_goal, 1)
        trajopt.AddPathVelocityConstraint(np.zeros(n), np.zeros(n), 0)
        trajopt.AddPathVelocityConstraint(np.zeros(n), np.zeros(n), 1)
        distance = MinimumDistanceLowerBoundConstraint(
            plant, cfg.min_distance_m, plant_context, None, cfg.influence_distance_m
        )
        samples = list(np.linspace(0, 1, cfg.num_collision_samples + 2)[1:-1])
        for s in samples:
            trajopt.AddPathPositionConstraint(distance, float(s))

        via_evaluations = EvaluationCounter()
        ctrl, guess = self._initial_control_points(problem, ds, plant_context, via_evaluations)
        trajopt.SetInitialGuess(BsplineTrajectory(trajopt.basis(), [c[:, None] for c in ctrl]))

        out_of_time = []
        evaluations = EvaluationCounter()
        queries = [via_evaluations.calls]  # per solve: evaluations x the distance bindings then

        def stop_at_deadline(x) -> None:  # evaluated with every cost and constraint evaluation
            evaluations(x)
            if budget.expired():
                out_of_time.append(True)
                raise _OutOfTime

        prog.AddVisualizationCallback(stop_at_deadline, prog.decision_variables())
        solver = SnoptSolver()
        options = SolverOptions()
        options.SetOption(SnoptSolver.id(), "Major iterations limit", cfg.major_iterations)
        s_out = np.linspace(0.0, 1.0, cfg.output_samples)
        stats: dict = {"solver": "SNOPT", "initial_guess": guess, "resolves": 0,
                       "constraint_samples": len(samples), "colliding_samples": [], "snopt_info": []}
        lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
        result = None
        reason = "solver failed"
        for attempt in range(cfg.max_resolves + 1):
            if attempt > 0:
                prog.SetInitialGuess(prog.decision_variables(), result.GetSolution(prog.decision_variables()))
            calls0 = evaluations.calls
            try:
                result = solver.Solve(prog, None, options)
            except RuntimeError:
                if not out_of_time:
                    raise
                queries.append((evaluations.calls - calls0) * len(samples))
                stats.update(resolves=attempt, solve_interrupted=True)
                break  # past the deadline: the TIMEOUT below
            queries.append((evaluations.calls - calls0) * len(samples))
            stats["resolves"] = attempt
            stats["solver_status"] = result.get_solution_result().name
            stats["snopt_info"].append(int(result.get_solver_details().info))
            traj = trajopt.ReconstructTrajectory(result)
            T = traj.end_time() - traj.start_time()
            path = np.array([traj.value(traj.start_time() + s * T).ravel() for s in s_out])
            # SNOPT's "cannot be improved" / iteration-limit exits often sit on a usable path: it is
            # kept if its ends and joint limits hold; the dense check then decides, as for a success.
            ends_ok = (np.max(np.abs(path[0] - q_start)) < 1e-4 and np.max(np.abs(path[-1] - q_goal)) < 1e-4
                       and np.all(path >= lower - 1e-6) and np.all(path <= upper + 1e-6))
            if not ends_ok:
                reason = f"solver failed ({stats['solver_status']}, info {stats['snopt_info'][-1]})"
                break
            path[0], path[-1] = q_start, q_goal
            path = np.clip(path, lower, upper)
            stats.update(duration_s=float(T), cost=float(result.get_optimal_cost()),
                         solver_converged=bool(result.is_success()))
            s_bad = colliding_s(world, path, s_out, resolution_rad=cfg.check_resolution_rad)
            stats["colliding_samples"].append(int(len(s_bad)))
            if len(s_bad) == 0:
                stats.update(constraint_samples=len(samples), solve_time_s=time.perf_counter() - t0)
                stats.update(self._queries(trajopt, prog, distance, evaluations, samples, sum(queries)))
                return PlanResult(PlanStatus.SUCCESS, path, stats)
            reason = "path still collides after the last re-solve"
            if budget.expired():
                break
            new = _stretches(s_bad, cfg.samples_per_hit, gap=2.0 / cfg.output_samples)
            for s in new:
                trajopt.AddPathPositionConstraint(distance, float(s))
            samples += new
        stats.update(constraint_samples=len(samples), solve_time_s=time.perf_counter() - t0)
        stats.update(self._queries(trajopt, prog, distance, evaluations, samples, sum(queries)))
        if budget.expired():
            stats["reason"] = "time limit reached"
            stats["reason_code"] = FailureReason.BUDGET_SPENT.value
            return PlanResult(PlanStatus.TIMEOUT, None, stats)
        stats["reason"] = reason
        stats["reason_code"] = (FailureReason.PATH_STILL_COLLIDES if reason.startswith("path still collides")
                                else FailureReason.SOLVER_FAILED).value
        return PlanResult(PlanStatus.NO_SOLUTION, None, stats)
