"""Collision-free convex regions of the arm's configuration space for `gcs`, cached on disk.

Regions are grown with Drake's sampled IRIS (`IrisNp2` by default, `IrisZo` as an option) on the
plan-mode Drake scene of a problem's collision world (`scenes.drake_scene.add_scene_to_plant`, in a
`RobotDiagramBuilder` because the collision checker needs a `RobotDiagram`): the held can and the
finger opening are part of the robot, removed cans are gone.

Seeding. By default from the world alone (`seeding` "chain" or "cliques", `planners.gcs_cover`,
`grow_for_world`): no problem's start, goal or path enters the regions, and joining a problem's
ends to them is `gcs`'s online work. The earlier rule, `seeding: problem` (kept to reproduce its
figures), seeds per problem of the world (offline, before any trial's clock):
1. the problem's start and goal configurations;
2. a guide path between them: the straight joint-space segment if the python-fcl world finds it
   free, otherwise an RRT-Connect path (OMPL, python-fcl) with a fixed seed;
3. walking the guide path, every first configuration not inside a region (or inside only
   regions that do not meet those holding the previous one) seeds a new region that must also
   contain the last covered configuration before it (IRIS containment points), so consecutive
   regions overlap and the chain connects start to goal.
Sampled-IRIS regions are only probabilistically collision-free, and Drake's geometry is not the
validator's, so each region is also checked with the python-fcl world (the validator's engine):
uniform samples, and the start-goal segment when a region holds both ends, are cut off where they
collide. Then GCS is solved for the problem as the planner will solve it, its path checked with
the python-fcl world and the colliding configurations cut off (`planners.gcs_solve.checked_path`),
reconnecting along the guide path when a cut disconnects, for up to VERIFY_ROUNDS rounds. The
planner still checks its path online; the suite's validator judges it like every other planner's.

A region set is stored as one `.npz` per world under a cache directory, named by a hash of the
collision world (`PlanningProblem.world_key()`: scene content, held can and its pose in the
gripper, finger opening, removed cans) and of the region options. A later problem in the same
world reuses the set and grows it (seeds, connection, verification) only if it has not been
verified for that problem. `offline_s` is the set's total build time, reported by every problem
that uses it.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import itertools
import json
import logging
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from planners.gcs_solve import checked_path, cut_at_collision
from scenes.errors import SuiteError

log = logging.getLogger(__name__)

FORMAT_VERSION = 1
IRIS_ALGORITHMS = ("np2", "zo")
#: How seeds are chosen: from the world alone ("chain", "cliques", see `planners.gcs_cover`), or
#: from each problem's start, goal and a guide between them ("problem", the earlier rule: it uses
#: the problems, so its regions are not the world's alone).
SEEDINGS = ("chain", "cliques", "problem")
#: The mark in `RegionSet.checked` of a set built from its world alone.
WORLD_BUILT = "world"
#: Default cache of regions built on demand (results/ is generated output, not committed).
DEFAULT_CACHE_DIR = Path(__file__).resolve().parents[1] / "results" / "regions"
#: Datasets may carry their own prebuilt regions (`python -m suite regions build --dataset NAME`).
DATASETS_DIR = Path(__file__).resolve().parents[1] / "scenes" / "datasets"

#: Offline rounds of connect (guide path), solve, check and cut per problem.
VERIFY_ROUNDS = 3

#: Regions grown in this process (tests assert that a cached world grows none).
GROWN_IN_PROCESS = 0


@dataclasses.dataclass(frozen=True)
class RegionOptions:
    """How regions are grown (every field enters the cache key).

    Attributes:
        iris: "np2" (IrisNp2: closest collisions by nonlinear programming) or "zo" (IrisZo:
            zero-order, collision checks only).
        num_particles: samples per inner iteration of the statistical test.
        epsilon: admissible fraction of a region's volume in collision.
        delta: probability that the fraction in collision exceeds epsilon.
        max_iterations: ellipsoid / separating-plane alternations.
        max_iterations_separating_planes: rounds of adding faces per alternation.
        max_separating_planes_per_iteration: faces added per round.
        configuration_space_margin_rad: faces step back from collisions by this much (rad).
        padding_m: the Drake checker's robot-environment padding (m); a seed that collides with
            the padding (a grasp between cans) is grown again without it.
        seed_radius_rad: radius of the starting hypersphere around a seed (rad).
        guide_step_rad: spacing of the configurations tested along a guide path (joint L2, rad).
        guide_rrt_time_s: budget of an RRT-Connect guide path (s): per problem ("problem"
            seeding), or per blocked join of the world's task chain (world seedings).
        max_regions_per_problem: regions a problem may add (start, goal and connection;
            "problem" seeding only).
        check_samples, check_rounds: each region is sampled uniformly (`check_samples` per
            round) and checked with the python-fcl world, the validator's engine; faces are added
            to cut off what collides, for up to `check_rounds` rounds (0 to skip).
        random_seed: IRIS's random seed.
        threads: threads of one IRIS call (its collision checks).
        seeding: "chain" (default: regions along the world's task chain, each containing one
            segment of it), "cliques" (a visibility clique cover of samples of the task's
            neighbourhood), both from the world alone (`planners.gcs_cover`); or "problem" (seeds
            at each problem's start, goal and along a guide between them, offline: the earlier
            rule, which uses the problems).
        segment_rad: longest chain segment one region must contain ("chain").
        max_regions_per_world: cap on a world's regions (world seedings). GCS's cost grows with
            the edges between overlapping regions: on a `window` world, 12 chain regions (37
            edges) took 2.3 s a solve, 8 (14 edges) 0.2 s, for a path 6% longer.
        sample_sigma_rad: per-joint standard deviation of the task-neighbourhood samples around
            the task chain ("cliques"; also the coverage estimate of `suite bench gcs-regions`).
        clique_samples: collision-free samples per clique-cover round ("cliques").
        min_clique: smallest clique that makes a region ("cliques"; at least 8 in 7-D).
        coverage: stop the clique cover once this fraction of fresh task-neighbourhood samples
            lies in some region ("cliques").
    """

    iris: str = "np2"
    num_particles: int = 200
    epsilon: float = 0.05
    delta: float = 0.1
    max_iterations: int = 1
    max_iterations_separating_planes: int = 10
    max_separating_planes_per_iteration: int = 10
    configuration_space_margin_rad: float = 0.01
    padding_m: float = 0.015
    seed_radius_rad: float = 0.01
    guide_step_rad: float = 0.02
    guide_rrt_time_s: float = 2.0
    max_regions_per_problem: int = 12
    check_samples: int = 200
    check_rounds: int = 2
    random_seed: int = 1234
    threads: int = 1
    seeding: str = "chain"
    segment_rad: float = 0.5
    max_regions_per_world: int = 8
    sample_sigma_rad: float = 0.25
    clique_samples: int = 200
    min_clique: int = 10
    coverage: float = 0.7

    def __post_init__(self):
        if self.iris not in IRIS_ALGORITHMS:
            raise SuiteError(f"gcs iris={self.iris!r}; allowed: {', '.join(IRIS_ALGORITHMS)}")
        if self.seeding not in SEEDINGS:
            raise SuiteError(f"gcs seeding={self.seeding!r}; allowed: {', '.join(SEEDINGS)}")
        if not 0 < self.coverage <= 1:
            raise SuiteError(f"gcs coverage={self.coverage!r} must be in (0, 1]")
        if self.min_clique < 8:
            raise SuiteError(f"gcs min_clique={self.min_clique!r} must be >= 8 (a 7-D ellipsoid needs 8 points)")
        for name in ("num_particles", "max_iterations", "max_iterations_separating_planes",
                     "max_separating_planes_per_iteration", "max_regions_per_problem", "threads",
                     "check_samples", "max_regions_per_world", "clique_samples"):
            if getattr(self, name) < 1:
                raise SuiteError(f"gcs {name}={getattr(self, name)!r} must be >= 1")
        for name in ("epsilon", "delta"):
            if not 0 < getattr(self, name) < 1:
                raise SuiteError(f"gcs {name}={getattr(self, name)!r} must be in (0, 1)")
        for name in ("seed_radius_rad", "guide_step_rad", "guide_rrt_time_s", "segment_rad", "sample_sigma_rad"):
            if not getattr(self, name) > 0:
                raise SuiteError(f"gcs {name}={getattr(self, name)!r} must be positive")
        for name in ("configuration_space_margin_rad", "padding_m", "check_rounds"):
            if not getattr(self, name) >= 0:
                raise SuiteError(f"gcs {name}={getattr(self, name)!r} must be >= 0")

    def key_fields(self) -> dict:
        """The fields that decide the regions (threads do not)."""
        d = dataclasses.asdict(self)
        d.pop("threads")
        if self.seeding == "problem":  # the key of the sets built before world seedings existed
            for name in ("seeding", "segment_rad", "max_regions_per_world", "sample_sigma_rad", "clique_samples",
                         "min_clique", "coverage"):
                d.pop(name)
        return d


def world_hash(problem, options: RegionOptions) -> str:
    """Content hash of a problem's collision world and the region options (20 hex digits)."""
    scene_key, held, opening, removed = problem.world_key()
    blob = json.dumps({
        "format": FORMAT_VERSION,
        "scene": scene_key,
        "held": None if held is None else [held[0], hashlib.sha1(held[1]).hexdigest()],
        "opening_m": opening,
        "removed": list(removed),
        "options": options.key_fields(),
    }, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:20]


