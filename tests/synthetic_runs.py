"""Realistic trial records without planning: real scenes, real IK goals, simple joint paths.

The tests of everything derived from trials.jsonl (summary, plots, Planner Arena export) need a
run's records. Planning a real run takes minutes, so these records are built in code instead: the
scene generator's cans and the grasp rule's poses give gripper targets, a damped least-squares IK
on the project's numpy forward kinematics gives the configurations, and each "planner" joins them
its own way (straight lines, a noisy detour, a smooth bump). The metrics are computed by hand from
those paths. Nothing here stands in for a product part: it only writes the records' format.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

from scenes.generate import generate_scene
from scenes.grasp_rule import down_pose, grasp_yaw, truth_grasp
from scenes.identity_rule import CURRENT_RULE
from scenes.robot_model import load_robot
from scenes.spec import load_spec
from suite.run.records import TrialRecord

Q_SEED = np.array([-1.57, 0.1, 0.0, -1.2, 0.0, 1.6, 0.0])
KINDS = ("approach", "descend", "lift", "transit", "return")


def ik(X_WG: np.ndarray, q_seed: np.ndarray) -> np.ndarray:
    """A configuration whose gripper pose is X_WG (least squares on position and rotation)."""
    robot = load_robot()

    def residual(q):
        X = robot.gripper_pose(q)
        return np.concatenate([X[:3, 3] - X_WG[:3, 3], 0.3 * (X[:3, :3] - X_WG[:3, :3]).ravel()])

    sol = least_squares(residual, q_seed, bounds=(robot.lower_rad + 1e-3, robot.upper_rad - 1e-3))
    return sol.x


def waypoint_pose(p_m) -> np.ndarray:
    return down_pose(np.asarray(p_m, float), grasp_yaw(p_xy_m=p_m[:2], lying=False, axis_yaw_rad=0.0))


def path_length_rad(path: np.ndarray) -> float:
    return float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)))


def smoothness(path: np.ndarray) -> float:
    """Sum of squared turning angles (rad^2) between consecutive segments (0 for a straight line)."""
    d = np.diff(path, axis=0)
    total = 0.0
    for a, b in zip(d[:-1], d[1:]):
        c = np.dot(a, b) / (np.linalg.norm(a) * np.linalg.norm(b))
        total += math.acos(max(-1.0, min(1.0, c))) ** 2
    return total


def duration_lower_bound_s(path: np.ndarray) -> float:
    """Time to follow the path at the slowest joint's velocity limit, segment by segment."""
    v = load_robot().velocity_limits_rad_s
    return float(np.sum(np.max(np.abs(np.diff(path, axis=0)) / v, axis=1)))


def planner_path(planner: str, q0: np.ndarray, q1: np.ndarray, via: np.ndarray | None, rng) -> np.ndarray:
    """How each synthetic planner joins q0 to q1 (through `via` for transit)."""
    anchors = [q0] + ([via] if via is not None else []) + [q1]
    if planner == "ik":
        return np.array(anchors)
    if planner == "rrt":
        pts = [anchors[0]]
        for a, b in zip(anchors[:-1], anchors[1:]):
            for f in (1 / 3, 2 / 3):
                pts.append(a + f * (b - a) + rng.normal(0.0, 0.08, 7))
            pts.append(b)
        return np.array(pts)
    # "trajopt": a smooth bump away from the straight line, 12 knots per leg
    pts = [anchors[0]]
    bump = rng.normal(0.0, 0.1, 7)
    for a, b in zip(anchors[:-1], anchors[1:]):
        for f in np.linspace(0, 1, 13)[1:]:
            pts.append(a + f * (b - a) + math.sin(math.pi * f) * bump)
    return np.array(pts)


FAILURES = {"ik": ("ik_failed", 0.1), "rrt": ("timeout", 0.15), "trajopt": ("no_solution", 0.2)}
TIME_SCALE_S = {"ik": 0.05, "rrt": 0.4, "trajopt": 1.5}


