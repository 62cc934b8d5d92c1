"""The JSON Schema of an export's problems and of the results file an external planner sends back.

The schema is the documentation of both formats (every quantity with its unit). The results part
is generated from the dataclass the import loads every line into (`suite.exchange.results.ResultLine`),
so what is documented is what is checked, with one error line per bad line.
"""

from __future__ import annotations

from typing import Any

from planners.base import ALL_KINDS

#: Version of the export's files (problems.jsonl, results lines); bumped on any incompatible change.
FORMAT_VERSION = 1

_NUM = {"type": "number"}
_STR = {"type": "string"}


def _vector(n: int, what: str) -> dict[str, Any]:
    return {"type": "array", "items": _NUM, "minItems": n, "maxItems": n, "description": what}


_POSE = {
    "type": "array", "minItems": 4, "maxItems": 4, "items": _vector(4, "a row"),
    "description": "a homogeneous transform, 4x4 row-major; translation in metres",
}
_Q = _vector(7, "joint positions of iiwa_joint_1..7, rad")
_PAIR = {"type": "array", "items": _STR, "minItems": 2, "maxItems": 2}

_OBSTACLE = {
    "type": "object",
    "required": ["name", "shape", "size_m", "X_WO"],
    "additionalProperties": False,
    "properties": {
        "name": {**_STR, "description": "unique in the problem: table, plate, bin_floor, wall, can_3, ..."},
        "shape": {"enum": ["box", "cylinder", "sphere"]},
        "size_m": {"type": "array", "items": _NUM, "minItems": 1, "maxItems": 3,
                   "description": "box: full sizes x, y, z; cylinder: radius, length along its z axis; "
                                  "sphere: radius (m)"},
        "X_WO": {**_POSE, "description": "the obstacle's frame in the world (its centre; a cylinder's "
                                         "axis is its z), 4x4 row-major, m"},
    },
}

