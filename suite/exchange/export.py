"""`export`: a dataset's problems as plain files that any planner, in any language, can read.

The export directory holds `problems.jsonl` (one self-contained problem per line: start, goal,
time budget, the validator's resolution, the robot, the held can and every obstacle as a
primitive in the world frame), `schema.json` (`suite.exchange.schema`), the robot model files
in `robot/` and a README saying what to send back. Obstacles are the scene spec's own primitives
(`Obstacle.to_json`, as `python -m suite scene --json` prints them) plus the cans on the plate;
which pairs are checked mirrors the python-fcl world (`scenes.collision.world`).
"""

from __future__ import annotations

import itertools
import json
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np

from planners.base import PlanningProblem
from scenes.errors import SuiteError
from suite.exchange.schema import FORMAT_VERSION, schema_document

PROBLEMS_FILE, SCHEMA_FILE, README_FILE, EXPORT_MANIFEST = "problems.jsonl", "schema.json", "README.md", "export.json"
ROBOT_DIR = "robot"
#: The arm with the gripper mounted, written by the export in standard URDF (capsules as a cylinder
#: and two spheres) and with the suite's <capsule> elements; the suite's own files are shipped too.
COMBINED_URDF, CAPSULE_URDF = "iiwa14_wsg50.urdf", "iiwa14_wsg50_capsules.urdf"
#: Tolerance of the validator's joint-limit check (`suite.scoring.validate`).
JOINT_LIMIT_TOLERANCE_RAD = 1e-9
#: How the validator samples each straight segment a -> b of a path (`suite.scoring.validate`).
SAMPLING_RULE = ("steps = max(1, ceil(max_j |b_j - a_j| / resolution_rad)); states a + (k / steps) (b - a) for "
                 "k = 0..steps, both ends included, each checked robot-obstacle and robot-robot (not "
                 "obstacle-obstacle); touching (distance <= 0) is a collision")
#: The gripper's finger joints (prismatic, along the gripper frame's x axis).
FINGER_JOINTS = ("left_finger_sliding_joint", "right_finger_sliding_joint")


def combined_urdf(*, capsules: bool = False, robot: str | None = None) -> str:
    """The iiwa URDF with the WSG's links and joints added and a fixed joint mounting the gripper
    frame ('body') on iiwa_link_7 at the robot variant's mount pose.

    Args:
        capsules: keep the suite's `<capsule>` elements (Drake reads them; urdfdom-based parsers,
            e.g. Pinocchio's, MoveIt's, drop the whole element). By default each capsule is
            written as the same solid in standard URDF: a cylinder and a sphere at each end.
        robot: the robot variant (`scenes.robot_model.ROBOTS`; the suite's own by default).
    """
    from scenes.robot_model import DEFAULT_ROBOT, DRAKE_NS, robot_variant

    v = robot_variant(robot or DEFAULT_ROBOT)
    ET.register_namespace("drake", DRAKE_NS.strip("{}"))
    iiwa = ET.parse(v.iiwa_urdf).getroot()
    wsg = ET.parse(v.wsg_urdf).getroot()
    iiwa.set("name", "iiwa14_wsg50")
    mount = ET.SubElement(iiwa, "joint", {"name": "iiwa_joint_gripper", "type": "fixed"})
    ET.SubElement(mount, "parent", {"link": "iiwa_link_7"})
    ET.SubElement(mount, "child", {"link": "body"})
    ET.SubElement(mount, "origin", {"xyz": _floats(v.mount_xyz), "rpy": _floats(v.mount_rpy)})
    for child in wsg:
        iiwa.append(child)
    if not capsules:
        for link in iiwa.findall("link"):
            for tag in ("collision", "visual"):
                for el in link.findall(tag):
                    if el.find("geometry/capsule") is not None:
                        index = list(link).index(el)
                        link.remove(el)
                        for k, part in enumerate(_capsule_parts(el)):
                            link.insert(index + k, part)
    ET.indent(iiwa)
    how = "capsules kept as <capsule>" if capsules else "each <capsule> written as a cylinder and two end spheres"
    return ('<?xml version="1.0"?>\n<!-- Written by `python -m suite export`: the suite\'s '
            f'{v.iiwa_urdf.name} with {v.wsg_urdf.name} mounted on iiwa_link_7 (gripper frame G = link "body"); '
            f'{how}. -->\n'
            + ET.tostring(iiwa, encoding="unicode") + "\n")