def synthetic_records(
    *, seeds=(0,), variants=("open", "wall"), cans: int = 2, planners=("ik", "rrt", "trajopt"), rng_seed: int = 7
) -> list[TrialRecord]:
    """Trial records in the runner's format for every scene, can, motion and planner."""
    robot = load_robot()
    rng = np.random.default_rng(rng_seed)
    records = []
    for variant in variants:
        spec = load_spec(variant=variant).with_can_count(cans)
        wp = spec.waypoints
        q_plate = ik(waypoint_pose(wp.above_plate_m), Q_SEED)
        q_mid = ik(waypoint_pose(wp.middle_m), q_plate)
        q_bin = ik(waypoint_pose(wp.above_bin_m), q_mid)
        for seed in seeds:
            scene = generate_scene(spec, seed=seed, check_reachable=False)
            for can in scene.cans:
                g = truth_grasp(scene, can)
                q_pre = ik(g.X_WGpre, q_plate)
                q_grasp = ik(g.X_WG, q_pre)
                motions = {
                    "approach": (q_plate, q_pre, None),
                    "descend": (q_pre, q_grasp, None),
                    "lift": (q_grasp, q_plate, None),
                    "transit": (q_plate, q_bin, q_mid),
                    "return": (q_bin, q_plate, q_mid),
                }
                for kind in KINDS:
                    q0, q1, via = motions[kind]
                    for planner in planners:
                        fail_status, p_fail = FAILURES.get(planner, ("no_solution", 0.1))
                        failed = rng.random() < p_fail
                        t_s = float(TIME_SCALE_S.get(planner, 0.2) * rng.lognormal(0.0, 0.5))
                        rec = {
                            "trial_id": f"{planner}-{variant}-{seed}-{can.id}-{kind}",
                            "planner": planner,
                            "planner_config": {"name": planner},
                            "scene_seed": seed,
                            "scene_key": scene.key(),
                            "variant": variant,
                            "can_id": can.id,
                            "problem": kind,
                            "held": kind in ("lift", "transit"),
                            "seed": int(rng.integers(0, 2**31)),
                            "time_limit_s": 10.0,
                            "q_start": q0.tolist(),
                            "q_goal": q1.tolist(),
                            "status": fail_status if failed else "success",
                            "planning_time_s": 10.0 if failed and fail_status == "timeout" else t_s,
                            "path": None,
                            "metrics": {},
                            "stats": {"solve_time_s": t_s},
                        }
                        if not failed:
                            path = planner_path(planner, q0, q1, via, rng)
                            p_WG = robot.gripper_pose(path)[:, :3, 3]
                            rec["path"] = path.tolist()
                            rec["metrics"] = {
                                "path_length_rad": path_length_rad(path),
                                "ee_path_length_m": float(np.sum(np.linalg.norm(np.diff(p_WG, axis=0), axis=1))),
                                "smoothness": smoothness(path),
                                "clearance_min_m": float(rng.uniform(0.005, 0.08)),
                                "duration_s": duration_lower_bound_s(path),
                            }
                        records.append(TrialRecord.from_json(rec))
    return records


def write_run(run_dir: Path, records: list[TrialRecord | dict], *, planners=("ik", "rrt", "trajopt"),
              cans: int = 2) -> Path:
    """A run directory like the runner's: manifest.json and trials.jsonl (records, or raw lines as dicts)."""
    run_dir.mkdir(parents=True, exist_ok=True)
    manifest = {"command": "python -m suite compare (synthetic)",
                "config": {"planners": list(planners), "cans": cans, "spec": None, "time_limit_s": 10.0},
                "identity_rule": CURRENT_RULE}
    (run_dir / "manifest.json").write_text(json.dumps(manifest))
    with open(run_dir / "trials.jsonl", "w") as f:
        for r in records:
            f.write(json.dumps(r.to_json() if isinstance(r, TrialRecord) else r) + "\n")
    return run_dir


def write_dataset_run(run_dir: Path, selection: str) -> tuple[Path, object]:
    """A run in the runner's format on a real dataset's stored problems, without planning: planner
    "ref" follows each problem's stored reference path, planner "stuck" times out on every problem
    with a stated reason. Returns the run directory and the loaded dataset."""
    from suite.problems.dataset import load_dataset

    ds = load_dataset(selection)
    records = []
    for pid, p in zip(ds.ids, ds.problems):
        base = {"scene_seed": p.scene.seed, "scene_key": p.scene.key(), "variant": p.scene.variant,
                "family": p.scene.variant, "can_id": p.can_id, "problem": p.kind, "kind": p.kind, "problem_id": pid,
                "held": p.held is not None, "q_start": p.q_start.tolist(), "q_goal": p.q_goal.tolist(),
                "time_limit_s": 5.0, "planner_config": {}}
        ref = ds.references[pid]
        records.append({**base, "planner": "ref", "status": "success", "planning_time_s": 0.5, "path": ref.tolist(),
                        "metrics": {"path_length_rad": path_length_rad(ref), "length_ratio": 1.0},
                        "certification": {"verdict": "certified"}, "stats": {}})
        records.append({**base, "planner": "stuck", "status": "timeout", "planning_time_s": 5.0, "path": None,
                        "metrics": {}, "stats": {"reason": "time limit reached"}})
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "manifest.json").write_text(json.dumps({
        "config": {"planners": ["ref", "stuck"], "dataset": selection},
        "dataset": {"name": ds.name, "tier": ds.tier, "hash": ds.hash}}))
    (run_dir / "trials.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    return run_dir, ds
