"""The planner interface: problems in, results out, identical for every planner family."""

from __future__ import annotations

import dataclasses
import enum
import time
from collections.abc import Callable
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np

from scenes.identity_rule import CURRENT_RULE, hashed, hashed_scalar
from scenes.scene import HeldCan, Scene


class PlanStatus(str, enum.Enum):
    """Outcome of one planning trial. Only SUCCESS carries a path that counts."""

    SUCCESS = "success"
    NO_SOLUTION = "no_solution"
    TIMEOUT = "timeout"
    INVALID_START = "invalid_start"
    INVALID_GOAL = "invalid_goal"
    IK_FAILED = "ik_failed"
    ERROR = "error"
    # Set by the orchestrator, never by a planner:
    INVALID_SOLUTION = "invalid_solution"  # the independent validator rejected the path
    TIMING_FAILED = "timing_failed"  # TOPP-RA could not time the path
    CRASH = "crash"  # the worker process died
    KILLED_TIMEOUT = "killed_timeout"  # the worker overran the hard time limit and was killed


class FailureReason(str, enum.Enum):
    """Why a trial failed, beside its status: one word per cause a reader can act on.

    A planner names its cause in `stats["reason_code"]` (its free-text `stats["reason"]` keeps
    the detail); the orchestrator names the causes it decides (the validator, the timing, a crash,
    the clock). `suite.run.records.reason_code` reads a record's, old records included.
    """

    ENDPOINT_IN_COLLISION = "endpoint_in_collision"  # the start or goal configuration collides
    ENDPOINT_OUT_OF_LIMITS = "endpoint_out_of_limits"  # the start or goal is outside the joint limits
    NO_GOAL_IK = "no_goal_ik"  # the problem has no goal configuration (no collision-free IK)
    NO_IK_AT_KNOT = "no_ik_at_knot"  # a task waypoint has no IK solution within the tolerances
    GOAL_NOT_REACHED = "goal_not_reached"  # the waypoints end off the goal, or the last step collides
    SOLVER_FAILED = "solver_failed"  # the optimizer stopped without a usable solution
    PATH_STILL_COLLIDES = "path_still_collides"  # the planner's own repairs left a collision
    REGIONS_MISSING = "regions_missing"  # no convex regions were built for the world
    REGIONS_DISCONNECTED = "regions_disconnected"  # the regions do not connect start and goal
    SEARCH_FAILED = "search_failed"  # a sampling planner stopped without a solution, within budget
    BUDGET_SPENT = "budget_spent"  # the planning budget ran out (the planner said so)
    LATE_PATH = "late_path"  # a valid path came after the budget (it does not count)
    PATH_REJECTED = "path_rejected"  # the independent validator rejected the claimed path
    PATH_OVER_LIMIT = "path_over_limit"  # the claimed path is over the judge's size limits
    TIMING_FAILED = "timing_failed"  # TOPP-RA could not time the path
    PLANNER_ERROR = "planner_error"  # the planner raised or returned an error
    OUT_OF_MEMORY = "out_of_memory"  # the worker hit its memory cap
    CRASH = "crash"  # the worker process died
    KILLED = "killed"  # the worker overran the hard time limit and was killed
    NOT_STATED = "not_stated"  # an external or old record that gives no cause


#: The motions of the paper's pick-and-place cycle, in order.
PROBLEM_KINDS = ("approach", "descend", "lift", "transit", "return")
#: A free transit: a motion between two configurations that belongs to no can's cycle (nothing
#: held, nothing picked up or put down), such as the GCS paper's tasks between its shelves and
#: bins. A scene numbers its free transits by `PlanningProblem.task_index`; no can does.
FREE_TRANSIT = "free"
#: Every kind a problem may have: the cycle's motions, then the free transit.
ALL_KINDS = (*PROBLEM_KINDS, FREE_TRANSIT)

