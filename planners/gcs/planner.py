"""`gcs`: motion planning with graphs of convex sets (Drake's GcsTrajectoryOptimization).

Marcucci et al., "Motion planning around obstacles with convex optimization" (Science Robotics
2023). The configuration space is covered by collision-free convex regions (sampled IRIS, see
`planners.gcs.regions`), built offline once per collision world from the world alone (its task
chain, `planners.gcs.cover`; `seeding`) and cached on disk; `prepare` loads them (or builds them
on a miss) before the trial's clock starts, and their build time is reported as
`stats.offline_s`, never as planning time.

Online (planning time), start and goal are joined to the regions: an end no region holds is
joined by a straight segment, free in the python-fcl world, to a point just inside the nearest
region it can reach (`planners.gcs.solve.join_endpoint`); if none, the trial is NO_SOLUTION with
`regions_disconnected`. Then one Bezier curve per visited region (order 1 by default: straight
segments, so the cost is exactly the joint-space path length) between the joined ends, joined
where regions intersect; the shortest path is found by the convex relaxation of the
mixed-integer program followed by randomized rounding and a convex restriction on each rounded
path, solved by Clarabel (ships with Drake). The time-free path is the curve sampled densely,
with the joining segments at its ends; the suite times it with TOPP-RA. Sampled IRIS regions are
not certified collision-free: the path is checked with the python-fcl world at the validator's
resolution, and where it collides that configuration is cut off (in-memory copies of) the regions
holding it and GCS is solved again (`max_repairs`, planning time); a path still colliding after
`max_repairs` is NO_SOLUTION, and repairs stopped by the planning budget are TIMEOUT. With
`max_repairs=0` the path is returned unchecked and the suite's validator judges it (a collision
is `invalid_solution`), as it judges every planner's path anyway.

Building regions inside a `compare` trial counts against the trial's hard limit (3 x budget +
30 s): build them ahead with `python -m suite regions build --dataset NAME`.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from typing import ClassVar

import numpy as np

from planners.base import Budget, FailureReason, PlannerBase, PlanningProblem, PlanResult, PlanStatus
from planners.gcs.iris import RegionBuilder
from planners.gcs.regions import regions_for
from planners.gcs.sets import RegionOptions, RegionSet, problem_hash
from planners.gcs.solve import SOLVERS, check_with_world, checked_path, connect_ends
from planners.worlds import remember
from scenes.errors import SuiteError

log = logging.getLogger(__name__)

#: The online fallback region around an end no segment joins: IrisZo, one alternation, few
#: particles (about a second), the Drake checker's padding as offline.
ONLINE_OPTIONS = RegionOptions(iris="zo", num_particles=100, max_iterations=1, check_rounds=1, check_samples=100)


@dataclasses.dataclass(frozen=True)
class GcsConfig(RegionOptions):
    """Settings of `gcs`: the region options (see `planners.gcs.sets.RegionOptions`) and:

    Attributes:
        order: Bezier order per region (1: straight segments, the shortest path).
        max_rounded_paths: paths drawn by randomized rounding of the relaxation.
        solver: "clarabel" or "scs" (convex solvers that ship with Drake).
        sample_step_rad: largest joint-space L2 step between returned waypoints inside a curved
            segment (order > 1); straight segments return their ends.
        max_repairs: online repairs: the path is checked with the python-fcl world at
            `check_resolution_rad` (as the validator checks it); where it collides, the colliding
            configuration is cut off the regions holding it and GCS is solved again (planning
            time, in-memory copies only). 0 returns the first rounded path unchecked.
        check_resolution_rad: joint resolution of that check (rad).
        regions_dir: the region cache read first and written by on-demand builds; "" for
            `results/regions/` (datasets' `regions/` directories are read too).
        build_regions: build missing regions in `prepare` (offline); otherwise a world without
            cached regions is NO_SOLUTION.
        online_iris: when no free straight segment joins an end to the regions, grow one small
            `IrisZo` region around that end online (planning time; its Drake collision checker
            is built in `prepare`, from the world alone) and join again; False to fail at once.
    """

    order: int = 1
    max_rounded_paths: int = 5
    solver: str = "clarabel"
    sample_step_rad: float = 0.02
    max_repairs: int = 5
    check_resolution_rad: float = 0.01
    regions_dir: str = ""
    build_regions: bool = True
    online_iris: bool = True

    def __post_init__(self):
        super().__post_init__()
        if self.order < 1:
            raise SuiteError(f"gcs order={self.order!r} must be >= 1")
        if self.max_rounded_paths < 1:
            raise SuiteError(f"gcs max_rounded_paths={self.max_rounded_paths!r} must be >= 1")
        if self.solver not in SOLVERS:
            raise SuiteError(f"gcs solver={self.solver!r}; allowed: {', '.join(SOLVERS)}")
        if not self.sample_step_rad > 0:
            raise SuiteError(f"gcs sample_step_rad={self.sample_step_rad!r} must be positive")

    def region_options(self) -> RegionOptions:
        names = {f.name for f in dataclasses.fields(RegionOptions)}
        return RegionOptions(**{k: v for k, v in dataclasses.asdict(self).items() if k in names})


class GcsPlanner(PlannerBase):
    """Shortest paths through cached IRIS regions with Drake's GcsTrajectoryOptimization."""

    name: ClassVar[str] = "gcs"
    Config: ClassVar[type] = GcsConfig
    #: The region seeding and IRIS's iteration limit (with the paper's thresholds: off, 2%), and the
    #: rounded paths. `order` left the search when `max_iterations` joined it (the grid stays at 8):
    #: order 3 solved and measured exactly as order 1 in both tunes that tried it (recycle-v3.1,
    #: 2026-11-27: 94/115 and the same length ratios).
    search_space: ClassVar[dict[str, tuple]] = {"seeding": ("chain", "cliques"), "max_iterations": (1, 10),
                                                "max_rounded_paths": (5, 10)}
    #: Left out of the product, with the reason (`suite.cli.tune.grid`).
    search_exclude: ClassVar[tuple] = (
        ({"seeding": "cliques", "max_iterations": 10},
         "the clique cover at one IRIS iteration already builds a window world in 194 s median, 313 s p90 on the "
         "tune sample (2026-11-27), over the offline bound; ten iterations cost more per region, so its regions "
         "were not grown"),
    )
    #: The bound on the offline seconds per world at p90 that a tuned default must meet: a user builds
    #: the regions (`suite.report.tuning`, step -1).
    offline_bound_s: ClassVar[float] = 120.0
    tuning_objective: ClassVar[str] = "length"

    def __init__(self, config: GcsConfig | None = None) -> None:
        super().__init__(config)
        self._regions: dict[tuple, tuple[RegionSet | None, dict]] = {}
        self._online: dict[tuple, object] = {}  # world -> RegionBuilder of online IrisZo regions

    def _key(self, problem: PlanningProblem) -> tuple:
        if self.config.seeding != "problem":  # one set per world, whatever the problem
            return (problem.world_key(),)
        return (problem.world_key(), problem_hash(problem))

    def prepare(self, problem: PlanningProblem) -> None:
        """Load (or build, offline) the regions of the problem's world before the clock starts."""
        key = self._key(problem)
        if key in self._regions or problem.pre_status is not None or problem.q_goal is None:
            return
        t0 = time.perf_counter()
        rs, info = regions_for(problem, self.config.region_options(), cache_dir=self.config.regions_dir or None,
                               build=self.config.build_regions)
        info["prepare_s"] = time.perf_counter() - t0
        remember(self._regions, key, (rs, info), max_items=16)
        if self.config.online_iris and self.config.seeding != "problem" and problem.world_key() not in self._online:
            remember(self._online, problem.world_key(), RegionBuilder(problem, ONLINE_OPTIONS), max_items=4)

    def solve(self, problem: PlanningProblem, world, budget: Budget) -> PlanResult:
        cfg = self.config
        key = self._key(problem)
        if key not in self._regions:  # called without prepare (e.g. directly): regions are still offline cost
            t_off = time.perf_counter()
            self.prepare(problem)
            log.info("gcs built/loaded regions inside plan() in %.1f s (offline_s)", time.perf_counter() - t_off)
        t0 = time.perf_counter()
        rs, info = self._regions[key]
        stats: dict = {
            "solver": cfg.solver.capitalize() if cfg.solver != "scs" else "SCS",
            "iris": cfg.iris,
            "world_hash": info["world_hash"],
            "regions_cache": info["cache"],
            "regions_added": info["regions_added"],
            "num_regions": 0 if rs is None else len(rs),
            "offline_s": 0.0 if rs is None else rs.offline_s,
            "offline_cpu_s": None if rs is None else rs.offline_cpu_s,
        }
        if rs is None or len(rs) == 0:
            stats["reason"] = "no regions for this world"
            stats["reason_code"] = FailureReason.REGIONS_MISSING.value
            return PlanResult(PlanStatus.NO_SOLUTION, None, stats)
        q_start = np.asarray(problem.q_start, float)
        q_goal = np.asarray(problem.q_goal, float)
        A, b = list(rs.A), list(rs.b)  # repairs cut these copies, not the cached set
        edges = list(rs.edges)
        # Online (planning time): join start and goal to the world's regions by free straight
        # segments where no region holds them.
        joined = connect_ends(A, b, edges, q_start, q_goal, world=world, resolution_rad=cfg.check_resolution_rad,
                              budget=budget)
        seeds = list(rs.seeds)
        stats["online_regions"] = 0
        builder = self._online.get(problem.world_key()) if cfg.online_iris else None
        for name, q in (("start", q_start), ("goal", q_goal)):
            if joined[f"{name}_join"] != "none" or builder is None or budget.expired():
                continue
            if _grow_online(A, b, edges, seeds, q, builder=builder, world=world):
                stats["online_regions"] += 1
        if stats["online_regions"]:
            joined = connect_ends(A, b, edges, q_start, q_goal, world=world,
                                  resolution_rad=cfg.check_resolution_rad, budget=budget)
        gcs_ends = joined.pop("ends")
        stats["regions_connected"] = joined.pop("connected")
        stats.update(joined)
        stats["join_s"] = time.perf_counter() - t0
        if not stats["regions_connected"]:
            unjoined = [n for n in ("start", "goal") if stats[f"{n}_join"] == "none"]
            stats["reason"] = (f"no free straight segment joins the {unjoined[0]} to the regions" if unjoined
                               else "the regions do not connect start and goal")
            stats["reason_code"] = FailureReason.REGIONS_DISCONNECTED.value
            stats["solve_time_s"] = time.perf_counter() - t0
            return PlanResult(PlanStatus.NO_SOLUTION, None, stats)

        path, solve_stats = checked_path(
            A, b, edges, seeds, gcs_ends[0], gcs_ends[1], world=world, order=cfg.order,
            max_rounded_paths=cfg.max_rounded_paths, solver=cfg.solver, seed=problem.seed,
            max_repairs=cfg.max_repairs, check_resolution_rad=cfg.check_resolution_rad,
            sample_step_rad=cfg.sample_step_rad, budget=budget)
        if path is not None:  # the joining segments, checked free above
            path = np.vstack([[q_start]] * (stats["start_join"] == "segment") + [path]
                             + [[q_goal]] * (stats["goal_join"] == "segment"))
        stats.update(solve_stats)
        stats["solve_time_s"] = time.perf_counter() - t0
        if path is None:
            status = PlanStatus.TIMEOUT if stats.get("timed_out") else PlanStatus.NO_SOLUTION
            if status is PlanStatus.TIMEOUT:
                stats["reason_code"] = FailureReason.BUDGET_SPENT.value
            elif str(stats.get("reason", "")).startswith(("GCS failed", "the solution does not join")):
                stats["reason_code"] = FailureReason.SOLVER_FAILED.value
            else:
                stats["reason_code"] = FailureReason.PATH_STILL_COLLIDES.value
            return PlanResult(status, None, stats)
        stats["waypoints"] = len(path)
        return PlanResult(PlanStatus.SUCCESS, path, stats)


def _grow_online(A: list, b: list, edges: list, seeds: list, q: np.ndarray, *, builder, world) -> bool:
    """Grow one IrisZo region around q (planning time), check it with the python-fcl world, and
    add it to A, b, seeds with its intersection edges (in place). False if IRIS fails."""
    from pydrake.geometry.optimization import HPolyhedron

    grown = builder.grow(q)
    if grown is None:
        return False
    Ai, bi, _, _ = grown
    o = builder.options
    Ai, bi, _ = check_with_world(Ai, bi, world=world, center=q, keep=[q], samples=o.check_samples,
                                 rounds=o.check_rounds, margin_rad=o.configuration_space_margin_rad, seed=o.random_seed)
    new = HPolyhedron(Ai, bi)
    k = len(A)
    for j in range(k):
        if new.IntersectsWith(HPolyhedron(A[j], b[j])):
            edges += [(k, j), (j, k)]
    A.append(Ai)
    b.append(bi)
    seeds.append(np.asarray(q, float))
    return True
