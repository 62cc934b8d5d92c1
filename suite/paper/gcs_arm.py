"""The GCS paper's arm experiment: its scene, its five tasks, and the `gcs-arm-v2` dataset.

Marcucci, Petersen, von Wrangel and Tedrake, "Motion planning around obstacles with convex
optimization" (Science Robotics 2023; arXiv 2205.04422), section "GCS vs PRM": a KUKA iiwa 14
with a welded WSG 50 among shelves and two bins, five tasks between gripper poses. Every number
below comes from the paper's repository, RobotLocomotion/gcs-science-robotics at 3d781488,
`reproduction/prm_comparison/` (docs/gcs-paper-sources.md, section 7, gives each one's file).

- The scene is the spec variant `gcs-arm` (scenes/specs/default.yaml) with the robot variant
  `iiwa14-spheres`; its 8 hand-placed region seeds are the scene's own (`region_seeds`). It is no
  can station: shelves and two bins as obstacles, no plate, bin, cans or waypoints.
- The tasks' end configurations are the paper's IK recipe (`scenes.ik.paper_ik`) at the
  demonstration poses (`TASK_POSES`), from the same q0 as the seeds.
- The dataset holds the five tasks and their reverses, as free transits (kind `free`, nothing
  held, numbered by their `task_index` 0-9), each with the straight gripper-pose interpolation
  between its ends as the task waypoints the nominal-IK planner follows, and with a certified
  best known path from the suite's offline search (`suite.run.best_known.search_job`).
- `gcs-arm`, the dataset's first revision, holds the same tasks in the same free space, posed as
  `transit`s numbered as cans 0-9 in the scene with a stand-in plate buried in the table (when a
  spec needed one); its specs and ids are stored with it and do not move.
"""

from __future__ import annotations

import datetime as dt
import json
import math
import sys
import time
from typing import Any

import numpy as np

from scenes.errors import SuiteError

#: The scene's variant and its one seed (the scene has no random part: no cans).
VARIANT = "gcs-arm"
SCENE_SEED = 0
#: The dataset `paper gcs-arm dataset` builds from this scene (the first revision: `gcs-arm`).
DATASET = "gcs-arm-v2"
_SHELF_RPY = (0.0, -math.pi, -math.pi / 2)
#: The demonstration poses (gripper body frame in the world: position m, roll-pitch-yaw rad):
#: the seeds' orientations at shifted positions (the notebook's task poses).
TASK_POSES = {
    "AS": ((0.75, -0.12, 0.9), _SHELF_RPY),
    "TS": ((0.75, 0.12, 0.67), _SHELF_RPY),
    "CS": ((0.75, 0.12, 0.41), _SHELF_RPY),
    "LB": ((0.08, 0.6, 0.22), (math.pi / 2, math.pi, 0.0)),
    "RB": ((-0.08, -0.6, 0.22), (math.pi / 2, math.pi, math.pi)),
}
#: The five tasks, in the paper's order (the notebook labels task 3 "BS->LB" and task 5
#: "RB->TS"; both ends are as here).
TASKS = (("AS", "TS"), ("TS", "CS"), ("CS", "LB"), ("LB", "RB"), ("RB", "AS"))
#: The schedule span of a task (time units of the nominal-IK planner's schedule, 1 s each): the
#: transit's, as in the suite's cycle.
TASK_SPAN_TU = (18.0, 30.0)


def paper_scene():
    """The `gcs-arm` scene (a concrete world: no can station, no random part)."""
    from scenes.generate import generate_scene
    from scenes.spec import load_spec

    return generate_scene(load_spec(variant=VARIANT), seed=SCENE_SEED)


def task_configurations(scene) -> dict[str, np.ndarray]:
    """The paper's IK recipe at each demonstration pose, from the scene's q0.

    Raises:
        SuiteError: an IK that fails, or a configuration in collision (the scene is not the paper's).
    """
    from scenes.drake_scene import build_drake_scene
    from scenes.collision.world import CollisionWorld
    from scenes.ik import paper_ik
    from scenes.robot_model import transform

    ds = build_drake_scene(scene, mode="plan", cameras=False)
    world = CollisionWorld(scene)
    q0 = np.asarray(scene.spec.region_seeds.q0_rad, float)
    out = {}
    for name, (p, rpy) in TASK_POSES.items():
        q = paper_ik(ds, transform(p, rpy), q0)
        if q is None:
            raise SuiteError(f"the paper's IK failed at task pose {name} {p}")
        if not world.is_free(q):
            raise SuiteError(f"task pose {name}'s configuration collides in scene {VARIANT}")
        out[name] = q
    return out


def task_label(a: str, b: str) -> str:
    return f"{a}->{b}"