@dataclasses.dataclass
class RegionSet:
    """The regions of one collision world.

    Attributes:
        world_hash: see `world_hash`.
        A, b: per region, the H-representation {q : A q <= b}.
        seeds: (k, 7) the configuration each region was grown from.
        region_build_s: per region, wall time of its IRIS call (s).
        offline_s: total wall time spent building this set (IRIS, guide paths, checks), s.
        problems: problem hashes (start, goal) this set was grown for.
        edges: directed pairs (i, j) of intersecting regions (both directions listed).
        iris: the algorithm.
        checked: problem hashes for which the set was verified offline: the blocked start-goal
            segment cut out (`cut_blocked_segment`), start and goal connected, and GCS's path
            checked with the python-fcl world and repaired by cuts (`planners.gcs_solve.checked_path`).
    """

    world_hash: str
    A: list[np.ndarray] = dataclasses.field(default_factory=list)
    b: list[np.ndarray] = dataclasses.field(default_factory=list)
    seeds: list[np.ndarray] = dataclasses.field(default_factory=list)
    region_build_s: list[float] = dataclasses.field(default_factory=list)
    offline_s: float = 0.0
    problems: list[str] = dataclasses.field(default_factory=list)
    edges: list[tuple[int, int]] = dataclasses.field(default_factory=list)
    iris: str = "np2"
    checked: list[str] = dataclasses.field(default_factory=list)

    def __len__(self) -> int:
        return len(self.A)

    def contains(self, Q: np.ndarray, tol: float = 1e-9) -> np.ndarray:
        """(m, n_regions) bool: which regions contain each row of Q (m, 7)."""
        Q = np.atleast_2d(Q)
        if not self.A:
            return np.zeros((len(Q), 0), bool)
        return np.stack([np.all(Q @ A.T <= b + tol, axis=1) for A, b in zip(self.A, self.b)], axis=1)

    def polyhedra(self) -> list:
        from pydrake.geometry.optimization import HPolyhedron

        return [HPolyhedron(A, b) for A, b in zip(self.A, self.b)]

    def connected(self, q_start: np.ndarray, q_goal: np.ndarray) -> bool:
        """Whether the region graph links a region holding q_start to one holding q_goal."""
        inside = self.contains(np.stack([q_start, q_goal]))
        frontier = list(np.nonzero(inside[0])[0])
        seen = set(frontier)
        targets = set(np.nonzero(inside[1])[0])
        adjacency: dict[int, list[int]] = {}
        for i, j in self.edges:
            adjacency.setdefault(i, []).append(j)
        while frontier:
            i = frontier.pop()
            if i in targets:
                return True
            for j in adjacency.get(i, []):
                if j not in seen:
                    seen.add(j)
                    frontier.append(j)
        return False

    # --- storage -------------------------------------------------------------------------------

    def save(self, path: Path) -> None:
        """Write atomically (workers of one run may build the same world side by side)."""
        path.parent.mkdir(parents=True, exist_ok=True)
        sizes = np.array([len(b) for b in self.b], int)
        meta = {"format": FORMAT_VERSION, "world_hash": self.world_hash, "offline_s": self.offline_s,
                "problems": self.problems, "iris": self.iris, "region_build_s": self.region_build_s,
                "verified": self.checked}
        fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".npz.tmp")
        os.close(fd)
        with open(tmp, "wb") as f:
            np.savez_compressed(
                f, sizes=sizes,
                A=np.concatenate(self.A) if self.A else np.zeros((0, 7)),
                b=np.concatenate(self.b) if self.b else np.zeros(0),
                seeds=np.array(self.seeds).reshape(-1, 7),
                edges=np.array(self.edges, int).reshape(-1, 2),
                meta=np.array(json.dumps(meta)),
            )
        os.replace(tmp, path)

    @classmethod
    def load(cls, path: Path) -> RegionSet:
        with np.load(path) as z:
            meta = json.loads(str(z["meta"]))
            if meta.get("format") != FORMAT_VERSION:
                raise SuiteError(f"{path}: region cache format {meta.get('format')!r}, expected {FORMAT_VERSION}")
            cuts = np.cumsum(z["sizes"])[:-1]
            A = np.split(z["A"], cuts) if len(z["sizes"]) else []
            b = np.split(z["b"], cuts) if len(z["sizes"]) else []
            return cls(meta["world_hash"], list(A), list(b), list(z["seeds"]), list(meta["region_build_s"]),
                       float(meta["offline_s"]), list(meta["problems"]),
                       [tuple(map(int, e)) for e in z["edges"]], meta["iris"], list(meta.get("verified", [])))