def _floats(values) -> str:
    return " ".join(repr(float(v)) for v in values)


def _capsule_parts(el: ET.Element) -> list[ET.Element]:
    """A <collision> or <visual> capsule as three elements of the same solid: its cylinder, and a
    sphere at each end of its axis (the shape's z)."""
    import copy

    from scenes.robot_model import rpy_to_matrix

    capsule = el.find("geometry/capsule")
    radius, length = float(capsule.get("radius")), float(capsule.get("length"))
    origin = el.find("origin")
    xyz = np.array([float(v) for v in (origin.get("xyz", "0 0 0") if origin is not None else "0 0 0").split()])
    rpy = (origin.get("rpy", "0 0 0") if origin is not None else "0 0 0").split()
    axis = rpy_to_matrix(tuple(float(v) for v in rpy))[:, 2]
    parts = []
    for shape, centre in (("cylinder", xyz), ("sphere", xyz + axis * length / 2), ("sphere", xyz - axis * length / 2)):
        part = copy.deepcopy(el)
        geometry = part.find("geometry")
        geometry.remove(geometry.find("capsule"))
        attrs = {"radius": repr(radius), "length": repr(length)} if shape == "cylinder" else {"radius": repr(radius)}
        ET.SubElement(geometry, shape, attrs)
        o = part.find("origin")
        if o is None:
            o = ET.SubElement(part, "origin")
        o.set("xyz", _floats(np.round(centre, 9)))
        o.set("rpy", " ".join(rpy))
        parts.append(part)
    return parts


def _pose(X) -> list:
    """A pose as written: its rotation made orthonormal to rounding (the polar factor, which moves an
    already orthonormal rotation by at most a few 1e-16), full precision."""
    X = np.array(X, float)
    U, _, Vt = np.linalg.svd(X[:3, :3])
    X[:3, :3] = U @ Vt
    return X.tolist()


def _robot_section(problem: PlanningProblem, robot) -> dict[str, Any]:
    from scenes.robot_model import robot_variant

    half = problem.gripper_opening_m / 2
    v = robot_variant(robot.name)
    return {
        "urdf": f"{ROBOT_DIR}/{COMBINED_URDF}",
        "urdf_with_capsules": f"{ROBOT_DIR}/{CAPSULE_URDF}",
        "model_files": [f"{ROBOT_DIR}/{v.iiwa_urdf.name}", f"{ROBOT_DIR}/{v.wsg_urdf.name}"],
        "joint_names": [j.name for j in robot.joints],
        "lower_rad": robot.lower_rad.tolist(),
        "upper_rad": robot.upper_rad.tolist(),
        "velocity_rad_s": robot.velocity_limits_rad_s.tolist(),
        "acceleration_rad_s2": robot.acceleration_limits_rad_s2.tolist(),
        "X_WB": _pose(np.eye(4)),  # the base link is the world frame
        "gripper_frame": "body",
        # a gripper whose fingers are welded (the GCS paper's) has no finger joints to hold
        "finger_positions_m": {} if robot.welded_fingers else {FINGER_JOINTS[0]: -half, FINGER_JOINTS[1]: half},
    }


