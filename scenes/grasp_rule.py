"""The paper's grasp rule (Algorithm 2) as geometry: a can's top and axis -> gripper poses.

Perception feeds it estimated values, `--grasps truth` the scene's ground truth; both get the
same frames from the same code.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from scenes.robot_model import matrix_to_rpy, rpy_to_matrix


@dataclasses.dataclass(frozen=True)
class Grasp:
    """A grasp of one can.

    Attributes:
        can_id: the can it grasps (a detection index for perceived grasps).
        X_WG: gripper pose at the grasp (4, 4).
        X_WGpre: gripper pose at the pre-grasp, straight above the grasp (4, 4).
        lying: the can lies on its side.
    """

    can_id: int
    X_WG: np.ndarray
    X_WGpre: np.ndarray
    lying: bool

    def to_json(self) -> dict:
        return {"X_WG": pose_json(self.X_WG), "X_WGpre": pose_json(self.X_WGpre)}


def pose_json(X: np.ndarray) -> dict:
    """{"p_m": [x, y, z], "rpy_rad": [r, p, y]} of a 4x4 pose."""
    return {
        "p_m": [round(float(v), 6) for v in X[:3, 3]],
        "rpy_rad": [round(float(v), 6) for v in matrix_to_rpy(X[:3, :3])],
    }


def down_pose(p_m, yaw_rad: float) -> np.ndarray:
    """Gripper pose at p pointing straight down: roll -pi/2, pitch 0, the given yaw (the paper's)."""
    X = np.eye(4)
    X[:3, :3] = rpy_to_matrix((-math.pi / 2, 0.0, yaw_rad))
    X[:3, 3] = p_m
    return X


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def grasp_yaw(*, p_xy_m, lying: bool, axis_yaw_rad: float) -> float:
    """The gripper yaw for a can at p_xy.

    With roll -pi/2, the gripper's z axis points along world (-sin yaw, cos yaw): for a lying can
    it must lie along the can's axis (the fingers, along x, then close across the diameter), so
    yaw = axis_yaw - pi/2, modulo pi. Of the two (or, for an upright can, of all) choices, take
    the one closest to the "natural" yaw, whose gripper z axis points back at the robot base: the
    iiwa reaches it with joint 7 near the middle of its range (the opposite yaw puts joint 7 at
    about 3.0 rad, against its 3.05 limit, and the next wrist turn then flips the IK branch).
    """
    natural = math.atan2(p_xy_m[1], p_xy_m[0]) + math.pi / 2
    if not lying:
        return _wrap(natural)
    base = axis_yaw_rad - math.pi / 2
    cands = [_wrap(base), _wrap(base + math.pi)]
    return min(cands, key=lambda a: abs(_wrap(a - natural)))


def make_grasp(
    *,
    can_id: int,
    p_xy_m,
    top_z_m: float,
    lying: bool,
    axis_yaw_rad: float,
    top_offset_m: float,
    pregrasp_height_m: float,
) -> Grasp:
    """Grasp and pre-grasp for a can whose highest point is at top_z_m above p_xy_m."""
    yaw = grasp_yaw(p_xy_m=p_xy_m, lying=lying, axis_yaw_rad=axis_yaw_rad)
    p = np.array([p_xy_m[0], p_xy_m[1], top_z_m + top_offset_m])
    X_WG = down_pose(p, yaw)
    X_WGpre = X_WG.copy()
    X_WGpre[2, 3] += pregrasp_height_m
    return Grasp(can_id, X_WG, X_WGpre, lying)


def waypoint_pose(p_m) -> np.ndarray:
    """A task waypoint: the gripper pointing down, its yaw facing away from the robot base."""
    yaw = grasp_yaw(p_xy_m=p_m[:2], lying=False, axis_yaw_rad=0.0)
    return down_pose(np.asarray(p_m, float), yaw)


def truth_grasp(scene, can) -> Grasp:
    """The grasp the rule gives for a can's ground-truth pose."""
    spec = scene.spec
    return make_grasp(
        can_id=can.id,
        p_xy_m=can.p_WC_m[:2],
        top_z_m=can.top_z_m(spec.can.radius_m, spec.can.height_m),
        lying=can.lying,
        axis_yaw_rad=can.axis_yaw_rad,
        top_offset_m=spec.grasp.top_offset_m,
        pregrasp_height_m=spec.grasp.pregrasp_height_m,
    )
