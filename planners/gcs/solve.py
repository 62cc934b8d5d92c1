"""Solving `gcs` through a set of convex regions, and repairing the regions where the path collides.

`solve_gcs` is one GcsTrajectoryOptimization shortest-path solve (convex relaxation, randomized
rounding, restriction) with Clarabel or SCS; `checked_path` checks its path with the python-fcl
world as the validator does and, where it collides, cuts that configuration off the regions
holding it (`cut_regions`, `cut_at_collision`) and solves again. Used online by `planners.gcs.planner` and
offline by `planners.gcs.regions` when it verifies a world's regions.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from planners.base import Budget
from planners.gcs.sets import RegionSet, linked, reachable

SOLVERS = ("clarabel", "scs")


def cut_at_collision(A: np.ndarray, b: np.ndarray, *, world, center: np.ndarray, q_bad: np.ndarray,
                     keep: list[np.ndarray], margin_rad: float, resolution_rad: float = 0.01):
    """Add a face to {A q <= b} that cuts off the first python-fcl collision on the segment from a
    free configuration inside (`center`, else one of `keep`) towards `q_bad`, `margin_rad` short of
    it and normal to that segment, keeping every configuration in `keep` inside. Returns (A, b),
    unchanged if no such cut exists."""
    for c in [center, *keep]:
        c = np.asarray(c, float)
        if np.linalg.norm(q_bad - c) < 1e-9:
            continue
        dense = world.interpolate(np.stack([c, q_bad]), resolution_rad)
        k = world.first_collision(dense)
        if k <= 0:
            continue
        d = dense[k] - c
        dist = float(np.linalg.norm(d))
        n = d / dist
        offset = float(n @ c) + max(dist - margin_rad, 0.5 * dist)
        if all(float(n @ q) <= offset for q in keep):
            return np.vstack([A, n]), np.append(b, offset)
    return _separating_cut(A, b, world=world, center=np.asarray(center, float), q_bad=q_bad, keep=keep,
                           margin_rad=margin_rad, resolution_rad=resolution_rad)


def _separating_cut(A: np.ndarray, b: np.ndarray, *, world, center: np.ndarray, q_bad: np.ndarray,
                    keep: list[np.ndarray], margin_rad: float, resolution_rad: float):
    """The cut of last resort: a face normal to the shortest segment from the convex hull of the
    center and `keep` to the first collision met going from the center towards `q_bad` (any point
    outside that hull can be separated from it by such a face), `margin_rad` short of the collision
    where the hull leaves room. Returns (A, b), unchanged if the collision lies in the hull."""
    from scipy.optimize import nnls

    dense = world.interpolate(np.stack([center, q_bad]), resolution_rad)
    k = world.first_collision(dense)
    x = dense[k] if k > 0 else np.asarray(q_bad, float)
    P = np.array([center, *keep], float)
    w = 1e3  # weight of the row that makes the coefficients sum to one
    lam, _ = nnls(np.vstack([P.T, w * np.ones(len(P))]), np.append(x, w))
    d = x - lam @ P
    dist = float(np.linalg.norm(d))
    if dist < 1e-6:
        return A, b
    n = d / dist
    inner = max(float(n @ p) for p in P)
    gap = float(n @ x) - inner
    if gap <= 1e-9:
        return A, b
    offset = float(n @ x) - min(margin_rad, 0.5 * gap)
    return np.vstack([A, n]), np.append(b, offset)


def cut_regions(A: list, b: list, edges: list, seeds: list, q_bad: np.ndarray, *, keep: list[np.ndarray],
                world) -> int:
    """Cut `q_bad` off every region holding it (A, b, edges changed in place), keeping the
    configurations of `keep` that a region holds; if no face keeps them all (the collision lies
    between them: the region's segment joining them collides), keeping only those no other region
    holds, so that every configuration of `keep` stays covered. Returns the number of regions cut."""
    from pydrake.geometry.optimization import HPolyhedron

    def holds(i: int, q: np.ndarray) -> bool:
        return bool(np.all(A[i] @ q <= b[i] + 1e-9))

    cuts = 0
    for i in range(len(A)):
        if not holds(i, q_bad):
            continue
        inside = [q for q in keep if holds(i, q)]
        center = np.asarray(seeds[i], float)
        A2, b2 = cut_at_collision(A[i], b[i], world=world, center=center, q_bad=q_bad, keep=inside, margin_rad=0.01)
        if len(b2) == len(b[i]):
            only_here = [q for q in inside if not any(holds(j, q) for j in range(len(A)) if j != i)]
            if len(only_here) < len(inside):
                A2, b2 = cut_at_collision(A[i], b[i], world=world, center=center, q_bad=q_bad, keep=only_here,
                                          margin_rad=0.01)
        if len(b2) == len(b[i]):
            continue
        cuts += 1
        A[i], b[i] = A2, b2
        poly = HPolyhedron(A2, b2)
        edges[:] = [e for e in edges if i not in e]
        for j in range(len(A)):
            if j != i and poly.IntersectsWith(HPolyhedron(A[j], b[j])):
                edges += [(i, j), (j, i)]
    return cuts



def usable_regions(A: list, b: list) -> list[int]:
    """Indices of the regions {A_i q <= b_i} that GCS can take: non-empty and bounded. Cuts can
    empty a region; Drake's GcsTrajectoryOptimization computes every region's bounding box when it
    joins subgraphs and throws on an empty or unbounded one ("Failed to compute the lower bound of
    a convex set")."""
    from pydrake.geometry.optimization import HPolyhedron

    keep = []
    for i, (Ai, bi) in enumerate(zip(A, b)):
        poly = HPolyhedron(np.asarray(Ai, float), np.asarray(bi, float))
        if not poly.IsEmpty() and poly.IsBounded():
            keep.append(i)
    return keep


def join_endpoint(A: list, b: list, q: np.ndarray, *, world, resolution_rad: float = 0.01,
                  inset_rad: float = 0.02, budget: Budget | None = None,
                  among: set[int] | None = None) -> tuple[list[int], np.ndarray | None, int]:
    """Join a configuration to the regions {A_i q <= b_i} online (planning time).

    If regions hold q, nothing is added. Otherwise, regions are tried in order of their distance
    to q: the nearest point of the region, moved `inset_rad` towards the region's Chebyshev
    centre (inside the region, not on its face), is joined to q by a straight segment if the
    python-fcl world finds that segment free at `resolution_rad`; GCS then plans from (to) that
    point and the segment is prepended (appended). (A segment as one more convex set of the graph,
    a VPolytope of its two ends, made Drake's relaxation infeasible in our trials.)

    With `among`, only those regions are considered, and by a segment even if another region
    holds q (to reach the other end's part of a disconnected region graph).

    Returns:
        (regions holding q or entered by the segment, the segment's far end or None if q is held,
        regions tried). ([], None, tried) when nothing joins q.
    """
    from pydrake.geometry.optimization import HPolyhedron

    q = np.asarray(q, float)
    holding = [i for i in range(len(A)) if np.all(A[i] @ q <= b[i] + 1e-9)]
    if holding and among is None:
        return holding, None, 0
    near = []
    for i in usable_regions(A, b):
        if among is not None and (i not in among or i in holding):
            continue
        poly = HPolyhedron(np.asarray(A[i], float), np.asarray(b[i], float))
        found = poly.Projection(q.reshape(-1, 1))
        if found is None:
            continue
        dist, points = found
        near.append((float(dist[0]), i, points[:, 0], poly))
    near.sort(key=lambda t: t[0])
    tried = 0
    for _, i, p, poly in near:
        if budget is not None and budget.expired():
            break
        tried += 1
        c = poly.ChebyshevCenter()
        d = c - p
        n = float(np.linalg.norm(d))
        p_in = p + d * min(1.0, inset_rad / n) if n > 1e-12 else p
        if world.motion_free(q, p_in, resolution_rad=resolution_rad):
            return [i], p_in, tried
    return [], None, tried


def connect_ends(A: list, b: list, edges: list, q_start: np.ndarray, q_goal: np.ndarray, *, world,
                 resolution_rad: float = 0.01, budget: Budget | None = None) -> dict:
    """Join start and goal to the regions (`join_endpoint`) and say whether the region graph
    links them.

    Returns:
        {"connected": bool, "start_join"/"goal_join": "inside", "segment" or "none",
        "start_join_tried"/"goal_join_tried": regions tried, "ends": the configurations GCS plans
        between (an end itself, or the far end of its joining segment)}.
    """
    out: dict = {"ends": []}
    held = []
    for name, q in (("start", q_start), ("goal", q_goal)):
        regions, p, tried = join_endpoint(A, b, q, world=world, resolution_rad=resolution_rad, budget=budget)
        out[f"{name}_join"] = "inside" if regions and p is None else ("segment" if regions else "none")
        out[f"{name}_join_tried"] = tried
        out["ends"].append(np.asarray(q if p is None else p, float))
        held.append(regions)
    out["connected"] = bool(held[0] and held[1] and linked(edges, held[0], held[1]))
    if held[0] and held[1] and not out["connected"]:
        # The ends sit in parts of the region graph that do not meet: join one end by a free
        # segment straight into the other end's part.
        for k, (name, q) in enumerate((("start", q_start), ("goal", q_goal))):
            other = reachable(edges, held[1 - k])
            regions, p, tried = join_endpoint(A, b, q, world=world, resolution_rad=resolution_rad,
                                              budget=budget, among=other)
            out[f"{name}_join_tried"] += tried
            if regions:
                out[f"{name}_join"] = "segment"
                out["ends"][k] = np.asarray(p, float)
                out["connected"] = True
                break
    return out


def _solver(name: str):
    from pydrake.solvers import ClarabelSolver, ScsSolver

    return {"clarabel": ClarabelSolver, "scs": ScsSolver}[name]()


def sample_trajectory(traj, *, order: int, step_rad: float) -> np.ndarray:
    """Waypoints (N, 7) of a composite Bezier trajectory: segment ends for straight segments,
    samples at most about `step_rad` apart on curved ones; repeated points dropped."""
    points = []
    for i in range(traj.get_number_of_segments()):
        seg = traj.segment(i)
        t0, t1 = seg.start_time(), seg.end_time()
        a, b = seg.value(t0).ravel(), seg.value(t1).ravel()
        if order <= 1 or np.allclose(a, b):
            ts = [t0, t1]
        else:
            coarse = np.array([seg.value(t).ravel() for t in np.linspace(t0, t1, 9)])
            length = np.linalg.norm(np.diff(coarse, axis=0), axis=1).sum()
            ts = np.linspace(t0, t1, max(2, int(np.ceil(length / step_rad)) + 1))
        points += [seg.value(t).ravel() for t in ts]
    out = [points[0]]
    for p in points[1:]:
        if np.linalg.norm(p - out[-1]) > 1e-9:
            out.append(p)
    return np.array(out)


def solve_gcs(A: list, b: list, edges: list, q_start: np.ndarray, q_goal: np.ndarray, *, order: int = 1,
              max_rounded_paths: int = 5, solver: str = "clarabel", seed: int = 0):
    """One GCS shortest-path solve (convex relaxation, rounding, restriction) through the regions
    {A_i q <= b_i} joined by `edges`, from the point q_start to the point q_goal. Regions that cuts
    left empty (or unbounded) are left out (`usable_regions`).

    Returns:
        (trajectory, MathematicalProgramResult).
    """
    from pydrake.geometry.optimization import (
        GraphOfConvexSetsOptions,
        HPolyhedron,
        Point,
    )
    from pydrake.planning import GcsTrajectoryOptimization

    gcs = GcsTrajectoryOptimization(len(q_start))
    keep = usable_regions(A, b)
    index = {old: new for new, old in enumerate(keep)}
    edges = [(index[i], index[j]) for i, j in edges if i in index and j in index]
    main = gcs.AddRegions([HPolyhedron(A[i], b[i]) for i in keep], edges, order, name="regions")
    source = gcs.AddRegions([Point(q_start)], 0, name="start")
    target = gcs.AddRegions([Point(q_goal)], 0, name="goal")
    gcs.AddEdges(source, main)
    gcs.AddEdges(main, target)
    gcs.AddPathLengthCost(1.0)
    options = GraphOfConvexSetsOptions()
    options.convex_relaxation = True
    options.preprocessing = True
    options.max_rounded_paths = max_rounded_paths
    options.rounding_seed = int(seed) % (2**31)
    options.solver = _solver(solver)
    drake_log = logging.getLogger("drake")
    level = drake_log.level
    drake_log.setLevel(logging.WARNING)  # Drake logs every solve and rounding at INFO
    try:
        return gcs.SolvePath(source, target, options)
    finally:
        drake_log.setLevel(level)


def checked_path(A: list, b: list, edges: list, seeds: list, q_start: np.ndarray, q_goal: np.ndarray, *, world,
                 order: int = 1, max_rounded_paths: int = 5, solver: str = "clarabel", seed: int = 0,
                 max_repairs: int = 5, check_resolution_rad: float = 0.01, sample_step_rad: float = 0.02,
                 budget: Budget | None = None) -> tuple[np.ndarray | None, dict]:
    """Solve, check the path with the python-fcl world as the validator does, and where it collides
    cut the colliding configuration off the regions holding it (A, b, edges are changed in place)
    and solve again, up to `max_repairs` times or the end of `budget` (None: no limit; a GCS
    solve itself runs to its end: the budget is checked between solves).

    Returns:
        (path (N, 7) or None, stats: solver_status, cost, repairs, cuts, first_solve_s and
        gcs_solve_s (the first and all GCS solves, s), reason when None, and timed_out when the
        budget stopped the repairs).
    """
    lower, upper = world.robot.lower_rad, world.robot.upper_rad
    stats: dict = {"repairs": 0, "cuts": 0}
    stats["gcs_solve_s"] = 0.0
    for attempt in range(max_repairs + 1):
        t_solve = time.perf_counter()
        traj, result = solve_gcs(A, b, edges, q_start, q_goal, order=order, max_rounded_paths=max_rounded_paths,
                                 solver=solver, seed=seed)
        stats["gcs_solve_s"] += time.perf_counter() - t_solve
        stats.setdefault("first_solve_s", stats["gcs_solve_s"])
        stats["solver_status"] = result.get_solution_result().name
        if not result.is_success():
            stats["reason"] = f"GCS failed ({stats['solver_status']})"
            return None, stats
        stats["cost"] = float(result.get_optimal_cost())
        path = sample_trajectory(traj, order=order, step_rad=sample_step_rad)
        if np.max(np.abs(path[0] - q_start)) > 1e-4 or np.max(np.abs(path[-1] - q_goal)) > 1e-4:
            stats["reason"] = "the solution does not join start and goal"
            return None, stats
        path[0], path[-1] = q_start, q_goal
        path = np.clip(path, lower, upper)
        if max_repairs == 0:
            return path, stats  # unchecked: the validator judges it
        # Sampled regions are not certified: check as the validator does, cut the colliding
        # configuration off the regions holding it, and solve again.
        dense = world.interpolate(path, check_resolution_rad)
        k = world.first_collision(dense)
        if k < 0:
            return path, stats
        if budget is not None and budget.expired():
            stats["reason"] = "the planning budget ran out while repairing a colliding path"
            stats["timed_out"] = True
            return None, stats
        if attempt == max_repairs:
            stats["reason"] = "the path through the regions still collides"
            return None, stats
        cut = cut_regions(A, b, edges, seeds, dense[k], keep=[q_start, q_goal], world=world)
        stats["repairs"] = attempt + 1
        stats["cuts"] += cut
        if cut == 0:
            stats["reason"] = "the path through the regions collides and cannot be cut"
            return None, stats
    return None, stats


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


def uniform_samples(poly, n: int, gen, *, mixing_steps: int) -> np.ndarray:
    """Up to `n` uniform samples of the H-polyhedron `poly` (Drake's hit-and-run
    `UniformSample`, `mixing_steps` apart, from its Chebyshev centre: strictly inside, where a seed
    may lie on a face), drawn with `gen`; fewer in a sliver the sampler cannot move in (what was
    drawn until then). Returns an (m, dim) array, m <= n."""
    x = poly.ChebyshevCenter()
    Q = []
    try:
        for _ in range(n):
            x = poly.UniformSample(gen, x, mixing_steps)
            Q.append(x)
    except ValueError:  # a sliver the sampler cannot move in
        pass
    return np.array(Q).reshape(len(Q), poly.ambient_dimension())


def check_with_world(A: np.ndarray, b: np.ndarray, *, world, center: np.ndarray, keep: list[np.ndarray],
                     samples: int, rounds: int, margin_rad: float, seed: int):
    """Cut a region where the python-fcl world (the validator's engine) finds collisions among
    uniform samples (hit-and-run), for up to `rounds` rounds. Returns (A, b, cuts)."""
    from pydrake.common import RandomGenerator
    from pydrake.geometry.optimization import HPolyhedron

    gen = RandomGenerator(seed)
    cuts = 0
    for _ in range(rounds):
        Q = uniform_samples(HPolyhedron(A, b), samples, gen, mixing_steps=5)
        if not len(Q):
            break
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