def _obstacles(problem: PlanningProblem) -> list[dict[str, Any]]:
    """The static primitives as `scene --json` prints them, then the cans still on the plate."""
    spec = problem.scene.spec
    gone = set(problem.removed_can_ids) | ({problem.held.can.id} if problem.held is not None else set())
    # full precision: the validator's own sizes and poses (`scene --json` rounds them for reading)
    out = [{"name": o.name, "shape": o.shape, "size_m": [float(v) for v in o.size_m], "X_WO": _pose(o.pose())}
           for o in spec.obstacles()]
    out += [{"name": f"can_{c.id}", "shape": "cylinder", "size_m": [spec.can.radius_m, spec.can.height_m],
             "X_WO": _pose(c.X_WC())} for c in problem.scene.cans if c.id not in gone]
    return out


def _self_collision_ignored(robot, held: bool) -> list[list[str]]:
    """Robot part pairs the python-fcl world does not check (as `CollisionWorld` filters them)."""
    from scenes.collision.world import GRIPPER_ASSEMBLY

    bodies = list(dict.fromkeys(s.body for s in robot.shapes)) + (["held_can"] if held else [])
    return [[a, b] for a, b in itertools.combinations(bodies, 2)
            if frozenset((a, b)) in robot.filtered_pairs or (a in GRIPPER_ASSEMBLY and b in GRIPPER_ASSEMBLY)]


def witness_entry(problem: PlanningProblem, path: np.ndarray | None) -> dict[str, Any] | None:
    """The dataset's witness that the problem is solvable (its `witness` path, searched with a
    margin, or else its reference): its length, its minimum clearance to the scene (the metric
    `clearance_min_m`, 0.01 rad samples) and its exact verdict (`suite.scoring.validate.certify_path`)."""
    if path is None:
        return None
    from planners.worlds import collision_world
    from suite.scoring.metrics import min_clearance_m
    from suite.scoring.validate import certify_path

    world = collision_world(problem)
    path = np.asarray(path, float)
    c_min = min_clearance_m(world, path)
    return {"length_rad": float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1))),
            "waypoints": len(path), "clearance_min_m": c_min,
            "certification": certify_path(path, world)["verdict"]}


def problem_entry(problem: PlanningProblem, meta: dict[str, Any], *, dataset: str, robot,
                  witness: np.ndarray | None = None) -> dict[str, Any]:
    """One line of problems.jsonl (see `suite.exchange.schema.PROBLEM_SCHEMA`).

    `X_WG_goal` is the gripper pose at `q_goal` by the robot's forward kinematics (what a path that
    ends at `q_goal` reaches); the pose the goal was solved for by IK is `X_WG_target`.
    """
    from suite.scoring.validate import ENDPOINT_TOLERANCE_RAD, VALIDATION_RESOLUTION_RAD

    spec = problem.scene.spec
    obstacles = _obstacles(problem)
    held = None
    if problem.held is not None:
        m = spec.grasp.held_margin_m
        held = {"name": "held_can", "shape": "cylinder", "size_m": [spec.can.radius_m + m, spec.can.height_m + 2 * m],
                "radius_m": spec.can.radius_m, "height_m": spec.can.height_m, "padding_m": m,
                "frame": "body", "X_GC": _pose(problem.held.X_GC)}
    allowed = [["iiwa_link_0", o["name"]] for o in obstacles]  # the base is welded to the static world
    if held is not None:
        allowed.append(["held_can", "plate"])  # it rests on the plate at the grasp
    return {
        "format_version": FORMAT_VERSION,
        "problem_id": meta["problem_id"],
        "dataset": dataset,
        "family": meta.get("family", problem.scene.variant),
        "kind": problem.kind,
        "scene_key": problem.scene.key(),
        "q_start": np.asarray(problem.q_start, float).tolist(),
        "q_goal": np.asarray(problem.q_goal, float).tolist(),
        "X_WG_goal": _pose(robot.gripper_pose(np.asarray(problem.q_goal, float))),
        "X_WG_target": _pose(problem.X_WG_goal),
        "trivial": meta.get("trivial"),
        "split": meta.get("split"),
        "witness": witness_entry(problem, witness),
        "time_limit_s": problem.time_limit_s,
        "validation": {"resolution_rad": VALIDATION_RESOLUTION_RAD, "endpoint_tolerance_rad": ENDPOINT_TOLERANCE_RAD,
                       "joint_limit_tolerance_rad": JOINT_LIMIT_TOLERANCE_RAD,
                       "rule": SAMPLING_RULE, "obstacle_pairs_checked": False},
        "robot": _robot_section(problem, robot),
        "gripper_opening_m": problem.gripper_opening_m,
        "held_can": held,
        "obstacles": obstacles,
        "allowed_contacts": allowed,
        "self_collision_ignored": _self_collision_ignored(robot, held is not None),
    }