def problem_hash(problem) -> str:
    """Identifies a problem's ends within its world."""
    blob = np.concatenate([np.asarray(problem.q_start, float), np.asarray(problem.q_goal, float)]).round(9)
    return hashlib.sha1(blob.tobytes()).hexdigest()[:16]


def cache_dirs(cache_dir: str | Path | None) -> list[Path]:
    """Where region sets are looked up: the given (or default) cache, then every dataset's
    `regions/` directory."""
    first = Path(cache_dir) if cache_dir else DEFAULT_CACHE_DIR
    dirs = [first]
    if DATASETS_DIR.exists():
        dirs += sorted(p / "regions" for p in DATASETS_DIR.iterdir() if (p / "regions").is_dir())
    return dirs


def find_cached(whash: str, cache_dir: str | Path | None) -> Path | None:
    for d in cache_dirs(cache_dir):
        path = d / f"{whash}.npz"
        if path.exists():
            return path
    return None


# --- building ----------------------------------------------------------------------------------


@contextlib.contextmanager
def quiet_drake():
    """IrisNp2 logs a warning for every closest-collision program SNOPT fails to solve (a
    routine event it handles); keep them out of the run's output."""
    logger = logging.getLogger("drake")
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        yield
    finally:
        logger.setLevel(level)


def make_checker(problem, *, padding_m: float, edge_step_rad: float = 0.01):
    """Drake's SceneGraphCollisionChecker on the problem's plan-mode scene."""
    from pydrake.planning import RobotDiagramBuilder, SceneGraphCollisionChecker

    from scenes.drake_scene import add_scene_to_plant

    builder = RobotDiagramBuilder(time_step=0.0)
    iiwa, wsg = add_scene_to_plant(
        builder.plant(), builder.scene_graph(), problem.scene.without_cans(problem.removed_can_ids),
        mode="plan", gripper_opening_m=problem.gripper_opening_m, held=problem.held,
    )
    with quiet_drake():  # its "Allocating contexts ..." info line, once per checker
        return SceneGraphCollisionChecker(
            model=builder.Build(), robot_model_instances=[iiwa, wsg], edge_step_size=edge_step_rad,
            env_collision_padding=padding_m, self_collision_padding=0.0,
        )


