"""OMPL sampling-based planners in joint space: `rrt` (RRT-Connect), `rrtstar`, `bitstar`, `aorrtc`, `prm`.

Each plans on the arm's 7 joints with states and motions checked by the problem's python-fcl world
(`planners.ompl_adapter`: the state space, batched motion checks, per-trial seeding). The solution
is shortened by OMPL's PathSimplifier (by default its deterministic rope shortcut; optionally its
randomized `simplify` under a time budget) and, if it was planned at a coarser resolution,
re-checked at the validator's (0.01 rad) and planned again at that resolution if it fails. Only an
exact solution counts.

A trial's OMPL randomness depends on its seed alone (see `planners.ompl_adapter`). Only `rrt`
stops at its first solution, so only its path is reproducible; the optimizing planners run until
their time budget and their result depends on how far they get.

What they share (the settings of `OmplConfig`, the solve, the simplification and the re-check) is
`planners.ompl_solve`'s; each planner here adds its OMPL planner object, statistics and config.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from ompl import geometric as og

from planners.base import PlanResult, PlanStatus
from planners.ompl_solve import OmplConfig, OmplPlanner


# --- configuration: each planner's own, over OmplConfig's -----------------------------------------


@dataclasses.dataclass(frozen=True)
class RRTConnectConfig(OmplConfig):
    """RRT-Connect: stops at its first solution."""


@dataclasses.dataclass(frozen=True)
class RRTstarConfig(OmplConfig):
    """RRT*: path-length objective, runs to its budget.

    Attributes:
        rewire_factor: OMPL's rewiring radius factor.
        goal_bias: probability of sampling the goal (OMPL's default 0.05).
    """

    # Optimized paths run along obstacles: checked at the validator's resolution from the start.
    resolution_rad: float = 0.01

    rewire_factor: float = 1.1
    goal_bias: float = 0.05


@dataclasses.dataclass(frozen=True)
class BITstarConfig(OmplConfig):
    """BIT*: path-length objective, runs to its budget.

    Attributes:
        samples_per_batch: samples drawn per batch.
    """

    # Optimized paths run along obstacles: checked at the validator's resolution from the start.
    resolution_rad: float = 0.01

    samples_per_batch: int = 100


@dataclasses.dataclass(frozen=True)
class AORRTCConfig(OmplConfig):
    """AORRTC (asymptotically optimal RRT-Connect): path-length objective, runs to its budget."""

    # Optimized paths run along obstacles: checked at the validator's resolution from the start.
    resolution_rad: float = 0.01


@dataclasses.dataclass(frozen=True)
class PRMConfig(OmplConfig):
    """PRM: path-length objective, grows its roadmap until its budget.

    Attributes:
        max_nearest_neighbors: how many neighbours a new milestone tries to connect to.
    """

    # Optimized paths run along obstacles: checked at the validator's resolution from the start.
    resolution_rad: float = 0.01

    max_nearest_neighbors: int = 10


# --- the planners ----------------------------------------------------------------------------------


def _certified_if_asked(cfg: OmplConfig, world, Q: np.ndarray) -> bool:
    """True unless `cfg` asks for certified motions and the exact check does not certify path Q."""
    if cfg.motion_check != "certified":
        return True
    from scenes.collision.certify import CERTIFIED, certifier

    return certifier(world).certify(Q).verdict == CERTIFIED


class RRTConnectPlanner(OmplPlanner):
    """OMPL RRT-Connect (the paper's baseline planner): the first solution, then simplification."""

    name = "rrt"
    Config = RRTConnectConfig
    solver = "RRTConnect"
    optimizing = False
    # None: OMPL's own range (a fifth of the space's extent, about 2.8 rad here), and steps around it
    search_space = {"range_rad": (None, 2.0, 1.0, 0.5), "simplifier": ("rope", "rope+full")}

    def _make(self, si):
        p = og.RRTConnect(si)
        if self.config.range_rad is not None:
            p.setRange(self.config.range_rad)
        return p


class RRTstarPlanner(OmplPlanner):
    """OMPL RRT* with the path-length objective, run to its budget."""

    name = "rrtstar"
    Config = RRTstarConfig
    solver = "RRTstar"
    search_space = {"range_rad": (None, 1.0, 0.5, 0.25), "goal_bias": (0.05, 0.2)}
    tuning_objective = "length"

    def _make(self, si):
        p = og.RRTstar(si)
        if self.config.range_rad is not None:
            p.setRange(self.config.range_rad)
        p.setRewireFactor(self.config.rewire_factor)
        p.setGoalBias(self.config.goal_bias)
        return p

    def _planner_stats(self, planner):
        return {"iterations": planner.numIterations()}


class BITstarPlanner(OmplPlanner):
    """OMPL BIT* with the path-length objective, run to its budget."""

    name = "bitstar"
    Config = BITstarConfig
    solver = "BITstar"
    graph_stats = False
    search_space = {"samples_per_batch": (100, 400), "range_rad": (None, 1.0)}
    tuning_objective = "length"

    def _make(self, si):
        p = og.BITstar(si)
        p.setSamplesPerBatch(self.config.samples_per_batch)
        p.setConsiderApproximateSolutions(False)
        return p

    def _planner_stats(self, planner):
        return {"iterations": planner.numIterations(), "batches": planner.numBatches()}


class AORRTCPlanner(OmplPlanner):
    """OMPL AORRTC (asymptotically optimal RRT-Connect) with the path-length objective, run to its
    budget."""

    name = "aorrtc"
    Config = AORRTCConfig
    solver = "AORRTC"
    graph_stats = False
    resumable = False
    search_space = {"range_rad": (None, 1.0, 0.5)}
    tuning_objective = "length"

    def _attempt(self, problem, world, *, resolution_rad, budget_s, seed):
        # OMPL 2.0.1's AORRTC reports a failure ("Zero-length path found") when its trees connect
        # start and goal directly; a free straight motion is that optimal path, checked here first.
        Q = np.stack([np.asarray(problem.q_start, float), np.asarray(problem.q_goal, float)])
        if world.motion_free(*Q, resolution_rad=resolution_rad) and _certified_if_asked(self.config, world, Q):
            return PlanResult(PlanStatus.SUCCESS, Q, {"solver": self.solver, "resolution_rad": resolution_rad,
                                                      "motion_check": self.config.motion_check,
                                                      "direct": True, "progress": []})
        return super()._attempt(problem, world, resolution_rad=resolution_rad, budget_s=budget_s, seed=seed)

    def _make(self, si):
        p = og.AORRTC(si)
        if self.config.range_rad is not None:
            p.setRange(self.config.range_rad)
        return p


class PRMPlanner(OmplPlanner):
    """OMPL PRM with the path-length objective: grows its roadmap until its budget."""

    name = "prm"
    Config = PRMConfig
    solver = "PRM"
    search_space = {"max_nearest_neighbors": (10, 20), "range_rad": (None, 1.0)}
    tuning_objective = "length"

    def _make(self, si):
        p = og.PRM(si)
        p.setMaxNearestNeighbors(self.config.max_nearest_neighbors)
        return p

    def _planner_stats(self, planner):
        return {"milestones": planner.milestoneCount(), "roadmap_edges": planner.edgeCount()}