#: The clocks a planning budget is measured on (s): "wall" (`time.perf_counter`, the elapsed time a
#: user waits) and "cpu" (`time.process_time`: the CPU time of the planner's process, all of its
#: threads: OMPL's PRM checks for a solution in a thread of its own, Drake's GCS rounds paths in
#: parallel, so the calling thread's time alone would miss work). A process runs one trial at a
#: time, so its CPU time across `plan` is the trial's. Looked up when read (a test may fake one).
CLOCKS: dict[str, Callable[[], float]] = {"wall": time.perf_counter, "cpu": time.process_time}
BUDGET_CLOCKS = tuple(CLOCKS)


def clock_now(clock: str) -> float:
    """The current reading of budget clock `clock` ("wall" or "cpu"), s."""
    return CLOCKS[clock]()


@dataclasses.dataclass(frozen=True)
class Budget:
    """A planning budget on one clock: what a planner's deadline checks read.

    Attributes:
        clock: "wall" or "cpu" (`BUDGET_CLOCKS`).
        start: the clock's reading when the budget started (s).
        deadline: the clock's reading at which it is spent (s).
    """

    clock: str
    start: float
    deadline: float

    def __post_init__(self) -> None:
        if self.clock not in CLOCKS:
            from scenes.errors import SuiteError

            raise SuiteError(f"budget clock {self.clock!r}; allowed: {', '.join(BUDGET_CLOCKS)}")

    @classmethod
    def starting_now(cls, seconds: float, *, clock: str = "wall") -> "Budget":
        """`seconds` on `clock` from now."""
        start = CLOCKS[clock]() if clock in CLOCKS else 0.0
        return cls(clock, start, start + float(seconds))

    def now(self) -> float:
        """The clock's reading (s)."""
        return CLOCKS[self.clock]()

    def spent_s(self) -> float:
        """Seconds of the budget used so far, on its clock."""
        return self.now() - self.start

    def left_s(self) -> float:
        """Seconds left before the deadline, on its clock (negative once past it)."""
        return self.deadline - self.now()

    def expired(self) -> bool:
        """Whether the deadline has passed."""
        return self.now() >= self.deadline


@dataclasses.dataclass(frozen=True)
class PlanWorld:
    """The world a planner plans in when it is not the judge's: a world built from the cameras
    (`perception.world`). The judge (validator, certifier, metrics) and the physics keep the
    problem's own scene, held can and removed cans: the truth.

    Attributes:
        scene: the planner's scene (its fixtures, voxel boxes and perceived cans).
        held: the can the planner believes is in the gripper (its perceived pose), or None.
        removed_can_ids: the planner's cans already recycled (ids of `scene`'s cans).
        source: where the world comes from (`perceived`).
    """

    scene: Scene
    held: HeldCan | None
    removed_can_ids: tuple[int, ...]
    source: str = "perceived"


@dataclasses.dataclass(frozen=True)
class TaskWaypoint:
    """A gripper pose of the nominal trajectory at a time of the paper's schedule (time units)."""

    t: float
    X_WG: np.ndarray