class RegionBuilder:
    """Grows the regions of one world (holds its two Drake collision checkers)."""

    def __init__(self, problem, options: RegionOptions):
        from pydrake.geometry.optimization import HPolyhedron

        self.options = options
        self.checkers = [make_checker(problem, padding_m=options.padding_m)]
        if options.padding_m > 0:
            self.checkers.append(make_checker(problem, padding_m=0.0))
        plant = self.checkers[0].plant()
        self.domain = HPolyhedron.MakeBox(plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits())

    def _iris_options(self, containment: np.ndarray | None):
        from pydrake.common import Parallelism
        from pydrake.planning import IrisNp2Options, IrisZoOptions

        o = self.options
        opts = IrisNp2Options() if o.iris == "np2" else IrisZoOptions()
        s = opts.sampled_iris_options
        s.num_particles = o.num_particles
        s.epsilon, s.delta = o.epsilon, o.delta
        s.max_iterations = o.max_iterations
        s.max_iterations_separating_planes = o.max_iterations_separating_planes
        s.max_separating_planes_per_iteration = o.max_separating_planes_per_iteration
        s.configuration_space_margin = o.configuration_space_margin_rad
        s.random_seed = o.random_seed
        s.parallelism = Parallelism(o.threads)
        s.relax_margin = True
        if containment is not None:
            s.containment_points = containment
        return opts

    def grow(self, q: np.ndarray, *, also_contain: np.ndarray | None = None, containment: np.ndarray | None = None,
             ellipsoid=None):
        """One region around q, or None if q collides in every checker or IRIS fails.

        Args:
            q: the seed (the starting ellipsoid's centre).
            also_contain: one more configuration the region must contain (with q).
            containment: (7, m) configurations the region must contain (their hull must be free).
            ellipsoid: the starting ellipsoid (centred at q); a hypersphere of `seed_radius_rad`
                by default.

        Returns (A, b, seconds). Containment that IRIS refuses is dropped and the region grown
        without it."""
        from pydrake.geometry.optimization import Hyperellipsoid
        from pydrake.planning import IrisNp2, IrisZo

        global GROWN_IN_PROCESS
        o = self.options
        fn = IrisNp2 if o.iris == "np2" else IrisZo
        if containment is None and also_contain is not None:
            containment = np.column_stack([q, also_contain])
        start = ellipsoid if ellipsoid is not None else Hyperellipsoid.MakeHypersphere(o.seed_radius_rad, q)
        for checker in self.checkers:
            if not checker.CheckConfigCollisionFree(q):
                continue
            for contain in ([None] if containment is None else [containment, None]):
                t0 = time.perf_counter()
                try:
                    with quiet_drake():
                        region = fn(checker, start, self.domain, self._iris_options(contain))
                except RuntimeError as exc:  # IRIS refuses (e.g. a containment point in collision)
                    log.debug("IRIS failed at %s: %s", q, exc)
                    continue
                GROWN_IN_PROCESS += 1
                region = region.ReduceInequalities()
                return region.A(), region.b(), time.perf_counter() - t0
        return None