def task_problems(scene=None, *, time_limit_s: float = 5.0, reverses: bool = True) -> list[tuple[str, Any]]:
    """(label, PlanningProblem) for the five tasks (then their reverses): free transits between
    the IK configurations, with the straight gripper-pose interpolation between the two poses as
    their task waypoints, numbered by their `task_index` (0-9; no can is picked)."""
    from planners.base import FREE_TRANSIT, PlanningProblem, TaskWaypoint
    from scenes.robot_model import load_robot

    scene = scene or paper_scene()
    q = task_configurations(scene)
    robot = load_robot(scene.spec.robot)
    pairs = list(TASKS) + ([(b, a) for a, b in TASKS] if reverses else [])
    out = []
    for k, (a, b) in enumerate(pairs):
        X_a, X_b = robot.gripper_pose(q[a]), robot.gripper_pose(q[b])
        out.append((task_label(a, b), PlanningProblem(
            kind=FREE_TRANSIT, scene=scene, can_id=None, task_index=k, q_start=q[a].copy(), q_goal=q[b].copy(),
            X_WG_goal=X_b,
            waypoints=(TaskWaypoint(TASK_SPAN_TU[0], X_a), TaskWaypoint(TASK_SPAN_TU[1], X_b)),
            held=None, gripper_opening_m=scene.spec.grasp.open_width_m, removed_can_ids=(),
            time_limit_s=time_limit_s, seed=0)))
    return out


# --- the dataset --------------------------------------------------------------------------------


def build_dataset(*, name: str = DATASET, search_s: float = 20.0, rrt_starts: int = 3, polish_s: float = 2.0,
                  jobs: int = 2, progress_bar: bool = True, argv: list[str] | None = None) -> dict[str, Any]:
    """Write scenes/datasets/NAME: the ten task problems, each with its straight-segment verdict
    and a certified best known path (the offline search: AORRTC and RRT-Connect starts, each
    polished by the certified descent and seeded trajectory optimization), and its witness.

    Raises:
        SuiteError: a problem the search cannot solve with a certified path (none is dropped).
    """
    from suite.problems.dataset import FORMAT_VERSION, dataset_dir
    from suite.problems.stored import dataset_hash, problem_record, scene_record
    from suite.problems.identity import problem_id, straight_line
    from suite.run.best_known import search_job
    from suite.run.build_dataset import write_dataset_files
    from suite.run.executors import Job, LocalExecutor
    from suite.run.references import clearance_summary, straight_certified
    from suite.run.manifest import git_commit, versions
    from suite.run.runner import worker_init
    from suite.run.witnesses import MIN_WITNESS_CLEARANCE_M, choose_witness, witness_with_margin
    from suite.scoring.polyline import path_length_rad
    from scenes.identity_rule import CURRENT_RULE

    t0 = time.perf_counter()
    out = dataset_dir(name)
    scene = paper_scene()
    labelled = task_problems(scene)
    pids = [problem_id(p) for _, p in labelled]
    metas, todo = {}, []
    for pid, (label, p) in zip(pids, labelled):
        line = straight_line(p)
        metas[pid] = {"task": label, "trivial": line.trivial, "difficulty": round(line.collision_fraction, 6),
                      "straight_length_rad": line.length_rad, "split": "test", "benchmark": True}
        if line.trivial and straight_certified(p):
            metas[pid]["reference"] = {"path": [p.q_start.tolist(), p.q_goal.tolist()], "planner": "straight",
                                       "config": {}, "time_s": 0.0}
        else:
            todo.append((pid, p))
    work = [Job(pid, search_job, (p, search_s, rrt_starts, polish_s), 6 * (search_s + 5.0 * rrt_starts) + 120,
                group=p.scene.key()) for pid, p in todo]
    done = 0
    for outcome in LocalExecutor(jobs=max(1, min(jobs, len(work))), init=worker_init).run(work) if work else ():
        best = None if outcome.failure is not None else outcome.result["best"]
        if best is None:
            raise SuiteError(f"the offline search found no certified path for {metas[outcome.job.key]['task']} "
                             f"({outcome.job.key}): {outcome.failure or 'every start failed or was not certified'}")
        metas[outcome.job.key]["reference"] = {"path": best["path"], "planner": "offline-search",
                                               "config": {"start": best["start"], "search_s": search_s},
                                               "time_s": 0.0}
        done += 1
        if progress_bar:
            print(f"\rbest known paths: {done}/{len(work)}", end="", file=sys.stderr, flush=True)
    if progress_bar and work:
        print(file=sys.stderr)
    records = []
    for pid, (label, p) in zip(pids, labelled):
        m = metas[pid]
        ref = m["reference"]
        m["reference_length_rad"] = path_length_rad(ref["path"])
        witness, _ = witness_with_margin(p, choose_witness(p, ref, None))
        if not m["trivial"] and witness["clearance_min_m"] < MIN_WITNESS_CLEARANCE_M:
            raise SuiteError(f"task {label}: no witness keeps {MIN_WITNESS_CLEARANCE_M} m from the scene")
        records.append(problem_record(p, {**m, "family": VARIANT, "witness": witness}, rule=CURRENT_RULE))
    scene_lines = [json.dumps(scene_record(scene, split="test"), sort_keys=True)]
    ids = [r["problem_id"] for r in records]
    manifest = {
        "name": name,
        "format_version": FORMAT_VERSION,
        "hash": dataset_hash(scene_lines, records),
        "identity_rule": CURRENT_RULE,
        "source": "the GCS paper's arm experiment (suite/paper/gcs_arm.py, docs/gcs-paper.md)",
        "previous_revision": {"name": "gcs-arm", "change": "the same tasks in the same free space, posed as free "
                              "transits numbered by task in the scene without the stand-in plate (its left bin "
                              "as the file's five boxes): a new scene key and new problem ids"},
        "counts": {"scenes": 1, "problems": len(records), "trivial": sum(r["trivial"] for r in records)},
        "references_certified": True,
        "witness_clearance_m": clearance_summary([r["witness"]["clearance_min_m"] for r in records
                                                   if not r["trivial"]]),
        "tiers": {"quick": ids, "tasks": [r["problem_id"] for r in records[:len(TASKS)]]},
        "splits": {"test": "every problem (the paper's tasks tune nothing)"},
        "build": {"command": " ".join(["python -m suite", *(argv or ["paper", "gcs-arm", "dataset"])]),
                  "settings": {"search_s": search_s, "rrt_starts": rrt_starts, "polish_s": polish_s},
                  "versions": versions(), "git_commit": git_commit(),
                  "built_utc": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
                  "build_s": round(time.perf_counter() - t0, 1)},
    }
    write_dataset_files(out, scene_lines, records, manifest)
    return manifest


