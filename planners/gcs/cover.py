"""World-only seeding of `gcs`'s regions: from the collision world alone, never from a problem.

A world's regions must not depend on the problems planned in it (issue 31's fairness rule): no
problem's start, goal, reference or witness path. What the world offers besides its geometry is
its task: the scene's three named waypoints (`SceneSpec.waypoints`: above the plate, the middle
of the motion, above the bin; in `window` the middle waypoint is the centre of the opening). Like
the GCS paper's hand-placed iiwa seeds at its shelves and bins (Marcucci et al. 2023), both
strategies here start from the arm's configurations at those gripper poses:

- `task_chain`: collision-aware IK (`scenes.ik.PoseIk`) of the gripper poses along the task path
  plate -> middle -> bin (poses between the waypoints interpolated as the cycle interpolates them),
  each solved near the previous; consecutive configurations whose straight segment the python-fcl
  world finds in collision are joined by an RRT-Connect path of the world (a fixed seed). The
  result is a collision-free polyline through the task's passage, the world's roadmap.
- "chain" (`chain_seeds`): EI-ZO-style (Werner et al.): the polyline is cut into segments of at
  most `segment_rad`; each segment's midpoint seeds one IRIS region that must contain the segment's
  two ends (IRIS containment points; the segment is free, so their hull is), so consecutive regions
  share a vertex and the chain of regions is connected by construction.
- "cliques" (`clique_seeds`): a visibility clique cover (Werner, Amice, Marcucci, Rus, Tedrake,
  ICRA 2024) over samples of the task's neighbourhood (the polyline perturbed by a Gaussian of
  `sample_sigma_rad` per joint; uniform samples of the 7-D joint box almost never fall in a window
  opening): Drake's `VisibilityGraph` and greedy max cliques, one IRIS region per clique, grown
  from the clique's minimum-volume circumscribed ellipsoid; rounds of new samples outside the
  regions until the estimated coverage of that distribution reaches `coverage` or the regions
  their cap.

A scene that declares its own hand-placed seeds (`SceneSpec.region_seeds`, the GCS paper's scene
`gcs-arm`) gets one region per seed instead, as the paper grew them (`scene_seeds`): its gripper
poses solved by the paper's IK recipe, its joint-space seeds as given. They are the scene's, like
the waypoints, not any problem's.

All are built per world, offline; what a problem adds (joining its own start and goal to these
regions) is done online by `planners.gcs.planner`, inside its planning time.
"""

from __future__ import annotations

import logging
import time

import numpy as np

log = logging.getLogger(__name__)

#: Gripper poses interpolated between consecutive task waypoints (as the cycle's IK continuation).
POSES_BETWEEN = 2
#: RRT-Connect attempts (seeds) at joining two consecutive configurations of the chain.
RRT_ATTEMPTS = 3


def _between(X_a: np.ndarray, X_b: np.ndarray, n: int) -> list[np.ndarray]:
    """n poses evenly spaced strictly between X_a and X_b (position linear, rotation slerp)."""
    from pydrake.math import RigidTransform
    from pydrake.trajectories import PiecewisePose

    traj = PiecewisePose.MakeLinear([0.0, 1.0], [RigidTransform(X_a), RigidTransform(X_b)])
    return [traj.GetPose(k / (n + 1)).GetAsMatrix4() for k in range(1, n + 1)]


def scene_seeds(problem) -> tuple[list[tuple[str, np.ndarray]], dict]:
    """The scene's hand-placed region seeds (`SceneSpec.region_seeds`) as named configurations:
    its gripper poses by the GCS paper's IK recipe (`scenes.ik.paper_ik`, from its `q0_rad`), then
    its joint-space seeds. A seed whose IK fails or that collides in the problem's world is left
    out and named in `info["seeds_dropped"]`."""
    from planners.worlds import drake_plan_scene, planning_world
    from scenes.ik import paper_ik
    from scenes.robot_model import transform

    spec = problem.scene.spec.region_seeds
    world = planning_world(problem)
    t0 = time.perf_counter()
    ds = drake_plan_scene(problem)
    named = [(n, paper_ik(ds, transform(p.p_m, p.rpy_rad), spec.q0_rad)) for n, p in spec.poses.items()]
    named += [(n, np.asarray(q, float)) for n, q in spec.joints_rad.items()]
    usable = [q is not None and world.is_free(q) for _, q in named]
    kept = [nq for nq, ok in zip(named, usable) if ok]
    return kept, {"seeds_from": "scene", "ik_s": time.perf_counter() - t0, "seeds": [n for n, _ in kept],
                  "seeds_dropped": [n for (n, _), ok in zip(named, usable) if not ok]}