def cut_blocked_segment(rs: RegionSet, q0: np.ndarray, q1: np.ndarray, *, world, margin_rad: float) -> int:
    """If the straight segment q0 -> q1 collides (python-fcl), cut it out of every region holding
    both ends (such a region holds the whole segment: the shortest path would take it). Each cut
    keeps the region's seed. Returns the number of regions cut."""
    if world.motion_free(q0, q1, resolution_rad=0.01):
        return 0
    dense = world.interpolate(np.stack([q0, q1]), 0.01)
    x_bad = dense[world.first_collision(dense)]
    cut = 0
    for i in np.flatnonzero(rs.contains(np.stack([q0, q1])).all(axis=0)):
        seed = np.asarray(rs.seeds[i], float)
        A, b = cut_at_collision(rs.A[i], rs.b[i], world=world, center=seed, q_bad=x_bad, keep=[seed],
                                margin_rad=margin_rad)
        if len(b) > len(rs.b[i]):
            rs.A[i], rs.b[i] = A, b
            cut += 1
    return cut


def check_with_world(A: np.ndarray, b: np.ndarray, *, world, center: np.ndarray, keep: list[np.ndarray],
                     samples: int, rounds: int, margin_rad: float, seed: int):
    """Cut a region where the python-fcl world (the validator's engine) finds collisions among
    uniform samples (hit-and-run), for up to `rounds` rounds. Returns (A, b, cuts)."""
    from pydrake.common import RandomGenerator
    from pydrake.geometry.optimization import HPolyhedron

    gen = RandomGenerator(seed)
    cuts = 0
    for _ in range(rounds):
        poly = HPolyhedron(A, b)
        x = poly.ChebyshevCenter()  # strictly inside (the seed may lie on a face)
        Q = []
        try:
            for _ in range(samples):
                x = poly.UniformSample(gen, x, 5)
                Q.append(x)
        except ValueError:  # a sliver the sampler cannot move in: check what was drawn
            pass
        if not Q:
            break
        Q = np.array(Q)
        bad = Q[~world.states_free(Q)]
        if len(bad) == 0:
            break
        # Cut towards the colliding sample nearest the center first: it shapes the region most.
        for q_bad in bad[np.argsort(np.linalg.norm(bad - center, axis=1))][:10]:
            if np.all(A @ q_bad <= b):
                A2, b2 = cut_at_collision(A, b, world=world, center=center, q_bad=q_bad, keep=keep,
                                          margin_rad=margin_rad)
                cuts += len(b2) - len(b)
                A, b = A2, b2
    return A, b, cuts


