"""`roboplan-rrt`: roboplan's RRT-Connect (C++: pinocchio + coal) as a planner of the suite.

A peer that shares the process (optional extra `peers`: `pip install -e .[peers]`). It plans on
`planners.roboplan_scene`'s model of the problem's world: the suite's own robot, scene, held can,
gripper opening and filtered pairs, with the python-fcl world's primitives and poses
(`python -m suite bench agreement` measures how far the two engines agree). Nothing here falls back
to another planner or another checker: what roboplan returns is what the validator judges.

Settings and how they map to the suite's `rrt` (docs/peers.md):
- `range_rad` is roboplan's `max_connection_distance`, the joint-space L2 length of one extension,
  `rrt`'s `range_rad` (OMPL's `setRange`) in the same norm.
- `collision_check_step_rad` is roboplan's `collision_check_step_size`: an edge of joint-space L2
  length L is checked at n = max(1, ceil(L / step)) equal steps (its interior samples i / n, and its
  end; roboplan 0.7.0's `hasCollisionsAlongPath`, checked against the library by probing a
  grazing edge at 3,000 step sizes), which bounds every joint's step too. 0.01 rad by default, the
  validator's resolution (roboplan's own default is 0.05). `rrt` samples a motion the same way with
  `resolution_norm: l2` (`planners.ompl_adapter.motion_steps`).
- `shortcut` runs roboplan's `PathShortcutter` (random shortcuts checked at the same step), as
  `rrt` runs OMPL's rope shortcut.

Collision queries: roboplan's checks happen in C++ and are not counted by roboplan. The stats give
the tree's size, a lower bound of the state checks (the samples of every edge kept in the two
trees; rejected extensions and the shortcutter's checks are not counted) and that bound times the
cost of one check measured in `prepare` (outside the clock). The same count gives the search's
check density, `samples_per_edge` (computed from the kept edges' lengths and the step, as
`samples_per_edge_from: computed` says; `rrt` counts its own).
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any, ClassVar

import numpy as np
import roboplan.core as rpc
import roboplan.rrt as rpr

from planners.base import Budget, FailureReason, PlannerBase, PlanningProblem, PlanResult, PlanStatus, snapped_to_ends
from planners.ompl_adapter import trial_seed
from planners.roboplan_scene import RoboplanWorld, build_roboplan_world
from planners.worlds import collision_world, remember
from scenes.errors import SuiteError

#: roboplan's failure messages (roboplan_rrt/rrt.cpp, 0.7.0) and the statuses they mean.
TIMEOUT_MESSAGE = "timed out"
NODES_MESSAGE = "maximum number of nodes"

#: Per-process cache of roboplan scenes, by the problem's world key.
_SCENES: dict[tuple, tuple[RoboplanWorld, float]] = {}
#: Configurations timed in `prepare` to estimate the cost of one of roboplan's state checks.
CALIBRATION_CHECKS = 400


@dataclasses.dataclass(frozen=True)
class RoboplanRRTConfig:
    """Settings of roboplan's RRT-Connect.

    Attributes:
        range_rad: roboplan's `max_connection_distance`: the longest extension (joint-space L2
            norm, rad). roboplan's default is 3.0.
        collision_check_step_rad: roboplan's `collision_check_step_size`: the largest joint-space
            L2 step between checked samples of an edge (rad); 0.01 matches the validator.
        use_bisection: check an edge's samples middle first (roboplan's default) rather than
            walking from its start; the same samples on a free edge.
        goal_bias: roboplan's `goal_biasing_probability` (its default 0.15). roboplan ignores it
            under RRT-Connect, which always grows towards the other tree; kept for a plain RRT.
        max_nodes: roboplan's cap on the nodes sampled (its default is 1000, which would end a
            hard problem long before its budget; OMPL's `rrt` has no cap, so the budget governs).
        shortcut: shorten the first solution with roboplan's `PathShortcutter`.
        shortcut_max_iters: the shortcutter's random shortcut attempts (its default 100).
        shortcut_reserve_s: time kept back from the search for the shortcutter (s); a shortcut
            that would start after the budget is skipped.
        time_limit_s: the budget of search and shortcutting (s); None for the problem's.
    """

    range_rad: float = 3.0
    collision_check_step_rad: float = 0.01
    use_bisection: bool = True
    goal_bias: float = 0.15
    max_nodes: int = 1_000_000
    shortcut: bool = True
    shortcut_max_iters: int = 100
    shortcut_reserve_s: float = 0.1
    time_limit_s: float | None = None

    def __post_init__(self) -> None:
        if not (isinstance(self.range_rad, (int, float)) and self.range_rad > 0):
            raise SuiteError(f"range_rad must be > 0 rad, got {self.range_rad!r}")
        if not 0 < self.collision_check_step_rad <= 0.2:
            raise SuiteError(f"collision_check_step_rad must be in (0, 0.2] rad, got {self.collision_check_step_rad!r}")
        if not 0 <= self.goal_bias <= 1:
            raise SuiteError(f"goal_bias must be in [0, 1], got {self.goal_bias!r}")
        if not (isinstance(self.max_nodes, int) and self.max_nodes >= 2):
            raise SuiteError(f"max_nodes must be an integer >= 2, got {self.max_nodes!r}")
        if not (isinstance(self.shortcut_max_iters, int) and self.shortcut_max_iters >= 1):
            raise SuiteError(f"shortcut_max_iters must be an integer >= 1, got {self.shortcut_max_iters!r}")
        if not self.shortcut_reserve_s >= 0:
            raise SuiteError(f"shortcut_reserve_s must be >= 0 s, got {self.shortcut_reserve_s!r}")
        if self.time_limit_s is not None and not self.time_limit_s > 0:
            raise SuiteError(f"time_limit_s must be > 0 or None, got {self.time_limit_s!r}")


def roboplan_world(problem: PlanningProblem) -> tuple[RoboplanWorld, float]:
    """roboplan's scene of the problem's world (cached per process) and the measured cost of one
    of its state checks (s), from `CALIBRATION_CHECKS` configurations uniform in the limits."""
    world = collision_world(problem)
    key = (problem.world_key(), world.padding_m)
    hit = _SCENES.get(key)
    if hit is None:
        rw = build_roboplan_world(world)
        Q = world.robot.random_configurations(np.random.default_rng(0), CALIBRATION_CHECKS)
        has = rw.scene.hasCollisions
        t = time.perf_counter()
        for q in Q:
            has(q)
        hit = remember(_SCENES, key, (rw, (time.perf_counter() - t) / len(Q)), max_items=16)
    return hit


def edge_samples(nodes, step_rad: float) -> tuple[int, int]:
    """(edges, samples) of the edges kept in a tree: max(1, ceil(L2 length / step)) samples per
    edge (roboplan's steps of an edge, its end included; its start, a tree node, is re-checked
    too and not counted)."""
    if not nodes:
        return 0, 0
    C = np.array([n.config for n in nodes], float)
    parent = np.array([n.parent_id for n in nodes])
    child = parent >= 0
    d = np.linalg.norm(C[child] - C[parent[child]], axis=1)
    return int(child.sum()), int(np.maximum(1, np.ceil(d / step_rad)).sum())


def edge_checks(nodes, step_rad: float) -> int:
    """State checks of the edges kept in a tree: ceil(length / step) samples per edge (the
    checked samples of an edge at most `step_rad` apart, its end included)."""
    return edge_samples(nodes, step_rad)[1]


class RoboplanRRTPlanner(PlannerBase):
    """roboplan's RRT-Connect on the suite's model of the problem (see the module docstring)."""

    name: ClassVar[str] = "roboplan-rrt"
    Config: ClassVar[type] = RoboplanRRTConfig
    solver: ClassVar[str] = "roboplan.RRTConnect"
    # roboplan's own max connection distance (3.0) first, steps around it, and rrt's 1.0; always
    # shortcut, as rrt always simplifies (unshortcut paths return sooner but are 1.4 to 5.6 times
    # the reference length on the tune split, and the time objective alone would choose them)
    search_space: ClassVar[dict[str, tuple]] = {"range_rad": (3.0, 2.0, 1.0, 0.5)}

    def prepare(self, problem: PlanningProblem) -> None:
        """Build (or fetch) roboplan's scene of the problem's world, outside the clock."""
        roboplan_world(problem)

    def _options(self, budget_s: float) -> Any:
        cfg = self.config
        return rpr.RRTOptions(
            max_nodes=cfg.max_nodes,
            max_connection_distance=float(cfg.range_rad),
            collision_check_step_size=float(cfg.collision_check_step_rad),
            collision_check_use_bisection=cfg.use_bisection,
            goal_biasing_probability=float(cfg.goal_bias),
            max_planning_time=float(budget_s),
            rrt_connect=True,
            rrt_star=False,
            fast_return=True,
        )

    def solve(self, problem: PlanningProblem, world, budget: Budget) -> PlanResult:
        """Plan with roboplan's RRT-Connect from `problem.q_start` to `problem.q_goal` (both
        checked valid by the python-fcl world in `PlannerBase.plan`, as for every planner).
        roboplan times its search itself, on the wall clock (`max_planning_time`, a steady clock
        in its C++ loop): with a CPU budget it is given the CPU time left as wall time.

        Returns:
            SUCCESS with the (N, 7) path (rad); TIMEOUT when roboplan runs out of time;
            NO_SOLUTION when it hits its node cap; ERROR for any other failure roboplan reports.
        """
        cfg = self.config
        t0 = budget.now()
        rw, check_s = roboplan_world(problem)
        budget_s = cfg.time_limit_s if cfg.time_limit_s is not None else budget.deadline - t0
        search_s = budget_s - (budget.now() - t0) - (cfg.shortcut_reserve_s if cfg.shortcut else 0.0)
        seed = trial_seed(problem)
        stats: dict[str, Any] = {"solver": self.solver, "seed": seed, "range_rad": cfg.range_rad,
                                 "resolution_rad": cfg.collision_check_step_rad, "resolution_norm": "l2",
                                 "post_processing": (f"PathShortcutter({cfg.shortcut_max_iters})"
                                                     if cfg.shortcut else "none")}
        if search_s <= 0:
            return PlanResult(PlanStatus.TIMEOUT, None, {**stats, "reason": "no time left for the search",
                                                         "reason_code": FailureReason.BUDGET_SPENT.value})
        names = rw.scene.getJointNames()
        start = rpc.JointConfiguration(names, np.asarray(problem.q_start, float))
        goal = rpc.JointConfiguration(names, np.asarray(problem.q_goal, float))
        rrt = rpr.RRT(rw.scene, self._options(search_s))
        rrt.setRngSeed(seed)
        t_solve = time.perf_counter()
        try:
            path = rrt.plan(start, goal)
            error = None
        except RuntimeError as exc:
            path, error = None, str(exc)
        stats["solve_time_s"] = time.perf_counter() - t_solve
        t_count = time.perf_counter()
        trees = rrt.getNodes()
        stats["graph_vertices"] = sum(len(t) for t in trees)
        counted = [edge_samples(t, cfg.collision_check_step_rad) for t in trees]
        edges, checks = sum(e for e, _ in counted), sum(c for _, c in counted)
        stats.update(roboplan_checks_min=checks, roboplan_check_s=check_s, roboplan_query_s_min=checks * check_s,
                     tree_edges=edges, edge_samples=checks, samples_per_edge=checks / edges if edges else None,
                     samples_per_edge_from="computed",
                     count_time_s=time.perf_counter() - t_count)  # this bookkeeping, inside the clock
        if path is None:
            stats["reason"] = error
            if TIMEOUT_MESSAGE in error:
                return PlanResult(PlanStatus.TIMEOUT, None, {**stats, "reason_code": FailureReason.BUDGET_SPENT.value})
            if NODES_MESSAGE in error:
                return PlanResult(PlanStatus.NO_SOLUTION, None, {**stats, "reason_code": FailureReason.SEARCH_FAILED.value})
            return PlanResult(PlanStatus.ERROR, None, {**stats, "reason_code": FailureReason.PLANNER_ERROR.value})
        Q = np.array(path.positions, float).reshape(-1, 7)
        stats["waypoints_before"] = len(Q)
        stats["length_before_rad"] = float(np.sum(np.linalg.norm(np.diff(Q, axis=0), axis=1)))
        t_short = time.perf_counter()
        if cfg.shortcut and len(Q) > 2 and t_short - t0 < budget_s:
            shortcutter = rpc.PathShortcutter(rw.scene, rpc.PathShortcuttingOptions(
                max_step_size=float(cfg.collision_check_step_rad), max_iters=cfg.shortcut_max_iters,
                seed=int(seed & 0x7FFFFFFF)))
            Q = np.array(shortcutter.shortcut(path).positions, float).reshape(-1, 7)
        stats["simplify_time_s"] = time.perf_counter() - t_short
        stats["length_after_rad"] = float(np.sum(np.linalg.norm(np.diff(Q, axis=0), axis=1)))
        stats["waypoints"] = len(Q)
        return snapped_to_ends(problem, Q, stats)
