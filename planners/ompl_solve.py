"""The solve that the OMPL geometric planners of `planners.ompl_rrt` share: their common settings
(`OmplConfig`), one attempt (OMPL's solve, in slices for an optimizing planner so that its progress
is recorded, then the PathSimplifier), and the re-check at the validator's resolution with one
replan at that resolution if it fails. A planner family adds its OMPL planner object (`_make`), its
statistics and its typed config.

Every OMPL object of an attempt lives only inside it (`OmplProblem.release`); the trial's seed
reseeds OMPL before each attempt (`planners.ompl_adapter`).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from typing import Any, ClassVar

from ompl import base as ob
from ompl import geometric as og

from planners.base import (
    Budget,
    FailureReason,
    PlannerBase,
    PlanningProblem,
    PlanResult,
    PlanStatus,
    clock_now,
    snapped_to_ends,
)
from planners.ompl_adapter import (
    RESOLUTION_NORMS,
    OmplProblem,
    drop_collinear,
    path_array,
    reseed_ompl,
    set_ompl_log_level,
    trial_seed,
)
from planners.ompl_budget import termination
from scenes.errors import SuiteError

log = logging.getLogger(__name__)

SIMPLIFIERS = ("rope", "full", "rope+full")
#: How a motion is checked while planning and simplifying: "samples" (the field's rule: states at
#: most `resolution_rad` apart), "certified" (those samples, then the exact segment check).
MOTION_CHECKS = ("samples", "certified")


@dataclasses.dataclass(frozen=True)
class OmplConfig:
    """Settings shared by the OMPL planners.

    Attributes:
        range_rad: the planner's extension step (joint-space L2 norm, rad); None for OMPL's
            default (0.2 x the space's maximum extent, about 2.8 rad here).
        resolution_rad: the largest joint step between checked samples of a motion while
            planning and simplifying (rad): 0.05 for `rrt` (its few long segments are re-checked
            at `validate_resolution_rad`), 0.01 for the optimizing planners (their paths run
            along obstacles and would often fail the finer check).
        resolution_norm: the norm a motion's step is measured in: "linf" (default, the
            validator's rule: n = ceil(max_j |dq_j| / resolution_rad) equal steps) or "l2"
            (roboplan's `collision_check_step_size` rule: n = ceil(|dq|_2 / resolution_rad), up to
            sqrt(7) times as many samples on a diagonal motion). `planners.ompl_adapter.motion_steps`.
        simplifier: how OMPL's PathSimplifier shortens the path: "rope" (`ropeShortcutPath`:
            deterministic, pulls the path tight from the start), "full" (`simplify`: randomized
            shortcuts, B-spline smoothing and vertex reduction, until converged or out of time) or
            "rope+full" (both, the second in the time left).
        rope_delta_rad: `ropeShortcutPath`'s spacing of intermediate states (joint-space L2, rad).
        simplify_time_s: budget of the "full" simplification (s); 0 to skip simplification.
        validate_resolution_rad: the simplified path is re-checked at this joint resolution (the
            orchestrator's validator uses 0.01 rad, largest-joint norm, whatever
            `resolution_norm` is); if it fails, planning is repeated once with `resolution_rad`
            set to this value (in `resolution_norm`). Only when it is finer than
            `resolution_rad`; None to skip (roboplan has no such re-check: the peers' equal
            settings skip it).
        interpolate_rad: if set, the returned path is densified so that no joint moves more than
            this between consecutive waypoints; otherwise the simplified path's waypoints.
        time_limit_s: the budget of planning + simplification (s); None for the problem's
            `time_limit_s`.
        motion_check: "samples" (default, the field's rule as in OMPL and MoveIt: a motion is free
            if its samples `resolution_rad` apart are) or "certified" (its samples are free and
            the exact segment check of `scenes.collision.certify` proves the whole motion free; an
            unproved motion counts as blocked). The judge applies the same certifier afterwards.
        verbose: let OMPL's informational log messages through.
    """

    range_rad: float | None = None
    resolution_rad: float = 0.05
    resolution_norm: str = "linf"
    simplifier: str = "rope"
    rope_delta_rad: float = 1.0
    simplify_time_s: float = 0.1
    validate_resolution_rad: float | None = 0.01
    interpolate_rad: float | None = None
    time_limit_s: float | None = None
    motion_check: str = "samples"
    verbose: bool = False

    def __post_init__(self) -> None:
        if self.range_rad is not None and not self.range_rad > 0:
            raise SuiteError(f"range_rad must be > 0 or None, got {self.range_rad!r}")
        if not 0 < self.resolution_rad <= 0.2:
            raise SuiteError(f"resolution_rad must be in (0, 0.2] rad, got {self.resolution_rad!r}")
        if self.resolution_norm not in RESOLUTION_NORMS:
            raise SuiteError(f"resolution_norm must be one of {', '.join(RESOLUTION_NORMS)}, "
                             f"got {self.resolution_norm!r}")
        if self.simplifier not in SIMPLIFIERS:
            raise SuiteError(f"simplifier must be one of {', '.join(SIMPLIFIERS)}, got {self.simplifier!r}")
        if self.motion_check not in MOTION_CHECKS:
            raise SuiteError(f"motion_check must be one of {', '.join(MOTION_CHECKS)}, got {self.motion_check!r}")
        if not self.rope_delta_rad > 0:
            raise SuiteError(f"rope_delta_rad must be > 0, got {self.rope_delta_rad!r}")
        if not self.simplify_time_s >= 0:
            raise SuiteError(f"simplify_time_s must be >= 0, got {self.simplify_time_s!r}")
        for name in ("validate_resolution_rad", "interpolate_rad", "time_limit_s"):
            v = getattr(self, name)
            if v is not None and not v > 0:
                raise SuiteError(f"{name} must be > 0 or None, got {v!r}")


#: Most (time, best cost) points recorded per solve of an optimizing planner, the slices its budget
#: is solved in, and the shortest slice (s).
MAX_PROGRESS_POINTS = 200
PROGRESS_SLICES = 20
MIN_SLICE_S = 0.01


def _progress_point(op, t_solve: float) -> list:
    """[time since the solve started (s), the best solution's cost, or None before the first one]."""
    cost = (float(og.PathGeometric(op.pdef.getSolutionPath()).cost(op.objective).value())
            if op.pdef.hasExactSolution() else None)
    return [round(time.perf_counter() - t_solve, 6), cost]


class OmplPlanner(PlannerBase):
    """One OMPL geometric planner on the problem's python-fcl world (see the module docstring)."""

    name: ClassVar[str]
    Config: ClassVar[type] = OmplConfig
    solver: ClassVar[str]
    optimizing: ClassVar[bool] = True
    #: whether to report the size of the planner's graph (BIT*'s PlannerData keeps the space
    #: information alive past the trial; AORRTC reports none)
    graph_stats: ClassVar[bool] = True
    #: whether solve() may be called again to carry on (AORRTC crashes on a second call)
    resumable: ClassVar[bool] = True

    # subclasses: the OMPL planner object
    def _make(self, si: ob.SpaceInformation) -> ob.Planner:
        raise NotImplementedError

    def _planner_stats(self, planner) -> dict[str, Any]:
        return {}

    #: the budget clock of the solve in progress (`solve` sets it; `_attempt` reads it)
    _clock: str = "wall"

    def solve(self, problem: PlanningProblem, world, budget: Budget) -> PlanResult:
        """Plan a collision-free joint path from `problem.q_start` to `problem.q_goal` (both
        checked valid by `PlannerBase.plan`), within `budget` (on its clock).

        Returns:
            SUCCESS with the (N, 7) path (rad) from q_start to q_goal exactly; TIMEOUT if the
            budget ran out without an exact solution; NO_SOLUTION if the planner stopped without one.
        """
        cfg = self.config
        set_ompl_log_level(cfg.verbose)
        checks0, query0 = world.checks, world.query_s
        self._clock = budget.clock
        t0 = budget.now()
        budget_s = cfg.time_limit_s if cfg.time_limit_s is not None else budget.deadline - t0
        seed = trial_seed(problem)
        result = self._attempt(problem, world, resolution_rad=cfg.resolution_rad, budget_s=budget_s, seed=seed)
        fine = cfg.validate_resolution_rad
        if result.status is PlanStatus.SUCCESS and fine is not None and fine < cfg.resolution_rad:
            bad_at = world.path_free(result.path, resolution_rad=fine)
            if bad_at >= 0:
                remaining_s = budget_s - (budget.now() - t0)
                log.debug("%s %s: path collides at %.3f rad resolution; replanning at that resolution in %.3f s",
                         self.name, problem.name, fine, remaining_s)
                if remaining_s > 0:
                    retry = self._attempt(problem, world, resolution_rad=fine, budget_s=remaining_s, seed=seed)
                else:
                    retry = PlanResult(PlanStatus.TIMEOUT, None, {
                        **result.stats, "reason": f"path collides at {fine} rad resolution; no time left to replan"})
                result = dataclasses.replace(retry, stats={**retry.stats, "replanned_fine": True})
        stats = {**result.stats, "collision_checks": world.checks - checks0, "seed": seed,
                 "collision_query_s": world.query_s - query0}
        stats.setdefault("replanned_fine", False)
        path = result.path
        if path is not None and cfg.interpolate_rad is not None:
            path = world.interpolate(path, cfg.interpolate_rad)
        stats["interpolated"] = cfg.interpolate_rad is not None
        code = {PlanStatus.TIMEOUT: FailureReason.BUDGET_SPENT, PlanStatus.NO_SOLUTION: FailureReason.SEARCH_FAILED,
                PlanStatus.ERROR: FailureReason.PLANNER_ERROR}.get(result.status)
        if code is not None:
            stats.setdefault("reason_code", code.value)
        return PlanResult(result.status, path, stats)

    @staticmethod
    def _solve_in_slices(op, budget_s: float, progress: list, t_solve: float, clock: str = "wall"):
        """Solve for the budget in PROGRESS_SLICES slices (an OMPL planner's solve() carries on from
        its tree or roadmap when called again), recording (time in the solve, best cost or None
        before the first solution) after each slice: OMPL's planner progress properties, which its
        Python bindings cannot return, sampled at a fixed period as OMPL's Benchmark samples them.
        The budget is on `clock`; each slice is wall-timed and no longer than what is left of it
        (`planners.ompl_budget`: PRM checks its condition from a thread of its own)."""
        deadline = clock_now(clock) + budget_s
        status = None
        while True:
            left = deadline - clock_now(clock)
            if left <= 0 and status is not None:
                return status
            slice_s = max(min(max(budget_s / PROGRESS_SLICES, MIN_SLICE_S), left), 1e-4)
            t_slice = time.perf_counter()
            status = op.planner.solve(ob.timedPlannerTerminationCondition(slice_s))
            quick = time.perf_counter() - t_slice < 0.1 * slice_s  # it stopped on its own
            if len(progress) < MAX_PROGRESS_POINTS:  # every slice, as OMPL samples at a fixed period
                progress.append(_progress_point(op, t_solve))
            T = ob.PlannerStatus.PlannerStatusType
            if status.getStatus() not in (T.EXACT_SOLUTION, T.APPROXIMATE_SOLUTION, T.TIMEOUT):
                return status  # stopped on its own (no solution possible, a crash)
            if quick and op.pdef.hasExactSolution():
                return status  # converged or satisfied: another slice would return at once too

    def _attempt(self, problem: PlanningProblem, world, *, resolution_rad: float, budget_s: float,
                 seed: int) -> PlanResult:
        """One OMPL solve + simplification; every OMPL object lives only inside this call."""
        cfg = self.config
        reseed_ompl(seed)
        simplify_budget_s = min(cfg.simplify_time_s, 0.5 * budget_s)
        solve_budget_s = budget_s - simplify_budget_s
        op = OmplProblem(world, problem.q_start, problem.q_goal, resolution_rad=resolution_rad,
                         optimizing=self.optimizing, certify=cfg.motion_check == "certified",
                         norm=cfg.resolution_norm, count_accepted=not self.optimizing)
        op.attach(self._make(op.si))
        stats: dict[str, Any] = {"solver": self.solver, "resolution_rad": resolution_rad,
                                 "resolution_norm": cfg.resolution_norm, "motion_check": cfg.motion_check,
                                 "post_processing": cfg.simplifier if simplify_budget_s > 0 else "none"}
        path = simplifier = None
        progress: list[list] = []  # optimizing planners: [time in the solve, best cost or None] points
        try:
            t_solve, c_solve = time.perf_counter(), clock_now(self._clock)
            if self.optimizing and self.resumable:
                status = self._solve_in_slices(op, solve_budget_s, progress, t_solve, self._clock)
                stats["progress"] = progress
            elif self.optimizing:  # one solve: its progress is the end point only
                status = op.planner.solve(termination(self._clock, solve_budget_s))
                progress.append(_progress_point(op, t_solve))
                stats["progress"] = progress
            else:
                status = op.planner.solve(termination(self._clock, solve_budget_s))
            solve_time_s = time.perf_counter() - t_solve
            solve_spent_s = clock_now(self._clock) - c_solve  # on the budget's clock
            if not self.optimizing:
                # the search's check density: the samples of the motions that passed, one per tree
                # edge (RRT-Connect adds an edge for each), before the simplifier checks its own
                edges = op.validator.accepted
                samples = op.validator.accepted_samples(edges)
                stats.update(tree_edges=edges, edge_samples=samples, samples_per_edge=samples / edges if edges else None,
                             samples_per_edge_from="counted")
            code = status.getStatus()
            T = ob.PlannerStatus.PlannerStatusType
            stats.update(solve_time_s=solve_time_s, solver_status=status.asString(),
                         motion_checks=op.validator.motions, certified_motion_checks=op.validator.certified_calls,
                         certify_s=round(op.validator.certify_s, 6), **self._planner_stats(op.planner))
            if self.graph_stats:
                data = ob.PlannerData(op.si)
                op.planner.getPlannerData(data)
                stats["graph_vertices"] = data.numVertices()
                del data
            if code != T.EXACT_SOLUTION or not op.pdef.hasExactSolution():
                out_of_time = solve_spent_s >= solve_budget_s * 0.999
                if code in (T.TIMEOUT, T.APPROXIMATE_SOLUTION) and out_of_time:
                    return PlanResult(PlanStatus.TIMEOUT, None, stats)
                if code == T.CRASH:
                    return PlanResult(PlanStatus.ERROR, None, stats)
                return PlanResult(PlanStatus.NO_SOLUTION, None, stats)

            path = og.PathGeometric(op.pdef.getSolutionPath())
            stats["length_before_rad"] = path.length()
            stats["waypoints_before"] = path.getStateCount()
            if op.objective is not None:
                stats["best_cost"] = path.cost(op.objective).value()
            t_simp, c_simp = time.perf_counter(), clock_now(self._clock)
            if simplify_budget_s > 0:
                simplifier = og.PathSimplifier(op.si)
                if cfg.simplifier in ("rope", "rope+full"):
                    simplifier.ropeShortcutPath(path, cfg.rope_delta_rad)
                left_s = simplify_budget_s - (clock_now(self._clock) - c_simp)
                if cfg.simplifier in ("full", "rope+full") and left_s > 0:
                    simplifier.simplify(path, termination(self._clock, left_s))
            stats["simplify_time_s"] = time.perf_counter() - t_simp
            stats["length_after_rad"] = path.length()
            stats["motion_checks"] = op.validator.motions
            stats.update(certified_motion_checks=op.validator.certified_calls,
                         certify_s=round(op.validator.certify_s, 6))
            Q = drop_collinear(path_array(path))
            stats["waypoints"] = len(Q)
        finally:
            # Release in dependency order: paths and simplifier, the planner's data and problem,
            # then the problem definition, the space information and the space.
            del path, simplifier
            op.release()

        # The path runs between the very start and goal states; snap away float noise, if any.
        return snapped_to_ends(problem, Q, stats)
