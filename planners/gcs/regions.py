"""A world's collision-free convex regions for `gcs`: seeded, grown, checked, connected and cached.

Each region is grown by Drake's sampled IRIS on the plan-mode Drake scene of a problem's collision
world (`planners.gcs.iris.RegionBuilder`: `IrisNp2` by default, `IrisZo` as an option).

Seeding. By default from the world alone (`seeding` "chain" or "cliques", `planners.gcs.cover`,
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
the python-fcl world and the colliding configurations cut off (`planners.gcs.solve.checked_path`),
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

import itertools
import time
from pathlib import Path

import numpy as np

from planners.gcs.iris import RegionBuilder, inscribed_volume, make_checker, quiet_drake
from planners.gcs.sets import DEFAULT_CACHE_DIR, WORLD_BUILT, RegionOptions, RegionSet, find_cached, problem_hash, world_hash
from planners.gcs.solve import check_with_world, checked_path, cut_blocked_segment

#: Offline rounds of connect (guide path), solve, check and cut per problem.
VERIFY_ROUNDS = 3


def _guide_path(problem, options: RegionOptions) -> np.ndarray | None:
    """The straight segment if free in the python-fcl world, else an RRT-Connect path, or None."""
    from planners.worlds import planning_world

    world = planning_world(problem)
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
    t0, c0 = time.perf_counter(), time.process_time()
    n0 = len(rs)
    q0, q1 = np.asarray(problem.q_start, float), np.asarray(problem.q_goal, float)
    added = 0
    from planners.worlds import planning_world

    world = planning_world(problem)

    def add(q, contain=None) -> bool:
        nonlocal added
        containment = None if contain is None else np.column_stack([q, contain])
        if not _add_region(rs, builder, world, q, containment=containment, keep=(q0, q1)):
            return False
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
    rs.offline_cpu_s = (rs.offline_cpu_s or 0.0) + time.process_time() - c0
    return added


def _add_region(rs: RegionSet, builder: RegionBuilder, world, q: np.ndarray, *, containment: np.ndarray | None = None,
                ellipsoid=None, keep: tuple = ()) -> bool:
    """Grow one region at q, check it with the python-fcl world (cuts keep q, the containment
    points and `keep` where the region holds them) and append it to `rs`."""
    o = builder.options
    grown = builder.grow(q, containment=containment, ellipsoid=ellipsoid)
    if grown is None:
        return False
    A, b, dt, iris = grown
    if o.check_rounds > 0:
        t1 = time.perf_counter()
        # q, then the containment points other than q itself, then `keep`
        held = [q, *([] if containment is None else [c for c in containment.T if not np.array_equal(c, q)]), *keep]
        inside = [p for p in held if np.all(A @ p <= b + 1e-9)]
        A, b, _ = check_with_world(A, b, world=world, center=np.asarray(q, float), keep=inside,
                                   samples=o.check_samples, rounds=o.check_rounds,
                                   margin_rad=o.configuration_space_margin_rad, seed=o.random_seed + len(rs))
        dt += time.perf_counter() - t1
    rs.A.append(A)
    rs.b.append(b)
    rs.seeds.append(np.asarray(q, float))
    rs.region_build_s.append(dt)
    rs.region_iris.append({**iris, **inscribed_volume(A, b)})
    return True


def coverage_of(rs: RegionSet, samples: np.ndarray) -> float:
    """The fraction of `samples` (collision-free configurations) inside some region."""
    if len(samples) == 0 or len(rs) == 0:
        return 0.0
    return float(rs.contains(samples).any(axis=1).mean())


def grow_for_world(rs: RegionSet, problem, builder: RegionBuilder) -> dict:
    """Grow `rs` from the problem's collision world alone (its task chain, `planners.gcs.cover`),
    never from the problem's start, goal or paths; then solve GCS between the chain's ends, check
    its path with the python-fcl world and cut what collides (`checked_path`). Returns the build's
    figures (chain, regions, seconds)."""
    from planners.gcs.cover import chain_seeds, clique_seeds, free_task_samples, scene_seeds, task_chain
    from planners.worlds import planning_world

    o = builder.options
    t0, c0 = time.perf_counter(), time.process_time()
    world = planning_world(problem)
    if problem.scene.spec.region_seeds is not None:  # the scene's own hand-placed seeds
        chain = None
        named, info = scene_seeds(problem)
        for _, q in named:
            _add_region(rs, builder, world, q)
        update_edges(rs, 0)
        info["edges"] = len(rs.edges) // 2
    else:
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
    rs.offline_cpu_s = (rs.offline_cpu_s or 0.0) + time.process_time() - c0
    info["offline_s"] = rs.offline_s
    info["offline_cpu_s"] = rs.offline_cpu_s
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