# --- GCS: the relaxation's gap and whether rounding reached the optimum ---------------------------


def _restriction_cost(regions: list, s: np.ndarray, g: np.ndarray, A: list, b: list) -> float | None:
    """The shortest path s -> g through the regions `regions` in this order (one straight
    segment per region, consecutive segments meeting in both regions): the convex restriction
    of the graph problem to this region path, a second-order cone program (Clarabel). None if
    infeasible."""
    from pydrake.solvers import ClarabelSolver, MathematicalProgram

    k = len(regions)
    if k == 1:  # both ends in one convex region: the straight segment (no program to solve)
        return float(np.linalg.norm(g - s))
    prog = MathematicalProgram()
    P = [s] + [prog.NewContinuousVariables(len(s), f"p{i}") for i in range(k - 1)] + [g]
    for i in range(1, k):  # p_i joins region i-1's segment to region i's: in both
        for r in (regions[i - 1], regions[i]):
            prog.AddLinearConstraint(np.asarray(A[r]), np.full(len(b[r]), -np.inf), np.asarray(b[r]), P[i])
    n = len(s)
    for i in range(k):
        a, c = P[i], P[i + 1]
        if isinstance(a, np.ndarray) and a.dtype != object:
            prog.AddL2NormCostUsingConicConstraint(np.eye(n), -a, c)
        elif isinstance(c, np.ndarray) and c.dtype != object:
            prog.AddL2NormCostUsingConicConstraint(np.eye(n), -c, a)
        else:
            prog.AddL2NormCostUsingConicConstraint(np.hstack([np.eye(n), -np.eye(n)]), np.zeros(n), np.concatenate([a, c]))
    result = ClarabelSolver().Solve(prog)
    if not result.is_success():
        return None
    return float(result.get_optimal_cost())


def region_paths(edges: list, starts: list[int], goals: list[int], limit: int = 100000) -> list[list[int]]:
    """Every simple path of the region graph from a region in `starts` to one in `goals` (a path
    that visits a region twice is never shorter: the stretch between the visits can stay in
    that convex region)."""
    nbrs: dict[int, list[int]] = {}
    for i, j in edges:
        nbrs.setdefault(i, []).append(j)
    goal_set, out = set(goals), []

    def walk(path: list[int]) -> None:
        if len(out) >= limit:
            return
        if path[-1] in goal_set:
            out.append(list(path))
        for j in nbrs.get(path[-1], ()):
            if j not in path:
                path.append(j)
                walk(path)
                path.pop()

    for s in starts:
        walk([s])
    return out


