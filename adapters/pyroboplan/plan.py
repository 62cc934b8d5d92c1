"""Plan an exported problem set with pyroboplan (Pinocchio + Coal), writing a results file.

This adapter is what a third party would write: it imports nothing from the suite and reads only
the export (`python -m suite export`): `problems.jsonl` and the robot URDF it names. For every
problem it builds a Pinocchio model of the arm with the fingers locked at the problem's opening,
adds the held can and the obstacles as Coal primitives, enables exactly the collision pairs the
export says are checked, tries the straight segment, then runs pyroboplan's bidirectional
RRT-Connect (steps of at most 0.5 rad) followed by its random shortcutting, within the problem's
time budget. pyroboplan 1.3.1's shortcutting can return a path with a segment it never checked
(it drops one of the two cut points), so a shortcut path is kept only if pyroboplan's own path
check passes it; else the RRT path is sent (`--trust-shortcut` sends it unchecked, to measure that).

    python adapters/pyroboplan/plan.py EXPORT_DIR --out results.jsonl [--limit N] [--problems ID,...]
        [--seed S] [--step-rad STEP] [--trust-shortcut]

`--step-rad` is pyroboplan's `max_step_size` (the joint-space L2 distance between the states it
checks along a motion). By default it is the export's `validation.resolution_rad`, which makes
every per-joint step at most the validator's; pyroboplan's own default is 0.05.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import platform
import sys
import time
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin
from pyroboplan.core.utils import check_collisions_along_path, check_collisions_at_state
from pyroboplan.planning.path_shortcutting import shortcut_path
from pyroboplan.planning.rrt import RRTPlanner, RRTPlannerOptions
from pyroboplan.planning.utils import discretize_joint_space_path


def geometry(shape: str, size_m: list[float]) -> coal.CollisionGeometry:
    """A Coal primitive from the export's (shape, size_m)."""
    if shape == "box":
        return coal.Box(*size_m)
    if shape == "cylinder":
        return coal.Cylinder(size_m[0], size_m[1])
    if shape == "sphere":
        return coal.Sphere(size_m[0])
    raise ValueError(f"unsupported obstacle shape {shape!r}")


def se3(X) -> pin.SE3:
    X = np.asarray(X, float)
    return pin.SE3(X[:3, :3], X[:3, 3])


class Robot:
    """The exported URDF parsed once; per problem, a reduced model with the fingers locked."""

    def __init__(self, urdf: Path) -> None:
        self.model = pin.buildModelFromUrdf(str(urdf))
        self.geom = pin.buildGeomFromUrdf(self.model, str(urdf), pin.GeometryType.COLLISION)

    def world(self, problem: dict) -> tuple[pin.Model, pin.GeometryModel]:
        """The problem's planning model (7 joints) and collision model with its checked pairs."""
        robot = problem["robot"]
        q_ref = pin.neutral(self.model)
        lock = []
        for name, value in robot["finger_positions_m"].items():
            jid = self.model.getJointId(name)
            q_ref[self.model.joints[jid].idx_q] = value
            lock.append(jid)
        model, geom = pin.buildReducedModel(self.model, self.geom, lock, q_ref)
        part = {}  # geometry index -> the export's part name (URDF link, held_can, obstacle)
        for i, go in enumerate(geom.geometryObjects):
            part[i] = model.frames[go.parentFrame].name
        held = problem["held_can"]
        if held is not None:
            fid = model.getFrameId(held["frame"])
            frame = model.frames[fid]
            placement = frame.placement * se3(held["X_GC"])
            i = geom.addGeometryObject(pin.GeometryObject("held_can", frame.parentJoint, fid, placement,
                                                          geometry("cylinder", held["size_m"])))
            part[i] = "held_can"
        robot_parts = dict(part)
        for ob in problem["obstacles"]:
            i = geom.addGeometryObject(pin.GeometryObject(ob["name"], 0, 0, se3(ob["X_WO"]),
                                                          geometry(ob["shape"], ob["size_m"])))
            part[i] = ob["name"]
        skip = {frozenset(p) for p in problem["self_collision_ignored"] + problem["allowed_contacts"]}
        n = len(geom.geometryObjects)
        for i in range(n):
            for j in range(i + 1, n):
                a, b = part[i], part[j]
                if i not in robot_parts and j not in robot_parts:
                    continue  # obstacle against obstacle
                if a == b or frozenset((a, b)) in skip:
                    continue
                geom.addCollisionPair(pin.CollisionPair(i, j))
        return model, geom