def write_export(dataset_arg: str, out: str | Path, *, time_limit_s: float) -> dict[str, Any]:
    """Write the export of dataset `NAME[:TIER]` into `out` (created; must not hold an export).

    Args:
        dataset_arg: the dataset and tier, e.g. "recycle-v2:quick".
        out: the export directory.
        time_limit_s: the planning budget per problem written into every problem, s.

    Returns:
        The export's manifest (also written as export.json).

    Raises:
        SuiteError: unknown dataset or tier, or `out` already holds an export or is not writable.
    """
    from scenes.robot_model import load_robot, robot_variant
    from suite.problems.dataset import load_dataset, parse_dataset_arg

    ds = load_dataset(dataset_arg, time_limit_s=time_limit_s)
    robots = sorted({p.scene.spec.robot for p in ds.problems})
    if len(robots) > 1:
        raise SuiteError(f"dataset {dataset_arg!r} mixes robot variants {robots}; an export holds one robot")
    out = Path(out)
    if (out / PROBLEMS_FILE).exists():
        raise SuiteError(f"--out {str(out)!r} already holds an export ({PROBLEMS_FILE}); choose another directory")
    try:
        (out / ROBOT_DIR).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SuiteError(f"--out {str(out)!r} is not writable: {exc.strerror}") from None
    robot = load_robot(robots[0]) if robots else load_robot()
    v = robot_variant(robot.name)
    name, tier = parse_dataset_arg(dataset_arg)
    label = f"{name}:{tier}"
    for path in (v.iiwa_urdf, v.wsg_urdf):
        shutil.copyfile(path, out / ROBOT_DIR / path.name)
    (out / ROBOT_DIR / COMBINED_URDF).write_text(combined_urdf(robot=robot.name))
    (out / ROBOT_DIR / CAPSULE_URDF).write_text(combined_urdf(capsules=True, robot=robot.name))
    (out / SCHEMA_FILE).write_text(json.dumps(schema_document(), indent=1) + "\n")
    with open(out / PROBLEMS_FILE, "w") as f:
        f.writelines(json.dumps(problem_entry(problem, ds.meta[pid], dataset=label, robot=robot,
                                              witness=ds.witnesses.get(pid, ds.references.get(pid)))) + "\n"
                     for pid, problem in zip(ds.ids, ds.problems))
    manifest = {"format_version": FORMAT_VERSION, "dataset": {"name": name, "tier": tier, "hash": ds.hash},
                "problems": len(ds.ids), "time_limit_s": time_limit_s,
                "files": [PROBLEMS_FILE, SCHEMA_FILE, README_FILE,
                          *(f"{ROBOT_DIR}/{p}" for p in (v.iiwa_urdf.name, v.wsg_urdf.name, COMBINED_URDF, CAPSULE_URDF))]}
    (out / EXPORT_MANIFEST).write_text(json.dumps(manifest, indent=1) + "\n")
    (out / README_FILE).write_text(EXPORT_README.format(dataset=label, n=len(ds.ids), time_limit_s=time_limit_s,
                                                        name=name, iiwa=v.iiwa_urdf.name, wsg=v.wsg_urdf.name,
                                                        about=v.about))
    return manifest