def task_chain(problem, *, seed: int, rrt_time_s: float = 2.0) -> tuple[np.ndarray | None, dict]:
    """The world's task polyline (K, 7): IK of the task path's gripper poses, joined by free
    straight segments or RRT-Connect paths (the shortest, once shortcut, of RRT_ATTEMPTS seeds of
    `rrt_time_s` each; a pair none joins stays a blocked segment, counted in `gaps`). A pose whose
    IK near the previous configuration fails is solved with restarts. Uses the problem's world only (scene,
    held can, finger opening, removed cans), never its start or goal.

    Returns:
        (polyline or None if fewer than two poses have IK, info: ik_s, rrt_s, poses, poses_solved,
        rrt_joins, gaps (consecutive poses left unjoined)).
    """
    from planners.worlds import drake_plan_scene, planning_world
    from scenes.grasp_rule import waypoint_pose
    from scenes.ik import Q_READY, IkOptions, PoseIk

    world = planning_world(problem)
    t0 = time.perf_counter()
    problem.scene.spec.require("waypoints", needed_by="gcs's task chain (a scene without waypoints gives its region_seeds)")
    wp = problem.scene.spec.waypoints
    X_plate, X_middle, X_bin = (waypoint_pose(p) for p in (wp.above_plate_m, wp.middle_m, wp.above_bin_m))
    poses = [X_plate, *_between(X_plate, X_middle, POSES_BETWEEN), X_middle,
             *_between(X_middle, X_bin, POSES_BETWEEN), X_bin]
    ik = PoseIk(drake_plan_scene(problem))
    rng = np.random.default_rng([seed, 31])
    near = IkOptions(restarts=0, near_sigmas_rad=(0.1,), major_iterations=30, min_distance_m=0.002)
    full = IkOptions(min_distance_m=0.002)
    q, vertices = Q_READY, []
    for k, X in enumerate(poses):
        qn = ik.solve(X, q_seed=q, rng=rng, options=full if k == 0 else near)
        if qn is None and k > 0:  # off the branch: restarts (kept nearest the previous one)
            qn = ik.solve(X, q_seed=q, rng=rng, options=full)
        if qn is not None and world.is_free(qn):
            vertices.append(np.asarray(qn, float))
            q = qn
    info = {"ik_s": time.perf_counter() - t0, "poses": len(poses), "poses_solved": len(vertices),
            "rrt_joins": 0, "gaps": 0, "rrt_s": 0.0}
    if len(vertices) < 2:
        return None, info
    t1 = time.perf_counter()
    out = [vertices[0]]
    for a, b in zip(vertices, vertices[1:]):
        if world.motion_free(a, b, resolution_rad=0.01):
            out.append(b)
            continue
        found = []  # the shortest of RRT_ATTEMPTS shortcut RRT-Connect paths (RRT paths wander)
        for attempt in range(RRT_ATTEMPTS):
            path = _rrt_join(problem, a, b, seed=seed + attempt, time_s=rrt_time_s)
            if path is not None:
                path = shortcut(path, world)
                found.append((float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1))), attempt, path))
        if not found:  # left as a blocked segment: its region grows without containment
            info["gaps"] += 1
            out.append(b)
            continue
        info["rrt_joins"] += 1
        out += list(min(found, key=lambda t: t[:2])[2][1:])
    info["rrt_s"] = time.perf_counter() - t1
    return np.array(out), info


def _rrt_join(problem, a: np.ndarray, b: np.ndarray, *, seed: int, time_s: float) -> np.ndarray | None:
    """An RRT-Connect path a -> b in the problem's world (OMPL, python-fcl), shortcut by OMPL's
    simplifier, or None."""
    from planners.ompl_rrt import RRTConnectPlanner

    joined = problem.with_(q_start=np.asarray(a, float), q_goal=np.asarray(b, float), time_limit_s=time_s,
                           seed=seed, pre_status=None)
    result = RRTConnectPlanner().plan(joined)
    return None if result.path is None else np.asarray(result.path, float)


def shortcut(path: np.ndarray, world, *, resolution_rad: float = 0.01) -> np.ndarray:
    """Greedy shortcutting: from each kept vertex, a far later vertex reachable by a free straight
    motion (python-fcl), found by doubling the stride and then bisecting, so a long, dense RRT
    path costs O(n log n) motion checks, not O(n^2)."""
    def free(i, j):
        return world.motion_free(path[i], path[j], resolution_rad=resolution_rad)

    out, i, n = [path[0]], 0, len(path)
    while i < n - 1:
        good, step = i + 1, 1
        while good + step < n and free(i, good + step):
            good += step
            step *= 2
        lo, hi = good, min(good + step, n)  # lo reachable; hi (or beyond) not known to be
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if free(i, mid):
                lo = mid
            else:
                hi = mid
        out.append(path[lo])
        i = lo
    return np.array(out)


def split_polyline(path: np.ndarray, max_step_rad: float) -> np.ndarray:
    """The polyline's vertices with points inserted so no segment is longer than max_step_rad."""
    out = [path[0]]
    for a, b in zip(path, path[1:]):
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / max_step_rad)))
        out += [a + (b - a) * k / n for k in range(1, n + 1)]
    return np.array(out)