@dataclasses.dataclass(frozen=True)
class PlanningProblem:
    """One motion of the pick-and-place cycle, or a free transit.

    Attributes:
        kind: one of PROBLEM_KINDS, or FREE_TRANSIT.
        scene: the scene (ground truth: what the robot really collides with).
        can_id: the can this cycle picks (ground-truth id); None for a free transit.
        q_start: start configuration (7,) rad.
        q_goal: goal configuration (7,) rad shared by every planner (collision-aware IK, computed
            once), or None when no IK solution exists (then `pre_status` is IK_FAILED).
        X_WG_goal: the goal gripper pose (4, 4).
        waypoints: the nominal task-space trajectory from the start pose to the goal pose
            (the nominal-waypoint planner follows it; the others may ignore it).
        held: the can carried in the gripper, part of the robot for collision, or None.
        gripper_opening_m: finger opening during the motion.
        removed_can_ids: cans already recycled (not on the plate any more).
        time_limit_s: the planner's budget, s on `budget_clock`.
        seed: the trial's seed (derived from the run seed and the trial's identity).
        pre_status: set when the problem cannot be posed (IK_FAILED); planners are not run.
        warm_start: an optional joint path (N, 7) a planner may start from (the path being
            executed when it replans toward a moved goal); its ends need not be q_start and
            q_goal (`warm_start_guess` maps it onto them). A planner that ignores it is unchanged;
            it is no part of the problem's identity.
        budget_clock: the clock `time_limit_s` is measured on: "wall" (elapsed time) or "cpu"
            (the planner's process's CPU time; `Budget`).
        plan_world: the world the planner plans in when it is not `scene` (a perceived world:
            `for_planner`); None: the planner plans in the truth.
        task_index: a free transit's number among its scene's tasks (0, 1, ...); None for a
            cycle's motion, which its can numbers.
    """

    kind: str
    scene: Scene
    can_id: int | None
    q_start: np.ndarray
    q_goal: np.ndarray | None
    X_WG_goal: np.ndarray
    waypoints: tuple[TaskWaypoint, ...]
    held: HeldCan | None
    gripper_opening_m: float
    removed_can_ids: tuple[int, ...]
    time_limit_s: float
    seed: int
    pre_status: PlanStatus | None = None
    warm_start: np.ndarray | None = None
    budget_clock: str = "wall"
    plan_world: PlanWorld | None = None
    task_index: int | None = None

    def __post_init__(self) -> None:
        free = self.kind == FREE_TRANSIT
        if self.kind not in ALL_KINDS or free != (self.task_index is not None) or free != (self.can_id is None):
            from scenes.errors import SuiteError

            raise SuiteError(f"problem kind {self.kind!r} with can_id {self.can_id} and task_index {self.task_index}: "
                             f"a cycle's motion ({', '.join(PROBLEM_KINDS)}) has a can_id and no task_index, "
                             f"a free transit ({FREE_TRANSIT!r}) a task_index and no can_id")

    @property
    def subject(self) -> int | str:
        """What the problem is numbered by in its scene: its can's id (an int, as trial seeds have
        always been derived from), or `task<index>` for a free transit."""
        return self.can_id if self.task_index is None else f"task{self.task_index}"

    @property
    def name(self) -> str:
        s = self.subject
        return f"{s if isinstance(s, str) else f'can{s}'}/{self.kind}"

    def world_key(self, *, rule: str = CURRENT_RULE) -> tuple:
        """Identifies the collision world of this problem (per-process caches, region cache keys),
        its floats written by identity rule `rule` (`scenes.identity_rule`)."""
        return (
            self.scene.key(),
            None if self.held is None else (self.held.can.id, hashed(self.held.X_GC, rule=rule).tobytes()),
            hashed_scalar(self.gripper_opening_m, rule=rule),
            tuple(sorted(self.removed_can_ids)),
        )

    def with_(self, **changes) -> "PlanningProblem":
        return dataclasses.replace(self, **changes)

    def for_planner(self) -> "PlanningProblem":
        """The problem as its planner sees it: in its `plan_world` when it has one (the same
        configurations, budget and seed), else itself."""
        w = self.plan_world
        if w is None:
            return self
        return dataclasses.replace(self, scene=w.scene, held=w.held, removed_can_ids=w.removed_can_ids, plan_world=None)


def resample_by_length(path: np.ndarray, n: int) -> np.ndarray:
    """n points (n, 7) evenly spaced by joint-space arc length along the polyline `path`, its ends
    exact."""
    path = np.asarray(path, float)
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] <= 0:
        return np.repeat(path[:1], n, axis=0)
    u = np.linspace(0.0, s[-1], n)
    out = np.column_stack([np.interp(u, s, path[:, j]) for j in range(path.shape[1])])
    out[0], out[-1] = path[0], path[-1]
    return out


def warm_start_guess(problem: "PlanningProblem", n: int) -> np.ndarray | None:
    """The problem's warm start as n points (n, 7) from q_start to q_goal: resampled by length, its
    ends moved onto the problem's by a correction that fades linearly along it; None without one."""
    if problem.warm_start is None or problem.q_goal is None:
        return None
    g = resample_by_length(np.asarray(problem.warm_start, float), n)
    u = np.linspace(0.0, 1.0, n)[:, None]
    g = g + (1 - u) * (np.asarray(problem.q_start, float) - g[0]) + u * (np.asarray(problem.q_goal, float) - g[-1])
    g[0], g[-1] = problem.q_start, problem.q_goal
    return g


