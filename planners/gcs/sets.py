"""The data of `gcs`'s regions: their options (`RegionOptions`, every field in the cache key), a
region set (`RegionSet`: H-polytopes, seeds, overlaps, what was verified, build time) and where
sets are cached (one `.npz` per hash of the collision world and the options; datasets carry their
own `regions/`). How regions are grown is `planners.gcs.regions`."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import tempfile
from pathlib import Path

import numpy as np

from scenes.errors import SuiteError
from scenes.identity_rule import CURRENT_RULE, hashed

FORMAT_VERSION = 1
IRIS_ALGORITHMS = ("np2", "zo")
#: How seeds are chosen: from the world alone ("chain", "cliques", see `planners.gcs.cover`), or
#: from each problem's start, goal and a guide between them ("problem", the earlier rule: it uses
#: the problems, so its regions are not the world's alone).
SEEDINGS = ("chain", "cliques", "problem")
#: The mark in `RegionSet.checked` of a set built from its world alone.
WORLD_BUILT = "world"
#: Default cache of regions built on demand (results/ is generated output, not committed).
DEFAULT_CACHE_DIR = Path(__file__).resolve().parents[2] / "results" / "regions"
#: Datasets may carry their own prebuilt regions (`python -m suite regions build --dataset NAME`).
DATASETS_DIR = Path(__file__).resolve().parents[2] / "scenes" / "datasets"


SAMPLING_STRATEGIES = ("greedy", "ray")
NP2_SOLVERS = ("snopt", "ipopt")
#: IRIS options named after region sets had been built with Drake's defaults for them: each stays
#: out of the cache key while it holds the value those sets were built with (Drake 1.51's
#: default; `relax_margin` was always on), so that the shipped sets keep their names.
UNKEYED_DEFAULTS = {
    "termination_threshold": 0.02, "relative_termination_threshold": 0.001, "tau": 0.5, "mixing_steps": 50,
    "require_sample_point_is_contained": True, "remove_all_collisions_possible": True, "relax_margin": True,
    "sample_particles_in_parallel": False, "sampling_strategy": "greedy", "ray_search_num_steps": 10,
    "num_particles_to_walk_towards": 200, "only_walk_toward_collisions": False,
    "add_hyperplane_if_solve_fails": False, "np2_solver": "snopt", "bisection_steps": 10,
}


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
            neighbourhood), both from the world alone (`planners.gcs.cover`); or "problem" (seeds
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

    The rest are the options IRIS reads (`IrisNp2Options`, `IrisZoOptions` and their
    `sampled_iris_options`, Drake 1.51), each set explicitly so that no region depends on a
    default a reader cannot see or that a Drake release may change. Their values here are Drake
    1.51's defaults, except `relax_margin` (always on here) and the two termination thresholds
    (the GCS paper's: off, and 2%). `UNKEYED_DEFAULTS` keeps each out of the cache key while it
    holds the value the sets built before it was named were built with, and the thresholds stay
    out while `max_iterations` is 1 (IRIS then stops after one iteration whatever they say), so
    those sets keep their names.

        termination_threshold: IRIS stops when an iteration grows the inscribed ellipsoid's
            volume (rad^7) by at most this much (absolute). Drake's default, 0.02, stops every
            region whose ellipsoid grew by less than that after its first iteration, whatever
            `max_iterations` says (iris_np2.cc, CheckTerminationConditions): a 7-D ellipsoid of
            0.3 rad radius has volume 0.001. The GCS paper set -1, which is off except when an
            iteration shrinks the volume by more than 1 rad^7 (the test is delta <= threshold);
            IRIS then returns that last, smaller region.
        relative_termination_threshold: ... or by at most this fraction of the last volume
            (the paper: 0.02; Drake's default 0.001).
        tau: the statistical test's decision threshold (Drake's unadaptive test).
        mixing_steps: hit-and-run steps between the uniform samples of a region.
        require_sample_point_is_contained: stop iterating once the seed would leave the region.
        remove_all_collisions_possible: keep adding faces until every particle found in collision
            is cut off (or `max_separating_planes_per_iteration` is reached).
        relax_margin: shrink the configuration-space margin where it would cut off a
            containment point.
        sample_particles_in_parallel: draw particles on `threads` threads (changes the draws).
        sampling_strategy: IrisNp2 only: "greedy" (the closest collision from each particle in
            collision) or "ray" (walk from the centre toward particles).
        ray_search_num_steps, num_particles_to_walk_towards, only_walk_toward_collisions:
            IrisNp2's "ray" strategy.
        add_hyperplane_if_solve_fails: IrisNp2: add a face at a particle whose closest-collision
            program fails, rather than skip it.
        np2_solver: IrisNp2's nonlinear solver for the closest collisions, "snopt" or "ipopt"
            (Drake takes the first available of the two: SNOPT in the pip wheels).
        bisection_steps: IrisZo's bisection steps toward each particle in collision.
      Not options here, because the suite never changes them: IRIS's `parameterization` (the
      identity: regions are in joint space), `solver_options` (the solver's defaults),
      `prog_with_additional_constraints` (none), `meshcat` (none), `verbose` (on, to record each
      region's iterations), `containment_points` (set by the seeding) and `parallelism`
      (`threads`).
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
    termination_threshold: float = -1.0
    relative_termination_threshold: float = 0.02
    tau: float = 0.5
    mixing_steps: int = 50
    require_sample_point_is_contained: bool = True
    remove_all_collisions_possible: bool = True
    relax_margin: bool = True
    sample_particles_in_parallel: bool = False
    sampling_strategy: str = "greedy"
    ray_search_num_steps: int = 10
    num_particles_to_walk_towards: int = 200
    only_walk_toward_collisions: bool = False
    add_hyperplane_if_solve_fails: bool = False
    np2_solver: str = "snopt"
    bisection_steps: int = 10

    def __post_init__(self):
        if self.iris not in IRIS_ALGORITHMS:
            raise SuiteError(f"gcs iris={self.iris!r}; allowed: {', '.join(IRIS_ALGORITHMS)}")
        if self.seeding not in SEEDINGS:
            raise SuiteError(f"gcs seeding={self.seeding!r}; allowed: {', '.join(SEEDINGS)}")
        if self.sampling_strategy not in SAMPLING_STRATEGIES:
            raise SuiteError(f"gcs sampling_strategy={self.sampling_strategy!r}; allowed: {', '.join(SAMPLING_STRATEGIES)}")
        if self.np2_solver not in NP2_SOLVERS:
            raise SuiteError(f"gcs np2_solver={self.np2_solver!r}; allowed: {', '.join(NP2_SOLVERS)}")
        if not 0 < self.tau < 1:
            raise SuiteError(f"gcs tau={self.tau!r} must be in (0, 1)")
        for name in ("mixing_steps", "ray_search_num_steps", "num_particles_to_walk_towards", "bisection_steps"):
            if getattr(self, name) < 1:
                raise SuiteError(f"gcs {name}={getattr(self, name)!r} must be >= 1")
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
        for name, value in UNKEYED_DEFAULTS.items():  # the key of the sets built before they were named
            if d[name] == value:
                d.pop(name)
        if self.max_iterations == 1:  # IRIS stops after its one iteration whatever the thresholds say
            for name in ("termination_threshold", "relative_termination_threshold"):
                d.pop(name, None)
        if self.seeding == "problem":  # the key of the sets built before world seedings existed
            for name in ("seeding", "segment_rad", "max_regions_per_world", "sample_sigma_rad", "clique_samples",
                         "min_clique", "coverage"):
                d.pop(name)
        return d


def world_hash(problem, options: RegionOptions, *, rule: str = CURRENT_RULE) -> str:
    """Content hash of a problem's collision world and the region options (20 hex digits), its
    floats written by identity rule `rule` (`scenes.identity_rule`; the cache uses the current one)."""
    scene_key, held, opening, removed = problem.world_key(rule=rule)
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
        offline_cpu_s: the CPU time of the building process over the same work, s (one IRIS
            thread: the wall time the build takes on a core of its own, whatever else the machine
            ran; None for sets built before it was recorded).
        problems: problem hashes (start, goal) this set was grown for.
        edges: directed pairs (i, j) of intersecting regions (both directions listed).
        iris: the algorithm.
        region_iris: per region, what its IRIS call did, from Drake's own log: `iterations` run,
            `stop` (why it stopped: "iteration_limit", "absolute_threshold",
            "relative_threshold", "seed_left_region", or "unknown"; several when several held
            at once), `volume` (the final region's maximum inscribed ellipsoid, rad^7) and
            `radius_rad` (the radius of the 7-ball of that volume). Empty for sets built before
            it was recorded.
        checked: problem hashes for which the set was verified offline: the blocked start-goal
            segment cut out (`cut_blocked_segment`), start and goal connected, and GCS's path
            checked with the python-fcl world and repaired by cuts (`planners.gcs.solve.checked_path`).
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
    region_iris: list[dict] = dataclasses.field(default_factory=list)
    offline_cpu_s: float | None = None

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
        return linked(self.edges, np.nonzero(inside[0])[0].tolist(), np.nonzero(inside[1])[0].tolist())

    # --- storage -------------------------------------------------------------------------------

    def save(self, path: Path) -> None:
        """Write atomically (workers of one run may build the same world side by side)."""
        sizes = np.array([len(b) for b in self.b], int)
        meta = {"format": FORMAT_VERSION, "world_hash": self.world_hash, "offline_s": self.offline_s,
                "problems": self.problems, "iris": self.iris, "region_build_s": self.region_build_s,
                "verified": self.checked, "region_iris": self.region_iris, "offline_cpu_s": self.offline_cpu_s}
        save_npz_atomically(
            path, sizes=sizes,
            A=np.concatenate(self.A) if self.A else np.zeros((0, 7)),
            b=np.concatenate(self.b) if self.b else np.zeros(0),
            seeds=np.array(self.seeds).reshape(-1, 7),
            edges=np.array(self.edges, int).reshape(-1, 2),
            meta=np.array(json.dumps(meta)),
        )

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
                       [tuple(map(int, e)) for e in z["edges"]], meta["iris"], list(meta.get("verified", [])),
                       list(meta.get("region_iris", [])), meta.get("offline_cpu_s"))


def problem_hash(problem, *, rule: str = CURRENT_RULE) -> str:
    """Identifies a problem's ends within its world (floats by identity rule `rule`)."""
    blob = hashed(np.concatenate([np.asarray(problem.q_start, float), np.asarray(problem.q_goal, float)]), rule=rule)
    return hashlib.sha1(blob.tobytes()).hexdigest()[:16]