def _guide_path(problem, options: RegionOptions) -> np.ndarray | None:
    """The straight segment if free in the python-fcl world, else an RRT-Connect path, or None."""
    from planners.worlds import collision_world

    world = collision_world(problem)
    q0, q1 = np.asarray(problem.q_start, float), np.asarray(problem.q_goal, float)
    if world.motion_free(q0, q1, resolution_rad=0.01):
        return np.stack([q0, q1])
    from planners.ompl_rrt import RRTConnectPlanner

    guide = problem.with_(time_limit_s=options.guide_rrt_time_s, seed=options.random_seed)
    result = RRTConnectPlanner().plan(guide)
    return None if result.path is None else np.asarray(result.path, float)


def _densify(path: np.ndarray, step: float) -> np.ndarray:
    out = [path[0]]
    for a, b in itertools.pairwise(path):
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / step)))
        out += [a + (b - a) * k / n for k in range(1, n + 1)]
    return np.array(out)


def _meet(rs: RegionSet, these: set[int], those: set[int]) -> bool:
    """Whether a region of `these` intersects a region of `those`."""
    from pydrake.geometry.optimization import HPolyhedron

    return any(HPolyhedron(rs.A[i], rs.b[i]).IntersectsWith(HPolyhedron(rs.A[j], rs.b[j]))
               for i in these for j in those)


def update_edges(rs: RegionSet, first_new: int) -> None:
    """Add the intersection edges of regions >= first_new with all others."""
    polys = rs.polyhedra()
    for j in range(first_new, len(polys)):
        for i in range(j):
            if polys[i].IntersectsWith(polys[j]):
                rs.edges += [(i, j), (j, i)]