@dataclasses.dataclass(frozen=True)
class PlanResult:
    """What a planner returns.

    Attributes:
        status: the outcome.
        path: joint waypoints (N, 7) rad from q_start to q_goal, or None.
        stats: planner statistics (plain JSON values): iterations, collision_checks, solver,
            solver_status, costs, solve_time_s, simplify_time_s, ...
    """

    status: PlanStatus
    path: np.ndarray | None = None
    stats: dict[str, Any] = dataclasses.field(default_factory=dict)


@runtime_checkable
class Planner(Protocol):
    """A motion planner. `Config` is a dataclass of its settings; `plan` never raises for a
    problem it cannot solve: that is a status."""

    name: ClassVar[str]
    Config: ClassVar[type]

    def __init__(self, config: Any = None) -> None: ...

    def prepare(self, problem: PlanningProblem) -> None:
        """Build what depends on the problem's world only (a Drake diagram, a program; nothing is
        fine): the orchestrator calls it before starting the clock and records its time as
        `setup_time_s`, as it builds the python-fcl worlds of every problem outside the clock."""

    def plan(self, problem: PlanningProblem) -> PlanResult: ...

    # `PlannerBase` below implements this protocol as a template: a planner then writes `solve` only.


#: The methods a planner class must have (`planners.registry.planner_class` checks them).
PLANNER_METHODS = ("prepare", "plan")


#: The cause a failure status names by itself: a planner's status that gave no cause (filled in
#: by `PlannerBase.plan`), and the orchestrator's statuses (`suite.run.records.reason_code`).
STATUS_CAUSE = {
    PlanStatus.TIMEOUT: FailureReason.BUDGET_SPENT,
    PlanStatus.ERROR: FailureReason.PLANNER_ERROR,
    PlanStatus.IK_FAILED: FailureReason.NO_GOAL_IK,
    PlanStatus.INVALID_SOLUTION: FailureReason.PATH_REJECTED,
    PlanStatus.TIMING_FAILED: FailureReason.TIMING_FAILED,
    PlanStatus.CRASH: FailureReason.CRASH,
    PlanStatus.KILLED_TIMEOUT: FailureReason.KILLED,
}


class PlannerBase:
    """The planner contract as a template: `plan` runs the parts every planner shares, a planner
    writes only its algorithm in `solve`.

    `plan(problem)`:
    1. takes the problem's python-fcl world (built outside the clock by the orchestrator, as
       `prepare` builds what else depends on the world alone);
    2. checks the endpoints (`check_endpoints`): a bad one is reported at once, with its cause;
    3. calls `solve(problem, world, budget)` with the problem's budget (`Budget`: its
       `time_limit_s` on its `budget_clock`, started now);
    4. fills in and checks the stats every planner shares (`shared_stats`: `reason_code`,
       `solver`, `reason`).

    A subclass sets `name`, `Config` (a frozen dataclass), optionally `solver` (stats' name for
    what it runs) and its tuning (`search_space`, `tuning_objective`), and overrides `solve` and,
    when it has world-only set-up, `prepare`.
    """

    name: ClassVar[str]
    Config: ClassVar[type]
    solver: ClassVar[str | None] = None
    #: `suite tune`'s search, next to the settings it searches: each setting's candidate values,
    #: the class default first (the grid is their product; small, so a tuning fits a session)
    search_space: ClassVar[dict[str, tuple]] = {}
    #: what the tuning weighs once success is settled: "time" (a feasibility planner: median time
    #: to solve, failures at the budget) or "length" (an optimizing planner: median length over
    #: the best known, on the problems every candidate solved)
    tuning_objective: ClassVar[str] = "time"

    def __init__(self, config: Any = None) -> None:
        from scenes.errors import SuiteError

        config = self.Config() if config is None else config
        if not isinstance(config, self.Config):
            raise SuiteError(f"planner {self.name!r} takes a {self.Config.__name__}, got {type(config).__name__}")
        self.config = config

    def prepare(self, problem: PlanningProblem) -> None:
        """Build what depends on the problem's world only (a Drake diagram, regions, a program):
        the orchestrator calls it before it starts the clock. Nothing by default."""

    def plan(self, problem: PlanningProblem) -> PlanResult:
        """The shared steps around `solve` (see the class docstring); never raises for a problem
        it cannot solve."""
        from planners.worlds import planning_world

        world = planning_world(problem)
        bad = check_endpoints(problem, world)
        if bad is not None:
            return shared_stats(bad, solver=self.solver)
        budget = Budget.starting_now(float(problem.time_limit_s), clock=problem.budget_clock)
        result = self.solve(problem, world, budget)
        return shared_stats(result, solver=self.solver)

    def solve(self, problem: PlanningProblem, world, budget: Budget) -> PlanResult:
        """The algorithm: a path from `problem.q_start` to `problem.q_goal` (both checked valid),
        within `budget` (its deadline checks read `budget.expired()` / `budget.left_s()`, so that
        they run on the run's budget clock). Failures name their cause in `stats["reason_code"]`
        (`FailureReason`)."""
        raise NotImplementedError