EXPORT_README = """\
# Planning problems of {dataset} ({n} problems)

Written by `python -m suite export` (can-recycling planner suite). Plan them with any planner,
send back a results file, and `python -m suite import` judges your paths with the suite's own
validator, TOPP-RA timing and metrics, beside the suite's planners.

## What is here

- `problems.jsonl`: one problem per line (JSON). Each is self-contained: `q_start` and `q_goal`
  (rad, `iiwa_joint_1..7`), the goal gripper pose `X_WG_goal` (forward kinematics at `q_goal`, to
  rounding; `X_WG_target` is the pose the goal was solved for, 1-2 mm and about 0.6 degrees away),
  the problem's `family`, `kind`, `split` and `trivial` flag (its straight segment already passes),
  a `witness` (the dataset's reference path: its length, its minimum clearance and its exact
  verdict; the path itself is not exported), the budget `time_limit_s`
  ({time_limit_s} s), the validator's settings (`validation`), the robot (URDF, joint limits,
  base pose, the finger joints' positions for this motion), the can held in the gripper (a
  padded cylinder fixed to the gripper link `body`, or null), every obstacle as a primitive in
  the world frame (`shape` box | cylinder | sphere, `size_m`, `X_WO` 4x4 row-major, metres),
  the robot-obstacle pairs that are not checked (`allowed_contacts`) and the robot's own pairs
  that are not checked (`self_collision_ignored`).
- `schema.json`: JSON Schema (2020-12) of a problem (`$defs/problem`) and of a result line
  (`$defs/result`), with units.
- `robot/iiwa14_wsg50.urdf`: the KUKA iiwa 14 with the WSG 50 gripper mounted on `iiwa_link_7`,
  in standard URDF. Collision geometry is primitives only: boxes, cylinders and spheres (the
  suite's links are capsules, each written here as the same solid: a cylinder and a sphere at
  each end). `robot/iiwa14_wsg50_capsules.urdf` keeps the `<capsule radius length>` elements
  (Drake reads them; urdfdom-based parsers drop such an element without failing).
  The finger joints are prismatic; hold them at `robot.finger_positions_m` during the motion
  (empty when the fingers are welded). The robot is {about}; `robot/{iiwa}` and `robot/{wsg}`
  are the suite's own files.

## What counts as a solution

A path is a list of waypoints joined by straight joint-space segments. It must start at
`q_start` and end at `q_goal` (within `validation.endpoint_tolerance_rad`), stay within the
joint limits (within `validation.joint_limit_tolerance_rad`), and be collision-free at every
checked state. Each segment a -> b is checked at

    steps = max(1, ceil(max_j |b_j - a_j| / 0.01)),  states a + (k / steps) (b - a),  k = 0 .. steps

(`validation.rule`; both ends included; the max is over the 7 joints, not a Euclidean norm).
Checked: robot against obstacles and robot against itself, held can included, except the pairs
in `allowed_contacts` (the base link against the static world; the held can against the plate it
was lifted from) and `self_collision_ignored`. Obstacle-obstacle pairs are not checked (cans may
touch the plate they stand on). Touching counts as collision (distance <= 0).

This is the field's fixed-step rule and the suite's success. Beside it the suite gives every
claimed path an exact verdict, `certified`, `unproved` or `collision`, on the same geometry and
pairs: a path free at every sample may still pass through an obstacle between two of them
(docs/certification.md in the suite).

## What to send back

A JSON-lines file, one line per problem (`$defs/result`):

```json
{{"problem_id": "…", "status": "success", "path": [[q1, …, q7], …], "planning_time_s": 0.42, "hardware": "1 core of an i7-1185G7", "notes": "…"}}
```

`path` is null when you have no solution (then `status`, e.g. `timeout` or `no_solution`, is
kept). A non-null path is judged as a claimed solution whatever `status` says. A problem you
leave out is recorded as `no_result`. Then, with the suite installed:

```bash
python -m suite import --dataset {dataset} --results results.jsonl --planner MYPLANNER --out results/myplanner
```
"""