def grow_for_problem(rs: RegionSet, problem, builder: RegionBuilder) -> int:
    """Grow `rs` until it covers the problem's start and goal and connects them (or the
    problem's region budget runs out). Returns the number of regions added."""
    o = builder.options
    t0 = time.perf_counter()
    n0 = len(rs)
    q0, q1 = np.asarray(problem.q_start, float), np.asarray(problem.q_goal, float)
    added = 0
    from planners.worlds import collision_world

    world = collision_world(problem)

    def add(q, contain=None) -> bool:
        nonlocal added
        grown = builder.grow(q, also_contain=contain)
        if grown is None:
            return False
        A, b, dt = grown
        if o.check_rounds > 0:
            t1 = time.perf_counter()
            keep = [p for p in (q, contain, q0, q1) if p is not None and np.all(A @ p <= b + 1e-9)]
            A, b, _ = check_with_world(A, b, world=world, center=np.asarray(q, float), keep=keep,
                                       samples=o.check_samples, rounds=o.check_rounds,
                                       margin_rad=o.configuration_space_margin_rad, seed=o.random_seed + len(rs))
            dt += time.perf_counter() - t1
        rs.A.append(A)
        rs.b.append(b)
        rs.seeds.append(np.asarray(q, float))
        rs.region_build_s.append(dt)
        added += 1
        return True

    for q in (q0, q1):
        if added < o.max_regions_per_problem and not rs.contains(q).any():
            add(q)
    if cut_blocked_segment(rs, q0, q1, world=world, margin_rad=o.configuration_space_margin_rad):
        rs.edges = []
        n0 = 0
    update_edges(rs, n0)

    def walk(guide) -> None:
        n_before = len(rs)
        prev, prev_in = None, set()
        for q in _densify(guide, o.guide_step_rad):
            if added >= o.max_regions_per_problem:
                break
            inside = set(np.flatnonzero(rs.contains(q)[0]).tolist())
            # Covered, and by a region that is (or meets) one holding the previous point.
            if inside and (prev is None or inside & prev_in or _meet(rs, inside, prev_in)):
                prev, prev_in = q, inside
                continue
            if add(q, prev):
                prev, prev_in = q, set(np.flatnonzero(rs.contains(q)[0]).tolist())
        update_edges(rs, n_before)

    # Connect start and goal along the guide path; then solve GCS as the planner will and cut
    # what the python-fcl world finds in collision (a cut may disconnect: walk again).
    guide = None
    for _ in range(VERIFY_ROUNDS):
        if not rs.connected(q0, q1):
            guide = _guide_path(problem, o) if guide is None else guide
            if guide is None:
                break
            walk(guide)
            if not rs.connected(q0, q1):
                break
        path, st = checked_path(rs.A, rs.b, rs.edges, rs.seeds, q0, q1, world=world)
        if path is not None or "cannot be cut" in st.get("reason", ""):
            break
    key = problem_hash(problem)
    if key not in rs.problems:
        rs.problems.append(key)
    if key not in rs.checked:
        rs.checked.append(key)
    rs.offline_s += time.perf_counter() - t0
    return added


def _add_region(rs: RegionSet, builder: RegionBuilder, world, q: np.ndarray, *, containment: np.ndarray | None = None,
                ellipsoid=None, keep: tuple = ()) -> bool:
    """Grow one region at q, check it with the python-fcl world (cuts keep q, the containment
    points and `keep` where the region holds them) and append it to `rs`."""
    o = builder.options
    grown = builder.grow(q, containment=containment, ellipsoid=ellipsoid)
    if grown is None:
        return False
    A, b, dt = grown
    if o.check_rounds > 0:
        t1 = time.perf_counter()
        held = [q, *([] if containment is None else list(containment.T)), *keep]
        inside = [p for p in held if np.all(A @ p <= b + 1e-9)]
        A, b, _ = check_with_world(A, b, world=world, center=np.asarray(q, float), keep=inside,
                                   samples=o.check_samples, rounds=o.check_rounds,
                                   margin_rad=o.configuration_space_margin_rad, seed=o.random_seed + len(rs))
        dt += time.perf_counter() - t1
    rs.A.append(A)
    rs.b.append(b)
    rs.seeds.append(np.asarray(q, float))
    rs.region_build_s.append(dt)
    return True


def coverage_of(rs: RegionSet, samples: np.ndarray) -> float:
    """The fraction of `samples` (collision-free configurations) inside some region."""
    if len(samples) == 0 or len(rs) == 0:
        return 0.0
    return float(rs.contains(samples).any(axis=1).mean())