def chain_seeds(chain: np.ndarray, *, segment_rad: float, max_regions: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """(seed, containment points (7, m)) per region: the chain cut into pieces of at most
    `segment_rad` (longer pieces if that gives more than `max_regions`), the seed at each piece's
    midpoint and its two ends to contain. A chain with more segments than `max_regions` (an
    RRT-joined stretch) gets one region per segment, up to twice `max_regions`; beyond that it is
    cut by arc length into `max_regions` stretches: the seed at a stretch's middle (on the chain)
    and the stretch's two ends to contain (IRIS grows the region without containment if the
    segment between them collides)."""
    if len(chain) - 1 > max_regions:
        if len(chain) - 1 <= 2 * max_regions:
            # One region per segment: each contains its (free) segment, so they chain up; more
            # regions cost GCS time, but stretches between non-adjacent vertices would not chain.
            return [(0.5 * (a + b), np.column_stack([a, b])) for a, b in zip(chain, chain[1:])]
        seg = np.linalg.norm(np.diff(chain, axis=0), axis=1)
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        cuts = np.linspace(0.0, cum[-1], max_regions + 1)

        def at(s: float) -> np.ndarray:
            i = int(np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1))
            return chain[i] + (s - cum[i]) / max(seg[i], 1e-12) * (chain[i + 1] - chain[i])

        # Only the stretch's ends are contained: with its inner vertices too, IrisNp2 aborted
        # (Drake 1.51, ComputeFaceTangentToDistCvxh) on a window world's RRT-joined stretch.
        return [(at(0.5 * (s0 + s1)), np.column_stack([at(s0), at(s1)])) for s0, s1 in zip(cuts, cuts[1:])]
    length = float(np.sum(np.linalg.norm(np.diff(chain, axis=0), axis=1)))
    step = max(segment_rad, length / max_regions)
    pts = split_polyline(chain, step)
    while len(pts) - 1 > max_regions:  # the chain's own vertices add pieces (at most max_regions of them)
        step *= 1.15
        pts = split_polyline(chain, step)
    return [(0.5 * (a + b), np.column_stack([a, b])) for a, b in zip(pts, pts[1:])]


def task_samples(chain: np.ndarray, *, n: int, sigma_rad: float, rng: np.random.Generator, lower: np.ndarray,
                 upper: np.ndarray) -> np.ndarray:
    """n configurations of the task's neighbourhood: a point uniform along the chain (by length)
    plus an isotropic Gaussian of `sigma_rad` per joint, clipped to the joint limits. Not checked
    for collision."""
    seg = np.linalg.norm(np.diff(chain, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    s = rng.uniform(0.0, cum[-1], n)
    i = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1)
    t = ((s - cum[i]) / np.maximum(seg[i], 1e-12))[:, None]
    base = chain[i] + t * (chain[i + 1] - chain[i])
    return np.clip(base + rng.normal(0.0, sigma_rad, base.shape), lower, upper)


def free_task_samples(chain: np.ndarray, *, n: int, sigma_rad: float, rng: np.random.Generator, world,
                      max_draws: int | None = None) -> np.ndarray:
    """Up to n collision-free (python-fcl) task-neighbourhood samples (`task_samples`)."""
    lower, upper = world.robot.lower_rad, world.robot.upper_rad
    got: list[np.ndarray] = []
    draws = 0
    max_draws = max_draws or 20 * n
    while sum(len(g) for g in got) < n and draws < max_draws:
        Q = task_samples(chain, n=n, sigma_rad=sigma_rad, rng=rng, lower=lower, upper=upper)
        draws += n
        got.append(Q[world.states_free(Q)])
    Q = np.concatenate(got) if got else np.zeros((0, 7))
    return Q[:n]


def clique_seeds(checker, samples: np.ndarray, *, min_clique: int, max_cliques: int) -> list[tuple[np.ndarray, object]]:
    """(seed, starting ellipsoid) per clique of the samples' visibility graph (Drake's
    `VisibilityGraph` on the checker, greedy max cliques taken out one after another while at least
    `min_clique` large). The seed is the ellipsoid's centre if it is free, else the clique's point
    nearest it."""
    from pydrake.common import Parallelism
    from pydrake.geometry.optimization import Hyperellipsoid
    from pydrake.planning import MaxCliqueSolverViaGreedy, VisibilityGraph

    if len(samples) < min_clique:
        return []
    t0 = time.perf_counter()
    adj = VisibilityGraph(checker, np.asfortranarray(samples.T), Parallelism(1)).tolil()
    log.debug("visibility graph of %d samples in %.1f s", len(samples), time.perf_counter() - t0)
    alive = np.ones(len(samples), bool)
    solver = MaxCliqueSolverViaGreedy()
    out = []
    while len(out) < max_cliques and alive.sum() >= min_clique:
        idx = np.flatnonzero(alive)
        sub = adj[idx][:, idx].tocsc()
        mask = np.asarray(solver.SolveMaxClique(sub), bool).ravel()
        if mask.sum() < min_clique:
            break
        members = idx[mask]
        alive[members] = False
        P = samples[members]
        try:
            E = Hyperellipsoid.MinimumVolumeCircumscribedEllipsoid(np.asfortranarray(P.T), 1e-6)
        except RuntimeError:  # the clique spans less than 7 dimensions
            continue
        center = E.center()
        if not checker.CheckConfigCollisionFree(center):
            center = P[np.argmin(np.linalg.norm(P - center, axis=1))]
            E = Hyperellipsoid(E.A(), center)
        out.append((np.asarray(center, float), E))
    return out