def gcs_optimality(problem, rs, *, max_rounded_paths: int = 10, seed: int = 0) -> dict[str, Any]:
    """For one task on the world's cached regions (no online repairs): the convex relaxation's
    cost, the rounded solution's cost, and the global optimum of the same graph problem by
    enumeration (every simple region path's convex restriction). The relaxation gap is
    (rounded - relaxed) / relaxed, as the paper reports it; rounding reached the optimum when the
    rounded cost is within 0.1% of the enumerated optimum. Also the paper's own formulation on the
    same regions and ends (`suite.paper.paper_regions.linear_gcs`: costs on edges, where `gcs`'s
    GcsTrajectoryOptimization puts them on vertices): `linear_relaxed_rad`, `linear_rounded_rad`,
    `linear_gap`, and whether its rounded path passes the validator (`linear_path_valid`)."""
    from planners.gcs.solve import connect_ends, solve_gcs
    from planners.worlds import collision_world
    from suite.scoring.validate import validate_path

    world = collision_world(problem)
    A, b, edges = list(rs.A), list(rs.b), list(rs.edges)
    joined = connect_ends(A, b, edges, problem.q_start, problem.q_goal, world=world)
    out: dict[str, Any] = {"start_join": joined["start_join"], "goal_join": joined["goal_join"],
                           "connected": joined["connected"]}
    if not joined["connected"]:
        return out
    s, g = joined["ends"]
    t0 = time.perf_counter()
    _, relaxed = solve_gcs(A, b, edges, s, g, max_rounded_paths=0, seed=seed)
    out["relaxation_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    traj, rounded = solve_gcs(A, b, edges, s, g, max_rounded_paths=max_rounded_paths, seed=seed)
    out["rounded_s"] = time.perf_counter() - t0
    if not relaxed.is_success() or not rounded.is_success():
        out["solver_status"] = [relaxed.get_solution_result().name, rounded.get_solution_result().name]
        return out
    ends = sum(float(np.linalg.norm(e - q)) for e, q in ((s, problem.q_start), (g, problem.q_goal)))
    out["relaxed_rad"] = float(relaxed.get_optimal_cost()) + ends
    out["rounded_rad"] = float(rounded.get_optimal_cost()) + ends
    starts = [i for i in range(len(A)) if np.all(A[i] @ s <= b[i] + 1e-9)]
    goals = [i for i in range(len(A)) if np.all(A[i] @ g <= b[i] + 1e-9)]
    t0 = time.perf_counter()
    paths = region_paths(edges, starts, goals)
    costs = [c for c in (_restriction_cost(p, s, g, A, b) for p in paths) if c is not None]
    out["enumeration_s"] = time.perf_counter() - t0
    out["region_paths"] = len(paths)
    out["optimum_rad"] = min(costs) + ends if costs else None
    out["relaxation_gap"] = (out["rounded_rad"] - out["relaxed_rad"]) / out["relaxed_rad"]
    out["rounding_optimal"] = bool(costs) and out["rounded_rad"] <= out["optimum_rad"] * (1 + 1e-3)
    from planners.gcs.solve import sample_trajectory

    def valid(points) -> bool:
        """Whether a path between the joined ends, with the joining segments added back, passes the validator."""
        full = np.vstack([[problem.q_start]] * (joined["start_join"] == "segment") + [np.asarray(points, float)]
                         + [[problem.q_goal]] * (joined["goal_join"] == "segment"))
        return validate_path(problem, full, world) is None

    out["rounded_path_valid"] = valid(sample_trajectory(traj, order=1, step_rad=0.02))
    # The paper's own formulation (LinearGCS: costs on edges) on the same regions and ends.
    from planners.gcs.iris import quiet_drake
    from suite.paper.paper_regions import linear_gcs

    t0 = time.perf_counter()
    with quiet_drake():
        lin = linear_gcs(A, b, edges, s, g, max_rounded_paths=max_rounded_paths, seed=seed)
    out["linear_s"] = time.perf_counter() - t0
    if lin.get("relaxed_rad") is not None and lin.get("rounded_rad") is not None:
        out["linear_relaxed_rad"] = lin["relaxed_rad"] + ends
        out["linear_rounded_rad"] = lin["rounded_rad"] + ends
        out["linear_gap"] = (out["linear_rounded_rad"] - out["linear_relaxed_rad"]) / out["linear_relaxed_rad"]
        out["linear_rounding_optimal"] = bool(costs) and out["linear_rounded_rad"] <= out["optimum_rad"] * (1 + 1e-3)
        out["linear_path_valid"] = valid(lin["waypoints"])
    else:
        out["linear_status"] = [lin.get("relaxation_status"), lin.get("rounded_status")]
    return out