def grow_for_world(rs: RegionSet, problem, builder: RegionBuilder) -> dict:
    """Grow `rs` from the problem's collision world alone (its task chain, `planners.gcs_cover`),
    never from the problem's start, goal or paths; then solve GCS between the chain's ends, check
    its path with the python-fcl world and cut what collides (`checked_path`). Returns the build's
    figures (chain, regions, seconds)."""
    from planners.gcs_cover import chain_seeds, clique_seeds, free_task_samples, task_chain
    from planners.worlds import collision_world

    o = builder.options
    t0 = time.perf_counter()
    world = collision_world(problem)
    chain, info = task_chain(problem, seed=o.random_seed, rrt_time_s=o.guide_rrt_time_s)
    if chain is not None:
        ends = (chain[0], chain[-1])
        info["chain_rad"] = float(np.sum(np.linalg.norm(np.diff(chain, axis=0), axis=1)))
        if o.seeding == "chain":
            for q, C in chain_seeds(chain, segment_rad=o.segment_rad, max_regions=o.max_regions_per_world):
                _add_region(rs, builder, world, q, containment=C, keep=ends)
        else:
            rng = np.random.default_rng([o.random_seed, 7])
            # The visibility graph only groups samples (regions are grown by IRIS and checked with
            # the python-fcl world after), so its edges are checked at a coarser 0.05 rad step;
            # unpadded, as Drake's clique cover ignores padding.
            checker = make_checker(problem, padding_m=0.0, edge_step_rad=0.05)
            for _ in range(o.max_regions_per_world):
                if len(rs) >= o.max_regions_per_world:
                    break
                probe = free_task_samples(chain, n=200, sigma_rad=o.sample_sigma_rad, rng=rng, world=world)
                info["coverage_estimate"] = coverage_of(rs, probe)
                if info["coverage_estimate"] >= o.coverage:
                    break
                pool = free_task_samples(chain, n=4 * o.clique_samples, sigma_rad=o.sample_sigma_rad, rng=rng,
                                         world=world)
                pool = pool[~rs.contains(pool).any(axis=1)][: o.clique_samples] if len(rs) else pool[: o.clique_samples]
                cliques = clique_seeds(checker, pool, min_clique=o.min_clique,
                                       max_cliques=o.max_regions_per_world - len(rs))
                if not cliques:
                    break
                for q, E in cliques:
                    _add_region(rs, builder, world, q, ellipsoid=E, keep=ends)
        update_edges(rs, 0)
        info["ends_connected"] = bool(rs.connected(*ends))
        if info["ends_connected"]:
            path, st = checked_path(rs.A, rs.b, rs.edges, rs.seeds, ends[0], ends[1], world=world)
            info["verified"] = path is not None
    if WORLD_BUILT not in rs.checked:
        rs.checked.append(WORLD_BUILT)
    info["regions"] = len(rs)
    rs.offline_s += time.perf_counter() - t0
    info["offline_s"] = rs.offline_s
    return info


def regions_for(problem, options: RegionOptions, *, cache_dir: str | Path | None = None,
                build: bool = True, fresh: bool = False) -> tuple[RegionSet | None, dict]:
    """The cached region set of the problem's world, grown for this problem if needed.

    Args:
        problem: the planning problem.
        options: how regions are grown.
        cache_dir: where on-demand builds are written (and first looked up); None for the default.
        build: grow regions on a miss; otherwise the cached set (if any) is returned as it is.
        fresh: ignore every cached set and grow the world's regions from nothing (written to
            `cache_dir`, replacing what is there).

    Returns:
        (region set or None, info) with info: world_hash, cache ("hit", "grown", "built",
        "miss"), regions_added, path.
    """
    whash = world_hash(problem, options)
    path = None if fresh else find_cached(whash, cache_dir)
    rs = RegionSet.load(path) if path is not None else None
    info = {"world_hash": whash, "regions_added": 0, "path": None if path is None else str(path)}
    pkey = WORLD_BUILT if options.seeding != "problem" else problem_hash(problem)
    if rs is not None and pkey in rs.checked:
        info["cache"] = "hit"
        return rs, info
    if not build:
        info["cache"] = "miss"
        return rs, info
    info["cache"] = "grown" if rs is not None else "built"
    if rs is None:
        rs = RegionSet(whash, iris=options.iris)
    with quiet_drake():
        if options.seeding == "problem":
            info["regions_added"] = grow_for_problem(rs, problem, RegionBuilder(problem, options))
        else:
            n0 = len(rs)
            info["build"] = grow_for_world(rs, problem, RegionBuilder(problem, options))
            info["regions_added"] = len(rs) - n0
    if path is None:
        path = (Path(cache_dir) if cache_dir else DEFAULT_CACHE_DIR) / f"{whash}.npz"
    rs.save(path)
    info["path"] = str(path)
    return rs, info