def plan_problem(robot: Robot, problem: dict, *, seed: int, step_rad: float | None,
                 trust_shortcut: bool = False) -> dict:
    """One results line for one problem."""
    model, geom = robot.world(problem)
    q_start, q_goal = np.array(problem["q_start"]), np.array(problem["q_goal"])
    step = step_rad if step_rad is not None else problem["validation"]["resolution_rad"]
    options = RRTPlannerOptions(max_step_size=step, max_connection_dist=0.5, rrt_connect=True,
                                bidirectional_rrt=True, max_planning_time=problem["time_limit_s"], rng_seed=seed,
                                fast_return=True, goal_biasing_probability=0.1)
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):  # pyroboplan prints its progress
        for q, word in ((q_start, "invalid_start"), (q_goal, "invalid_goal")):
            if check_collisions_at_state(model, geom, q):
                return {"problem_id": problem["problem_id"], "status": word, "path": None,
                        "planning_time_s": time.perf_counter() - t0}
        if not check_collisions_along_path(model, geom, discretize_joint_space_path([q_start, q_goal], step)):
            path = [q_start, q_goal]  # the straight segment is free (pyroboplan tries it only within 0.5 rad)
        else:
            path = RRTPlanner(model, geom, options).plan(q_start, q_goal)
        status = "success" if path else "timeout"
        if path:
            short = shortcut_path(model, geom, [np.array(q) for q in path], max_iters=100, max_step_size=step)
            # pyroboplan 1.3.1's shortcut_path keeps the later cut point but drops the earlier one,
            # leaving a segment it never checked: keep the shortcut only if its own checker passes it.
            if trust_shortcut or not check_collisions_along_path(
                    model, geom, discretize_joint_space_path(short, step)):
                path = short
    elapsed = time.perf_counter() - t0
    return {"problem_id": problem["problem_id"], "status": status,
            "path": [np.asarray(q, float).tolist() for q in path] if path else None,
            "planning_time_s": elapsed,
            "hardware": f"1 core, {platform.processor() or platform.machine()}",
            "notes": f"pyroboplan RRT-Connect (bidirectional) + shortcutting{' (unchecked)' if trust_shortcut else ''}, "
                     f"max_step_size {step} rad"}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("export", type=Path, help="the export directory (problems.jsonl, robot/)")
    p.add_argument("--out", type=Path, required=True, help="results file to write (JSON lines)")
    p.add_argument("--limit", type=int, default=None, help="plan only the first N problems")
    p.add_argument("--problems", default=None, metavar="ID,ID", help="plan only these problem_ids")
    p.add_argument("--seed", type=int, default=0, help="seed of the first problem (the k-th gets seed + k)")
    p.add_argument("--step-rad", type=float, default=None,
                   help="pyroboplan's max_step_size (default: the export's validation resolution)")
    p.add_argument("--trust-shortcut", action="store_true",
                   help="send pyroboplan's shortcut path as it is (without re-checking it with its own checker)")
    args = p.parse_args(argv)
    problems = [json.loads(line) for line in (args.export / "problems.jsonl").read_text().splitlines() if line.strip()]
    if args.problems:
        wanted = set(args.problems.split(","))
        problems = [p for p in problems if p["problem_id"] in wanted]
    problems = problems[: args.limit] if args.limit is not None else problems
    robot = Robot(args.export / problems[0]["robot"]["urdf"])
    with open(args.out, "w") as f:
        for k, problem in enumerate(problems):
            line = plan_problem(robot, problem, seed=args.seed + k, step_rad=args.step_rad,
                                trust_shortcut=args.trust_shortcut)
            f.write(json.dumps(line) + "\n")
            f.flush()
            print(f"{k + 1}/{len(problems)} {problem['problem_id']} {problem['kind']:8s} {line['status']:13s} "
                  f"{line['planning_time_s']:.2f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