def shared_stats(result: PlanResult, *, solver: str | None) -> PlanResult:
    """The stats every planner's result shares, filled in and checked (`PlannerBase.plan`):

    - `reason_code`: a `FailureReason` value on a failure, named from the status when the planner
      named none (a timeout spent its budget, an error is the planner's); a word that is no
      `FailureReason` is the planner's bug (ValueError, which the trial records as its error);
    - `solver`: what it ran (the class's `solver` unless the planner named one);
    - `reason`: free text, the detail a reader needs (kept as the planner wrote it).

    Every other key is the planner's own.
    """
    stats = dict(result.stats)
    code = stats.get("reason_code")
    if code is not None:
        FailureReason(code)  # ValueError for a word that is no cause
    elif result.status is not PlanStatus.SUCCESS and STATUS_CAUSE.get(PlanStatus(result.status)) is not None:
        stats["reason_code"] = STATUS_CAUSE[PlanStatus(result.status)].value
    if solver and "solver" not in stats:
        stats["solver"] = solver
    return PlanResult(result.status, result.path, stats)


def check_endpoints(problem: PlanningProblem, world) -> PlanResult | None:
    """The shared pre-check: an invalid start or goal is reported at once.

    Returns a PlanResult with INVALID_START / INVALID_GOAL (or the problem's pre_status), or None
    if both ends are valid.
    """
    if problem.pre_status is not None:
        return PlanResult(problem.pre_status, None, {"reason_code": FailureReason.NO_GOAL_IK.value})
    if problem.q_goal is None:
        return PlanResult(PlanStatus.IK_FAILED, None, {"reason_code": FailureReason.NO_GOAL_IK.value})
    lo, hi = world.robot.lower_rad, world.robot.upper_rad
    for q, status in ((problem.q_start, PlanStatus.INVALID_START), (problem.q_goal, PlanStatus.INVALID_GOAL)):
        q = np.asarray(q, float)
        if q.shape != (7,) or not np.all(np.isfinite(q)) or np.any(q < lo - 1e-9) or np.any(q > hi + 1e-9):
            return PlanResult(status, None, {"reason": "outside joint limits",
                                             "reason_code": FailureReason.ENDPOINT_OUT_OF_LIMITS.value})
        if not world.is_free(q):
            return PlanResult(status, None, {"reason": "in collision",
                                             "reason_code": FailureReason.ENDPOINT_IN_COLLISION.value})
    return None


def snapped_to_ends(problem: PlanningProblem, path: np.ndarray, stats: dict) -> PlanResult:
    """A sampling planner's solution with its ends set to the very start and goal: float noise
    (up to 1e-9 rad) snapped away, a larger offset an ERROR naming it."""
    for end, q in ((0, problem.q_start), (-1, problem.q_goal)):
        err = float(np.max(np.abs(path[end] - q)))
        if err > 1e-9:
            return PlanResult(PlanStatus.ERROR, None, {**stats, "reason": f"path end off by {err:.3g} rad",
                                                       "reason_code": FailureReason.PLANNER_ERROR.value})
        path[end] = q
    return PlanResult(PlanStatus.SUCCESS, path, stats)
