"""Plan an exported problem set with mplib 0.2.1 (OMPL RRTConnect, FCL), writing a results file.

This adapter is what a third party would write: it imports nothing from the suite and reads only
the export (`python -m suite export`): `problems.jsonl` and the robot URDF it names. For every
problem it builds an `mplib.Planner` of the arm and gripper (the export's standard URDF, an SRDF
written from the problem's `self_collision_ignored` pairs), sets the fingers at the problem's
opening, attaches the held can to the gripper link `body` at `X_GC`, adds every obstacle at `X_WO`,
allows the pairs of `allowed_contacts`, and plans from `q_start` to `q_goal` with mplib's
RRTConnect within the problem's time budget.

Modes (`--mode`):

- `mplib`: mplib's own planner as `Planner.plan_qpos` runs it: the same call into its OMPL
  planner (`Planner.planner.plan`) with plan_qpos's defaults (RRTConnect, `rrt_range` 0.1,
  `simplify` True), the path it returns sent as it is. Only the time budget differs from
  plan_qpos's default (1 s): the problem's `time_limit_s`, less `--reserve-s` kept for mplib's path
  simplification, which runs after the search without a time limit. plan_qpos's last step (TOPP-RA
  on a cubic spline through the waypoints, sampled every 0.1 s) is skipped: the suite times paths
  itself; `--send topp` sends those samples instead, from plan_qpos itself.
- `mplib-recheck`: OUR wrapper around the same call, not mplib's: every returned path is checked
  again at the validator's rule (straight joint-space segments, steps = max(1, ceil(max_j |dq_j| /
  0.01)), both ends) with mplib's own collision model (its planning world's check of one
  configuration, the check its OMPL validity checker makes); a path that fails is dropped and the
  problem planned again (next seed) within what is left of the budget.

    python adapters/mplib/plan.py EXPORT_DIR --out results.jsonl [--mode mplib|mplib-recheck]
        [--limit N] [--problems ID,...] [--seed S] [--reserve-s R] [--send path|topp]
    python adapters/mplib/plan.py EXPORT_DIR --self-check [--limit N] [--problems ID,...]
    python adapters/mplib/plan.py EXPORT_DIR --states STATES.jsonl --out VERDICTS.jsonl

`--self-check` verifies the model against the export alone (forward kinematics of `body` at
`q_goal` against `X_WG_goal`, the fingers' faces against `gripper_opening_m`, the held can's pose
and size with probe spheres just inside and outside its surface, the endpoints free). `--states`
writes mplib's verdict (colliding or not) for given configurations of given problems
(`{"problem_id": ..., "q": [[7 rad], ...]}` per line), to compare with the suite's validator.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import mplib
import numpy as np
from mplib import Planner, Pose
from mplib.collision_detection import fcl

#: plan_qpos's defaults in mplib 0.2.1 (mplib/planner.py): RRTConnect's range, simplification, TOPP step.
PLAN_QPOS_RANGE, PLAN_QPOS_SIMPLIFY, PLAN_QPOS_TIME_STEP = 0.1, True, 0.1
GRIPPER_LINK = "body"


def pose(X) -> Pose:
    return Pose(np.asarray(X, float))


def geometry(shape: str, size_m: list[float]) -> fcl.CollisionGeometry:
    """An FCL primitive (mplib's bindings) from the export's (shape, size_m)."""
    if shape == "box":
        return fcl.Box(np.asarray(size_m, float))
    if shape == "cylinder":
        return fcl.Cylinder(size_m[0], size_m[1])
    if shape == "sphere":
        return fcl.Sphere(size_m[0])
    raise ValueError(f"unsupported obstacle shape {shape!r}")


def srdf_text(problem: dict, links: set[str]) -> str:
    """An SRDF that disables exactly the export's ignored robot-robot pairs (the held can's pairs
    are the attached body's touch links)."""
    rows = [f'  <disable_collisions link1="{a}" link2="{b}" reason="export"/>'
            for a, b in problem["self_collision_ignored"] if a in links and b in links]
    return '<?xml version="1.0"?>\n<robot name="iiwa14_wsg50">\n' + "\n".join(rows) + "\n</robot>\n"


class World:
    """One problem's mplib planner: robot, fingers, held can, obstacles, allowed pairs."""

    def __init__(self, export: Path, problem: dict, workdir: Path) -> None:
        robot = problem["robot"]
        urdf = export / robot["urdf"]
        links = {"iiwa_link_0", "iiwa_link_1", "iiwa_link_2", "iiwa_link_3", "iiwa_link_4", "iiwa_link_5",
                 "iiwa_link_6", "iiwa_link_7", "body", "left_finger", "right_finger"}
        srdf = workdir / f"{problem['problem_id']}.srdf"
        srdf.write_text(srdf_text(problem, links))
        self.problem = problem
        self.planner = Planner(str(urdf), GRIPPER_LINK, srdf=str(srdf))
        pl = self.planner
        assert pl.user_joint_names[:7] == robot["joint_names"], pl.user_joint_names
        assert pl.move_group_joint_indices == list(range(7)), pl.move_group_joint_indices
        self.world = pl.planning_world
        pl.set_base_pose(pose(robot["X_WB"]))
        # The full configuration: the 7 arm joints, then the fingers held at this motion's opening.
        # OMPL plans the move group (the arm) only; the other joints keep the values set here.
        self.fingers = np.array([robot["finger_positions_m"][n] for n in pl.user_joint_names[7:]], float)
        pl.robot.set_qpos(np.concatenate([problem["q_start"], self.fingers]), True)
        for ob in problem["obstacles"]:
            self.world.add_object(fcl.FCLObject(ob["name"], pose(ob["X_WO"]),
                                                [fcl.CollisionObject(geometry(ob["shape"], ob["size_m"]))], [Pose()]))
        held = problem["held_can"]
        if held is not None:
            touch = sorted({a if b == "held_can" else b for a, b in problem["self_collision_ignored"]
                            if "held_can" in (a, b)})
            # Attached at X_GC in the gripper link itself (mplib composes the link's pose with it).
            self.world.attach_object("held_can", geometry("cylinder", held["size_m"]), pl.robot.get_name(),
                                     pl.link_name_2_idx[held["frame"]], pose(held["X_GC"]), touch)
        acm = self.world.get_allowed_collision_matrix()
        for a, b in problem["allowed_contacts"]:  # set after attaching: attaching resets the can's entries
            acm.set_entry(a, b, True)

    def colliding(self, q) -> bool:
        """mplib's check of one arm configuration: what its OMPL validity checker calls."""
        self.world.set_qpos_all(np.asarray(q, float))
        return self.world.is_state_colliding()

    def collisions(self, q) -> list[tuple[str, str]]:
        self.world.set_qpos_all(np.asarray(q, float))
        return [(c.link_name1 or c.object_name1, c.link_name2 or c.object_name2) for c in self.world.check_collision()]

    def link_pose_W(self, link: str, q) -> np.ndarray:
        """A robot link's pose in the world by mplib's kinematics (pinocchio)."""
        pin = self.planner.pinocchio_model
        pin.compute_forward_kinematics(np.concatenate([np.asarray(q, float), self.fingers]))
        X_BL = pin.get_link_pose(self.planner.link_name_2_idx[link]).to_transformation_matrix()
        return np.asarray(self.problem["robot"]["X_WB"], float) @ X_BL

    def plan(self, seed: int, time_s: float) -> tuple[str, np.ndarray | None]:
        """mplib's RRTConnect from q_start to q_goal: the call Planner.plan_qpos makes, with its
        defaults (range 0.1, simplify), for `time_s` of search."""
        mplib.set_global_seed(seed)
        p = self.problem
        start = np.concatenate([p["q_start"], self.fingers])
        self.planner.robot.set_qpos(start, True)
        status, path = self.planner.planner.plan(start[:7], [np.asarray(p["q_goal"], float)], time=max(time_s, 1e-3),
                                                 range=PLAN_QPOS_RANGE, simplify=PLAN_QPOS_SIMPLIFY)
        return status, (np.asarray(path, float) if status == "Exact solution" else None)

    def plan_qpos(self, seed: int, time_s: float) -> tuple[str, np.ndarray | None]:
        """Planner.plan_qpos itself, and the positions it returns (TOPP-RA samples of a cubic
        spline through the planned waypoints, every 0.1 s at mplib's default limits of 1 rad/s and 1 rad/s^2)."""
        mplib.set_global_seed(seed)
        p = self.problem
        goal = np.concatenate([p["q_goal"], self.fingers])
        with contextlib.redirect_stdout(sys.stderr):
            out = self.planner.plan_qpos([goal], np.concatenate([p["q_start"], self.fingers]),
                                         planning_time=max(time_s, 1e-3))
        if out["status"] != "Success":
            return out["status"], None
        return out["status"], np.asarray(out["position"], float)[:, :7]

    def first_dense_collision(self, path: np.ndarray, resolution_rad: float) -> int | None:
        """OUR re-check: the index of the first colliding state along `path` sampled at the
        validator's rule, or None. States of each segment a -> b: a + (k / steps)(b - a), k = 0..steps,
        steps = max(1, ceil(max_j |b_j - a_j| / resolution_rad))."""
        n = 0
        for a, b in zip(path[:-1], path[1:]):  # noqa: RUF007 (itertools.pairwise: Python 3.10+; mplib runs on 3.8)
            steps = max(1, math.ceil(float(np.max(np.abs(b - a))) / resolution_rad))
            for k in range(steps + 1):
                if self.colliding(a + (k / steps) * (b - a)):
                    return n
                n += 1
        return None


def dense_states(path: np.ndarray, resolution_rad: float) -> int:
    pairs = zip(path[:-1], path[1:])  # noqa: RUF007
    return sum(max(1, math.ceil(float(np.max(np.abs(b - a))) / resolution_rad)) + 1 for a, b in pairs)


def word(status: str) -> str:
    """mplib's (OMPL's) status as the import's word."""
    if status in ("Exact solution", "Success"):
        return "success"
    if "Timeout" in status or "Approximate" in status:
        return "timeout"  # OMPL's RRTConnect ends its budget with an approximate solution, which mplib drops
    return "no_solution"


def plan_problem(export: Path, problem: dict, workdir: Path, *, mode: str, seed: int, reserve_s: float,
                 send: str = "path") -> dict:
    """One results line for one problem."""
    t_setup = time.perf_counter()
    world = World(export, problem, workdir)
    setup_s = time.perf_counter() - t_setup
    pid, budget = problem["problem_id"], float(problem["time_limit_s"])
    resolution = float(problem["validation"]["resolution_rad"])
    hardware = f"1 core, {platform.processor() or platform.machine()}"
    t0 = time.perf_counter()
    for q, bad in ((problem["q_start"], "invalid_start"), (problem["q_goal"], "invalid_goal")):
        if world.colliding(q):
            return {"problem_id": pid, "status": bad, "path": None, "planning_time_s": time.perf_counter() - t0,
                    "hardware": hardware, "stats": {"setup_s": setup_s, "mplib_collisions": world.collisions(q)},
                    "notes": f"mplib 0.2.1 ({mode}): the {bad.split('_')[1]} configuration collides in mplib's model"}
    attempts, rejected, checks_s, statuses = 0, [], 0.0, []
    path, status = None, "Timeout"
    while True:
        left = budget - (time.perf_counter() - t0) - reserve_s
        if attempts and left <= 0:
            break
        attempts += 1
        if send == "topp":
            status, path = world.plan_qpos(seed + 1000 * (attempts - 1), left)
        else:
            status, path = world.plan(seed + 1000 * (attempts - 1), left)
        statuses.append(status)
        if path is None or mode == "mplib":
            break
        tc = time.perf_counter()
        bad = world.first_dense_collision(path, resolution)
        checks_s += time.perf_counter() - tc
        if bad is None:
            break
        rejected.append({"waypoints": len(path), "first_colliding_state": bad,
                         "states": dense_states(path, resolution)})
        path, status = None, "Timeout"
    elapsed = time.perf_counter() - t0
    stats = {"setup_s": setup_s, "attempts": attempts, "mplib_status": statuses}
    if mode == "mplib-recheck":
        stats.update(recheck_s=checks_s, rejected_by_recheck=rejected)
    if path is not None:
        stats["waypoints"] = len(path)
    if mode == "mplib":
        notes = ("mplib 0.2.1 Planner.plan_qpos's RRTConnect (range 0.1, OMPL's default motion checks, "
                 "simplifyMax), its defaults but the time budget; path sent as returned"
                 + (" (plan_qpos's TOPP-RA samples)" if send == "topp" else ""))
    else:
        notes = ("OUR wrapper (not mplib's) around mplib 0.2.1's plan_qpos RRTConnect: each path re-checked at "
                 f"{resolution} rad per joint with mplib's collision model, re-planned within the budget if it fails")
    return {"problem_id": pid, "status": word(status),
            "path": path.tolist() if path is not None else None, "planning_time_s": elapsed,
            "hardware": hardware, "stats": stats, "notes": notes}


def self_check(export: Path, problem: dict, workdir: Path) -> dict:
    """The model in mplib against what the export states: forward kinematics, finger faces, held
    can (probe spheres 2 mm inside and outside its surface), free endpoints."""
    world = World(export, problem, workdir)
    out = {"problem_id": problem["problem_id"]}
    X_WG = world.link_pose_W(GRIPPER_LINK, problem["q_goal"])
    X_ref = np.asarray(problem["X_WG_goal"], float)
    out["fk_position_error_m"] = float(np.linalg.norm(X_WG[:3, 3] - X_ref[:3, 3]))
    out["fk_rotation_error"] = float(np.max(np.abs(X_WG[:3, :3] - X_ref[:3, :3])))
    # Finger faces: each finger link sits at its joint position along body's x; its box's inner face
    # is at the link origin, so the faces are the joint positions apart.
    X_GL = np.linalg.inv(X_WG) @ world.link_pose_W("left_finger", problem["q_goal"])
    X_GR = np.linalg.inv(X_WG) @ world.link_pose_W("right_finger", problem["q_goal"])
    out["opening_error_m"] = float(abs((X_GR[0, 3] - X_GL[0, 3]) - problem["gripper_opening_m"]))
    out["start_colliding"] = world.collisions(problem["q_start"])
    out["goal_colliding"] = world.collisions(problem["q_goal"])
    held = problem["held_can"]
    if held is not None:
        r, h = held["size_m"]
        X_WC = X_WG @ np.asarray(held["X_GC"], float)
        mplib_X_WC = world.world.get_attached_object("held_can").get_global_pose().to_transformation_matrix()
        out["held_can_pose_error_m"] = float(np.linalg.norm(mplib_X_WC[:3, 3] - X_WC[:3, 3]))
        # A world with the can alone: probes of radius 1 mm whose centres lie 2 mm inside and outside
        # the cylinder (side, top, bottom): the inner ones must collide, the outer ones must not.
        probe_r, gap = 0.001, 0.002
        probes = []
        for a in np.linspace(0, 2 * np.pi, 8, endpoint=False):
            for z in (-0.3 * h, 0.0, 0.3 * h):
                for d, inside in ((r - gap, True), (r + gap, False)):
                    probes.append(((d * math.cos(a), d * math.sin(a), z), inside))
        for z, inside in ((h / 2 - gap, True), (h / 2 + gap, False), (-h / 2 + gap, True), (-h / 2 - gap, False)):
            probes.append(((0.0, 0.0, z), inside))
        wrong = []
        bare = dict(problem, obstacles=[], allowed_contacts=[["held_can", "plate"]])
        probe_world = World(export, bare, workdir)
        probe_world.colliding(problem["q_goal"])
        for k, (c, inside) in enumerate(probes):
            X = X_WC @ np.array([[1, 0, 0, c[0]], [0, 1, 0, c[1]], [0, 0, 1, c[2]], [0, 0, 0, 1.0]])
            name = f"probe_{k}"
            probe_world.world.add_object(fcl.FCLObject(name, pose(X), [fcl.CollisionObject(fcl.Sphere(probe_r))],
                                                       [Pose()]))
            hit = any(set(pair) == {"held_can", name} for pair in probe_world.collisions(problem["q_goal"]))
            probe_world.world.remove_object(name)
            if hit != inside:
                wrong.append({"probe": k, "centre_in_can_m": c, "inside": inside, "mplib_collides": hit})
        out["held_can_probes"] = len(probes)
        out["held_can_probes_wrong"] = wrong
    return out


def read_problems(export: Path, limit: int | None, wanted: str | None) -> list[dict]:
    problems = [json.loads(line) for line in (export / "problems.jsonl").read_text().splitlines() if line.strip()]
    if wanted:
        ids = set(wanted.split(","))
        problems = [p for p in problems if p["problem_id"] in ids]
    return problems[:limit] if limit is not None else problems


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("export", type=Path, help="the export directory (problems.jsonl, robot/)")
    p.add_argument("--out", type=Path, help="results file to write (JSON lines)")
    p.add_argument("--mode", choices=("mplib", "mplib-recheck"), default="mplib",
                   help="mplib: its planner as plan_qpos runs it; mplib-recheck: OUR wrapper re-checking at 0.01 rad")
    p.add_argument("--limit", type=int, default=None, help="plan only the first N problems")
    p.add_argument("--problems", default=None, metavar="ID,ID", help="plan only these problem_ids")
    p.add_argument("--seed", type=int, default=1,
                   help="seed of the first problem (the k-th gets seed + k; OMPL turns 0 into 1)")
    p.add_argument("--reserve-s", type=float, default=0.1,
                   help="seconds of the budget kept for mplib's path simplification after the search (default 0.1)")
    p.add_argument("--send", choices=("path", "topp"), default="path",
                   help="path: the planned waypoints; topp: plan_qpos's TOPP-RA samples (mode mplib only)")
    p.add_argument("--self-check", action="store_true", help="check the model against the export; print JSON lines")
    p.add_argument("--states", type=Path, default=None,
                   help="JSON lines {problem_id, q: [[7 rad], ...]}: write mplib's verdicts to --out")
    args = p.parse_args(argv)
    problems = read_problems(args.export, args.limit, args.problems)
    with tempfile.TemporaryDirectory(prefix="mplib-srdf-") as tmp:
        workdir = Path(tmp)
        if args.self_check:
            bad = 0
            for problem in problems:
                res = self_check(args.export, problem, workdir)
                ok = (res["fk_position_error_m"] < 1e-6 and res["fk_rotation_error"] < 1e-6
                      and res["opening_error_m"] < 1e-9 and not res["start_colliding"] and not res["goal_colliding"]
                      and not res.get("held_can_probes_wrong") and res.get("held_can_pose_error_m", 0.0) < 1e-6)
                bad += not ok
                print(json.dumps(dict(res, ok=ok)))
            print(f"self-check: {len(problems) - bad} of {len(problems)} problems agree with the export",
                  file=sys.stderr)
            return 1 if bad else 0
        if args.out is None:
            p.error("--out is required")
        if args.states is not None:
            by_id = {pr["problem_id"]: pr for pr in problems}
            with open(args.out, "w") as f:
                for line in args.states.read_text().splitlines():
                    if not line.strip():
                        continue
                    rec = json.loads(line)
                    world = World(args.export, by_id[rec["problem_id"]], workdir)
                    f.write(json.dumps({"problem_id": rec["problem_id"],
                                        "colliding": [world.colliding(q) for q in rec["q"]]}) + "\n")
            return 0
        if args.send == "topp" and args.mode != "mplib":
            p.error("--send topp goes with --mode mplib")
        with open(args.out, "w") as f:
            for k, problem in enumerate(problems):
                line = plan_problem(args.export, problem, workdir, mode=args.mode, seed=args.seed + k,
                                    reserve_s=args.reserve_s, send=args.send)
                f.write(json.dumps(line) + "\n")
                f.flush()
                print(f"{k + 1}/{len(problems)} {problem['problem_id']} {problem['family']:8s} {problem['kind']:8s} "
                      f"{line['status']:13s} {line['planning_time_s']:.3f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    sys.exit(main())