def save_npz_atomically(path: Path, **arrays) -> None:
    """Write `arrays` to `path` (.npz, compressed) through a temporary file renamed into place,
    so that a reader never sees a half-written file (workers may build the same world side by
    side)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".npz.tmp")
    os.close(fd)
    with open(tmp, "wb") as f:
        np.savez_compressed(f, **arrays)
    os.chmod(tmp, 0o644)  # mkstemp makes it private; a region set is data others read
    os.replace(tmp, path)


def cache_dirs(cache_dir: str | Path | None, *, default: Path = DEFAULT_CACHE_DIR,
               subdir: str = "regions") -> list[Path]:
    """Where cached sets are looked up: the given (or `default`) cache, then every dataset's
    `subdir/` directory (region sets by default; `prm-roadmap`'s roadmaps in `roadmaps/`)."""
    first = Path(cache_dir) if cache_dir else default
    dirs = [first]
    if DATASETS_DIR.exists():
        dirs += sorted(p / subdir for p in DATASETS_DIR.iterdir() if (p / subdir).is_dir())
    return dirs


def find_cached(whash: str, cache_dir: str | Path | None, *, default: Path = DEFAULT_CACHE_DIR,
                subdir: str = "regions") -> Path | None:
    """The first `cache_dirs` file named after hash `whash`, or None."""
    for d in cache_dirs(cache_dir, default=default, subdir=subdir):
        path = d / f"{whash}.npz"
        if path.exists():
            return path
    return None


def reachable(edges: list, starts: list[int]) -> set[int]:
    """The regions the directed region graph `edges` leads to from `starts` (them included)."""
    adjacency: dict[int, list[int]] = {}
    for i, j in edges:
        adjacency.setdefault(i, []).append(j)
    seen, frontier = set(starts), list(starts)
    while frontier:
        for j in adjacency.get(frontier.pop(), []):
            if j not in seen:
                seen.add(j)
                frontier.append(j)
    return seen


def linked(edges: list, starts: list[int], targets: list[int]) -> bool:
    """Whether the directed region graph `edges` leads from a region of `starts` to one of `targets`."""
    return bool(reachable(edges, starts) & set(targets))
