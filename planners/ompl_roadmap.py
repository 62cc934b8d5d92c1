"""`prm-roadmap`: a PRM queried on a fixed roadmap that OMPL's PRM built offline, once per world.

This is the PRM of the GCS paper's comparison (Marcucci et al. 2023, "GCS vs PRM"): a roadmap of
`roadmap_size` milestones, each joined to its `max_nearest_neighbors` nearest by motions checked
free, built before any query and reported as offline cost (`stats.offline_s`, like `gcs`'s
regions); a query joins its start and goal to the roadmap and searches it. With
`simplify_time_s` > 0 the path is then shortened by OMPL's PathSimplifier (the paper's "shortcut
PRM"), inside the query's time.

Build (offline): OMPL's `PRM.growRoadmap` on the world's python-fcl checks, until the roadmap has
`roadmap_size` milestones. Its first milestones are, as in the paper's code, the states of
RRT-Connect paths between every pair of the scene's hand-placed seeds
(`SceneSpec.region_seeds`, the same seeds `gcs` grows its regions from; none for a scene without
them), fed to PRM by its valid-state sampler before the uniform samples. The roadmap (milestones,
edges, build time) is then stored as data: `roadmaps/` of a dataset, or results/roadmaps/, under
the hash of the world and these settings, and loaded by later processes.

Query (planning time): the start and the goal are each joined to their `max_nearest_neighbors`
nearest milestones by motions the world finds free, and the shortest path (Dijkstra, joint-space
length) is searched on that graph. The stored roadmap itself never changes: OMPL's own
`PRM.solve` would keep every query's start and goal, and grow the roadmap, for later queries, so
repeated and reversed queries would get easier; the paper's planner did not. A start or goal
that joins no milestone, or a roadmap that does not link them, is NO_SOLUTION.

States and motions are checked at `resolution_rad` (0.01 rad, the validator's; the paper's 0.05
rad edges were checked on a voxelized world, whose voxels grow the obstacles); the path is re-checked at the validator's resolution, and one that fails there is
NO_SOLUTION (`path_still_collides`): the roadmap is fixed, there is nothing to plan again.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import json
import logging
import time
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from planners.base import Budget, FailureReason, PlannerBase, PlanningProblem, PlanResult, PlanStatus, snapped_to_ends
from planners.worlds import remember
from scenes.errors import SuiteError

log = logging.getLogger(__name__)

FORMAT_VERSION = 1
#: Roadmaps built on demand (results/ is generated output); datasets may carry `roadmaps/`.
DEFAULT_CACHE_DIR = Path(__file__).resolve().parents[1] / "results" / "roadmaps"
#: Spacing of the seed paths' states fed to the roadmap (the paper's BiRRT step, rad).
SEED_PATH_STEP_RAD = 0.1
#: RRT-Connect's budget per pair of seeds (s).
SEED_RRT_S = 5.0


@dataclasses.dataclass(frozen=True)
class PRMRoadmapConfig:
    """Settings of `prm-roadmap`.

    Attributes:
        roadmap_size: milestones of the offline roadmap (the paper: 10,000 in its final code,
            15,000 in the arXiv version).
        max_nearest_neighbors: neighbours a milestone, and a query's start and goal, are joined
            to (the paper: 5).
        resolution_rad: largest joint step between checked samples of a motion (rad): the
            validator's 0.01 (the paper's 0.05 rad edge steps were checked against 4 cm voxels,
            which grow the obstacles; on the exact geometry 0.05 rad steps clip corners).
        validate_resolution_rad: the path is re-checked at this resolution (the validator's).
        seed_paths: start the roadmap with RRT-Connect paths between the scene's seeds.
        simplify_time_s: OMPL's PathSimplifier.simplify budget after a query (s); 0: the plain
            roadmap path.
        roadmap_seed: OMPL's seed for the roadmap (one roadmap per world, whatever the trial).
        roadmap_dir: the roadmap cache read first and written by builds; "" for results/roadmaps/
            (datasets' `roadmaps/` directories are read too).
    """

    roadmap_size: int = 10000
    max_nearest_neighbors: int = 5
    resolution_rad: float = 0.01
    validate_resolution_rad: float = 0.01
    seed_paths: bool = True
    simplify_time_s: float = 0.0
    roadmap_seed: int = 1
    roadmap_dir: str = ""

    def __post_init__(self) -> None:
        if self.roadmap_size < 10:
            raise SuiteError(f"prm-roadmap roadmap_size={self.roadmap_size!r} must be >= 10")
        if self.max_nearest_neighbors < 1:
            raise SuiteError(f"prm-roadmap max_nearest_neighbors={self.max_nearest_neighbors!r} must be >= 1")
        if not 0 < self.resolution_rad <= 0.2:
            raise SuiteError(f"prm-roadmap resolution_rad={self.resolution_rad!r} must be in (0, 0.2]")
        if not self.simplify_time_s >= 0:
            raise SuiteError(f"prm-roadmap simplify_time_s={self.simplify_time_s!r} must be >= 0")
        if not 1 <= self.roadmap_seed < 2**32:
            raise SuiteError(f"prm-roadmap roadmap_seed={self.roadmap_seed!r} must be in [1, 2**32)")

    def key_fields(self) -> dict:
        """The fields that decide the roadmap (what a query does with it does not)."""
        return {k: getattr(self, k) for k in ("roadmap_size", "max_nearest_neighbors", "resolution_rad",
                                              "seed_paths", "roadmap_seed")}


@dataclasses.dataclass
class Roadmap:
    """A fixed roadmap: milestones (N, 7) rad, undirected edges (E, 2) with their lengths (E,),
    how long it took to build (s) and how it was seeded."""

    key: str
    milestones: np.ndarray
    edges: np.ndarray
    offline_s: float
    seeded: int  # milestones fed from the seed paths

    def save(self, path: Path) -> None:
        from planners.gcs.sets import save_npz_atomically

        save_npz_atomically(path, milestones=self.milestones, edges=self.edges,
                            meta=json.dumps({"format": FORMAT_VERSION, "key": self.key, "offline_s": self.offline_s,
                                             "seeded": self.seeded}))

    @classmethod
    def load(cls, path: Path) -> "Roadmap":
        with np.load(path) as z:
            meta = json.loads(str(z["meta"]))
            if meta.get("format") != FORMAT_VERSION:
                raise SuiteError(f"roadmap {path}: format {meta.get('format')!r}, this suite reads {FORMAT_VERSION}")
            return cls(meta["key"], z["milestones"], z["edges"], float(meta["offline_s"]), int(meta["seeded"]))

    @functools.cached_property
    def edge_lengths(self) -> np.ndarray:
        """Each edge's joint-space length (E,), computed once (a query only adds its joins)."""
        return np.linalg.norm(self.milestones[self.edges[:, 0]] - self.milestones[self.edges[:, 1]], axis=1)

    def graph(self, extra: list[tuple[int, int]] = (), n_extra: int = 0, points: np.ndarray | None = None):
        """The roadmap as a symmetric sparse matrix of edge lengths, with `n_extra` more nodes
        (at `points`) joined by the `extra` edges."""
        from scipy.sparse import coo_matrix

        n = len(self.milestones) + n_extra
        all_points = self.milestones if points is None else np.vstack([self.milestones, points])
        x = np.asarray(extra, int).reshape(-1, 2)
        e = np.concatenate([self.edges.reshape(-1, 2), x])
        w = np.concatenate([self.edge_lengths, np.linalg.norm(all_points[x[:, 0]] - all_points[x[:, 1]], axis=1)])
        w = np.maximum(w, 1e-12)  # a zero weight would read as no edge
        return coo_matrix((np.concatenate([w, w]), (np.concatenate([e[:, 0], e[:, 1]]),
                                                     np.concatenate([e[:, 1], e[:, 0]]))), shape=(n, n)).tocsr()


def roadmap_key(problem: PlanningProblem, cfg: PRMRoadmapConfig) -> str:
    """The hash of the problem's collision world and the roadmap's settings."""
    from planners.gcs.sets import world_hash

    return world_hash(problem, cfg)


def seed_path_states(problem: PlanningProblem) -> list[np.ndarray]:
    """The states, SEED_PATH_STEP_RAD apart, of RRT-Connect paths (unsimplified, the scene's fixed
    seed) between every pair of the scene's hand-placed seeds; none without seeds."""
    from planners.gcs.cover import scene_seeds
    from planners.ompl_rrt import RRTConnectConfig, RRTConnectPlanner
    from planners.worlds import collision_world

    if problem.scene.spec.region_seeds is None:
        return []
    named, _ = scene_seeds(problem)
    world = collision_world(problem)
    planner = RRTConnectPlanner(RRTConnectConfig(simplify_time_s=0.0))
    out: list[np.ndarray] = []
    for k, ((_, a), (_, b)) in enumerate(itertools.combinations(named, 2)):
        r = planner.plan(problem.with_(q_start=a, q_goal=b, time_limit_s=SEED_RRT_S, seed=1000 + k, pre_status=None))
        if r.path is not None:
            out += list(world.interpolate(np.asarray(r.path, float), SEED_PATH_STEP_RAD))
    return out


def build_roadmap(problem: PlanningProblem, cfg: PRMRoadmapConfig, key: str) -> Roadmap:
    """Grow OMPL's PRM in the problem's world to `roadmap_size` milestones (the seed paths'
    states first) and read its graph out."""
    from ompl import base as ob
    from ompl import geometric as og

    from planners.ompl_adapter import DOF, OmplProblem, reseed_ompl, set_ompl_log_level
    from planners.worlds import planning_world

    set_ompl_log_level(False)
    t0 = time.perf_counter()
    world = planning_world(problem)
    queue = seed_path_states(problem) if cfg.seed_paths else []
    reseed_ompl(cfg.roadmap_seed)
    op = OmplProblem(world, problem.q_start, problem.q_start, resolution_rad=cfg.resolution_rad, optimizing=True)

    class SeededSampler(ob.ValidStateSampler):
        """The seed paths' states, then uniform valid samples (OMPL's PRM draws its milestones here)."""

        def __init__(self, si):
            super().__init__(si)
            self.uniform = ob.UniformValidStateSampler(si)
            self.next = 0

        def sample(self, state):
            if self.next < len(queue):
                q = queue[self.next]
                self.next += 1
                state[0:DOF] = [float(v) for v in q]
                return True
            return self.uniform.sample(state)

        def sampleNear(self, state, near, distance):
            return self.uniform.sampleNear(state, near, distance)

    op.si.setValidStateSamplerAllocator(lambda si: SeededSampler(si))
    prm = og.PRM(op.si)
    prm.setMaxNearestNeighbors(cfg.max_nearest_neighbors)
    op.attach(prm)
    while prm.milestoneCount() < cfg.roadmap_size:
        prm.growRoadmap(0.25)
    data = ob.PlannerData(op.si)
    prm.getPlannerData(data)
    n = data.numVertices()
    milestones = np.array([data.getVertex(i).getState()[0:DOF] for i in range(n)], float).reshape(n, DOF)
    edges = sorted({(min(i, j), max(i, j)) for i in range(n) for j in data.getEdges(i)})
    del data, prm
    op.release()
    rm = Roadmap(key, milestones, np.asarray(edges, int).reshape(-1, 2), time.perf_counter() - t0, len(queue))
    log.info("prm-roadmap: %d milestones (%d from seed paths), %d edges in %.1f s", n, len(queue), len(edges),
             rm.offline_s)
    return rm


def roadmap_for(problem: PlanningProblem, cfg: PRMRoadmapConfig) -> tuple[Roadmap, str]:
    """The world's roadmap from the cache, or built and stored; with "hit" or "built"."""
    from planners.gcs.sets import find_cached

    key = roadmap_key(problem, cfg)
    path = find_cached(key, cfg.roadmap_dir, default=DEFAULT_CACHE_DIR, subdir="roadmaps")
    if path is not None:
        return Roadmap.load(path), "hit"
    rm = build_roadmap(problem, cfg, key)
    rm.save((Path(cfg.roadmap_dir) if cfg.roadmap_dir else DEFAULT_CACHE_DIR) / f"{key}.npz")
    return rm, "built"


class PRMRoadmapPlanner(PlannerBase):
    """Queries on a fixed roadmap built offline by OMPL's PRM (see the module docstring)."""

    name: ClassVar[str] = "prm-roadmap"
    Config: ClassVar[type] = PRMRoadmapConfig
    solver: ClassVar[str] = "PRM (fixed roadmap)"
    #: the paper's two generations (10,000 milestones in its final code, 15,000 in the arXiv
    #: version) and OMPL's default neighbours; not tuned: the paper's experiment runs its settings
    search_space: ClassVar[dict[str, tuple]] = {"roadmap_size": (10000, 15000), "max_nearest_neighbors": (5, 10)}
    tuning_objective: ClassVar[str] = "length"

    def __init__(self, config: PRMRoadmapConfig | None = None) -> None:
        super().__init__(config)
        self._roadmaps: dict[tuple, tuple[Roadmap, str]] = {}

    def prepare(self, problem: PlanningProblem) -> None:
        """Load (or build, offline) the world's roadmap before the trial's clock starts."""
        key = problem.world_key()
        if key in self._roadmaps or problem.pre_status is not None or problem.q_goal is None:
            return
        remember(self._roadmaps, key, roadmap_for(problem, self.config), max_items=2)

    def solve(self, problem: PlanningProblem, world, budget: Budget) -> PlanResult:
        from scipy.sparse.csgraph import dijkstra

        cfg = self.config
        if problem.world_key() not in self._roadmaps:  # called without prepare: still offline cost
            self.prepare(problem)
        rm, cache = self._roadmaps[problem.world_key()]
        t0 = time.perf_counter()
        checks0 = world.checks
        stats: dict[str, Any] = {"offline_s": rm.offline_s, "roadmap_cache": cache, "milestones": len(rm.milestones),
                                 "roadmap_edges": len(rm.edges), "seeded_milestones": rm.seeded,
                                 "resolution_rad": cfg.resolution_rad}
        ends = np.stack([np.asarray(problem.q_start, float), np.asarray(problem.q_goal, float)])
        n = len(rm.milestones)
        extra: list[tuple[int, int]] = []
        if world.motion_free(ends[0], ends[1], resolution_rad=cfg.resolution_rad):
            extra.append((n, n + 1))
        joined = []
        for k, q in enumerate(ends):
            d = np.linalg.norm(rm.milestones - q, axis=1)
            near = np.argsort(d)[: cfg.max_nearest_neighbors]
            links = [int(i) for i in near if world.motion_free(q, rm.milestones[i], resolution_rad=cfg.resolution_rad)]
            extra += [(n + k, i) for i in links]
            joined.append(len(links))
            if budget.expired():
                stats.update(query_s=time.perf_counter() - t0, reason_code=FailureReason.BUDGET_SPENT.value)
                return PlanResult(PlanStatus.TIMEOUT, None, stats)
        stats["start_links"], stats["goal_links"] = joined
        graph = rm.graph(extra, 2, ends)
        dist, pred = dijkstra(graph, indices=n, return_predecessors=True)
        stats["collision_checks"] = world.checks - checks0
        if not np.isfinite(dist[n + 1]):
            stats["query_s"] = time.perf_counter() - t0
            stats["reason"] = ("the start or the goal joins no milestone" if 0 in joined
                               else "the roadmap does not link the start and the goal")
            stats["reason_code"] = FailureReason.SEARCH_FAILED.value
            return PlanResult(PlanStatus.NO_SOLUTION, None, stats)
        order = [n + 1]
        while order[-1] != n:
            order.append(int(pred[order[-1]]))
        points = np.vstack([rm.milestones, ends])
        Q = points[order[::-1]]
        stats["length_before_rad"] = float(np.sum(np.linalg.norm(np.diff(Q, axis=0), axis=1)))
        stats["query_s"] = time.perf_counter() - t0
        t_simp = time.perf_counter()
        left = min(cfg.simplify_time_s, budget.left_s())
        if cfg.simplify_time_s > 0 and left > 0:
            Q = _simplified(Q, world, cfg.resolution_rad, left, clock=budget.clock)
        stats["simplify_time_s"] = time.perf_counter() - t_simp
        bad = world.path_free(Q, resolution_rad=cfg.validate_resolution_rad)
        stats["collision_checks"] = world.checks - checks0
        if bad >= 0:
            stats["reason"] = f"the roadmap path collides at {cfg.validate_resolution_rad} rad resolution"
            stats["reason_code"] = FailureReason.PATH_STILL_COLLIDES.value
            return PlanResult(PlanStatus.NO_SOLUTION, None, stats)
        stats["waypoints"] = len(Q)
        return snapped_to_ends(problem, np.asarray(Q, float), stats)


def _simplified(Q: np.ndarray, world, resolution_rad: float, budget_s: float, *, clock: str = "wall") -> np.ndarray:
    """OMPL's PathSimplifier.simplify (shortcuts, smoothing, vertex reduction) on path Q in the
    world, within `budget_s` on budget clock `clock`."""
    from ompl import geometric as og

    from planners.ompl_adapter import DOF, OmplProblem, drop_collinear, path_array
    from planners.ompl_budget import termination

    op = OmplProblem(world, Q[0], Q[-1], resolution_rad=resolution_rad, optimizing=False)
    path = og.PathGeometric(op.si)
    states = []
    try:
        for q in Q:
            s = op.si.allocState()
            s[0:DOF] = [float(v) for v in q]
            states.append(s)
            path.append(s)
        simplifier = og.PathSimplifier(op.si)
        simplifier.simplify(path, termination(clock, budget_s))
        out = drop_collinear(path_array(path))
    finally:
        del path, states
        op.planner = None
        op.pdef.clearSolutionPaths()
        del op
    return out


@dataclasses.dataclass(frozen=True)
class ShortcutPRMRoadmapConfig(PRMRoadmapConfig):
    """`prm-roadmap`'s settings with the path shortened after each query (the paper's
    "shortcut PRM"): OMPL's `PathSimplifier.simplify` for up to `simplify_time_s`."""

    simplify_time_s: float = 1.0


class ShortcutPRMRoadmapPlanner(PRMRoadmapPlanner):
    """`prm-roadmap` with the query's path shortened by OMPL's PathSimplifier (planning time)."""

    name: ClassVar[str] = "prm-roadmap-shortcut"
    Config: ClassVar[type] = ShortcutPRMRoadmapConfig
    solver: ClassVar[str] = "PRM (fixed roadmap) + PathSimplifier"