PROBLEM_SCHEMA: dict[str, Any] = {
    "type": "object",
    "description": "One planning problem: move the arm from q_start to q_goal without collision.",
    "required": ["format_version", "problem_id", "dataset", "family", "kind", "q_start", "q_goal", "X_WG_goal",
                 "X_WG_target", "trivial", "split", "witness", "time_limit_s", "validation", "robot", "gripper_opening_m", "held_can", "obstacles",
                 "allowed_contacts", "self_collision_ignored"],
    "additionalProperties": False,
    "properties": {
        "format_version": {"const": FORMAT_VERSION},
        "problem_id": {**_STR, "pattern": "^[0-9a-f]{20}$",
                       "description": "content hash of the problem; send it back with your result"},
        "dataset": {**_STR, "description": "dataset NAME:TIER the problem was exported from"},
        "family": {**_STR, "description": "the scene family (open, wall, station, shelf, window, clutter)"},
        "kind": {"enum": list(ALL_KINDS),
                 "description": "the motion of the pick-and-place cycle, or 'free': a free transit between two "
                                "configurations that belongs to no can's cycle (the GCS paper's tasks)"},
        "scene_key": {**_STR, "description": "the scene the problem comes from (problems share scenes)"},
        "q_start": {**_Q, "description": "start configuration, rad (iiwa_joint_1..7)"},
        "q_goal": {**_Q, "description": "goal configuration, rad: the path must end here"},
        "X_WG_goal": {**_POSE, "description": "the gripper frame G ('body' link) at q_goal by forward kinematics "
                                              "of the exported URDF, in the world, m (rotation orthonormal to "
                                              "rounding)"},
        "X_WG_target": {**_POSE, "description": "the gripper pose the goal configuration was solved for by IK "
                                                "(within the IK's tolerances of X_WG_goal), m"},
        "trivial": {"type": ["boolean", "null"],
                    "description": "true if the straight segment q_start -> q_goal already passes the validator"},
        "split": {"type": ["string", "null"], "description": "the dataset split the problem belongs to (tune or test)"},
        "witness": {
            "description": "the dataset's reference path, which proves the problem solvable (not exported "
                           "itself), or null",
            "oneOf": [{"type": "null"}, {
                "type": "object",
                "required": ["length_rad", "waypoints", "clearance_min_m", "certification"],
                "additionalProperties": False,
                "properties": {
                    "length_rad": {**_NUM, "description": "its joint-space length (sum of L2 segment lengths), rad"},
                    "waypoints": {"type": "integer"},
                    "clearance_min_m": {**_NUM, "description": "its smallest distance to the scene (robot and "
                                                               "held can, base and link 1 left out), m"},
                    "certification": {"enum": ["certified", "unproved", "collision"],
                                      "description": "its exact verdict: certified means no collision between "
                                                     "the validator's samples either"},
                },
            }],
        },
        "time_limit_s": {**_NUM, "exclusiveMinimum": 0, "description": "planning budget per problem, s"},
        "validation": {
            "type": "object",
            "required": ["resolution_rad", "endpoint_tolerance_rad", "joint_limit_tolerance_rad"],
            "description": "how the suite checks a path: straight joint-space segments between waypoints, "
                           "sampled so that no joint moves more than resolution_rad between checked states",
            "properties": {
                "rule": {**_STR, "description": "the sampling rule as a formula"},
                "obstacle_pairs_checked": {"const": False,
                                           "description": "obstacle-obstacle pairs are never checked"},
                "resolution_rad": {**_NUM, "description": "max |dq_i| between densely checked states, rad"},
                "endpoint_tolerance_rad": {**_NUM, "description": "max |q_i| error of the first and last "
                                                                  "waypoint from q_start / q_goal, rad"},
                "joint_limit_tolerance_rad": {**_NUM, "description": "allowed excess over a joint limit, rad"},
            },
        },
        "robot": {
            "type": "object",
            "required": ["urdf", "model_files", "joint_names", "lower_rad", "upper_rad", "velocity_rad_s",
                         "acceleration_rad_s2", "X_WB", "gripper_frame", "finger_positions_m"],
            "properties": {
                "urdf": {**_STR, "description": "path (relative to the export) of the arm with the gripper "
                                                "mounted, standard URDF; collision geometry is primitives "
                                                "(box, cylinder, sphere)"},
                "urdf_with_capsules": {**_STR, "description": "the same robot with the suite's <capsule> "
                                                              "elements (Drake reads them)"},
                "model_files": {"type": "array", "items": _STR,
                                "description": "the suite's own arm and gripper model files, as shipped"},
                "joint_names": {"type": "array", "items": _STR, "minItems": 7, "maxItems": 7},
                "lower_rad": _vector(7, "lower joint limits, rad"),
                "upper_rad": _vector(7, "upper joint limits, rad"),
                "velocity_rad_s": _vector(7, "joint velocity limits, rad/s (used by the suite's TOPP-RA)"),
                "acceleration_rad_s2": _vector(7, "joint acceleration limits, rad/s^2 (TOPP-RA)"),
                "X_WB": {**_POSE, "description": "the robot base (iiwa_link_0) in the world"},
                "gripper_frame": {**_STR, "description": "the link that is the gripper frame G"},
                "finger_positions_m": {"type": "object", "additionalProperties": _NUM,
                                       "description": "positions of the gripper's prismatic finger joints "
                                                      "for this problem (fixed during the motion), m"},
            },
        },
        "gripper_opening_m": {**_NUM, "description": "distance between the finger inner faces, m"},
        "held_can": {
            "description": "the can carried in the gripper (part of the robot for collision), or null",
            "oneOf": [{"type": "null"}, {
                "type": "object",
                "required": ["name", "shape", "size_m", "radius_m", "height_m", "padding_m", "frame", "X_GC"],
                "additionalProperties": False,
                "properties": {
                    "name": {"const": "held_can"},
                    "shape": {"const": "cylinder"},
                    "size_m": _vector(2, "the padded collision cylinder: radius + padding, height + 2 padding "
                                         "(m); this is what is checked"),
                    "radius_m": {**_NUM, "description": "the can's radius, m"},
                    "height_m": {**_NUM, "description": "the can's height, m"},
                    "padding_m": {**_NUM, "description": "margin added around the can for collision, m"},
                    "frame": {**_STR, "description": "the link it is rigidly attached to"},
                    "X_GC": {**_POSE, "description": "the can's frame (centre, axis z) in that link's frame"},
                },
            }],
        },
        "obstacles": {"type": "array", "items": _OBSTACLE,
                      "description": "every obstacle as a primitive in the world frame (static station "
                                     "parts and the cans still on the plate)"},
        "allowed_contacts": {"type": "array", "items": _PAIR,
                             "description": "[robot part, obstacle] pairs that are not checked: the base "
                                            "link with the static world, the held can with the plate it "
                                            "was lifted from"},
        "self_collision_ignored": {"type": "array", "items": _PAIR,
                                   "description": "robot part pairs (URDF links, held_can) not checked "
                                                  "against each other; every other pair is"},
    },
}

def result_schema() -> dict[str, Any]:
    """`$defs/result`: generated from `suite.exchange.results.ResultLine`, the dataclass `import`
    loads every line into, so the documented format and the checked one are the same."""
    from scenes.schema import json_schema
    from suite.exchange.results import ResultLine

    doc = json_schema(ResultLine)
    doc.pop("title", None)
    doc["description"] = "One line of the results file: your planner's answer to one problem."
    return doc


def schema_document() -> dict[str, Any]:
    """The schema.json of an export: both formats under `$defs`."""
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": f"can-recycling-planner-suite/export/v{FORMAT_VERSION}",
        "title": "Can-recycling planner suite: exported problems and external planner results",
        "description": "problems.jsonl holds one $defs/problem per line; send back a JSON-lines file of "
                       "$defs/result, one line per problem you attempted.",
        "$defs": {"problem": PROBLEM_SCHEMA, "result": result_schema()},
    }
