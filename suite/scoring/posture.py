"""Natural poses along a path: joint-limit margin, distance from a comfortable posture,
manipulability, and the tilt of a carried upright can.

No benchmark we know defines these, so each is stated exactly here and evaluated on configurations
sampled by arc length along the path (`polyline.arc_samples`), never per waypoint.
"""

from __future__ import annotations

import math

import numpy as np

from scenes.robot_model import RobotModel

#: The comfortable posture the posture distance is measured from: Drake's iiwa "ready"
#: configuration used across this project as the IK seed (`scenes.ik.Q_READY`): elbow bent,
#: gripper pointing down over the table in front of the robot. rad.
Q_COMFORT = np.array([-1.57, 0.1, 0.0, -1.2, 0.0, 1.6, 0.0])


def joint_limit_margins(q: np.ndarray, robot: RobotModel) -> np.ndarray:
    """Per configuration, the smallest distance to a joint limit as a fraction of that joint's
    range: min_j min(q_j - lower_j, upper_j - q_j) / (upper_j - lower_j). (M,) for q (M, 7);
    0.5 at the middle of every range, 0 at a limit, negative beyond one."""
    lo, hi = robot.lower_rad, robot.upper_rad
    q = np.atleast_2d(q)
    return np.min(np.minimum(q - lo, hi - q) / (hi - lo), axis=1)


def posture_distances_rad(q: np.ndarray, q_comfort: np.ndarray = Q_COMFORT) -> np.ndarray:
    """Joint-space L2 distance (rad) of each configuration (M, 7) from the comfortable posture."""
    return np.linalg.norm(np.atleast_2d(q) - q_comfort, axis=1)


def gripper_jacobians(q: np.ndarray, robot: RobotModel) -> np.ndarray:
    """Geometric Jacobians (M, 6, 7) of the gripper frame G in the world: rows 0-2 the velocity of
    G's origin (m/rad), rows 3-5 the angular velocity (rad/rad), both in world coordinates.

    Every joint turns about the z axis of its own frame (the model's X_origin Rz(q)), whose pose
    is the child link's pose: column i is [z_i x (p_G - p_i); z_i].
    """
    X = robot.link_poses(np.atleast_2d(q))  # (M, 9, 4, 4): link_0..link_7, G
    z = X[:, 1:8, :3, 2]
    p = X[:, 1:8, :3, 3]
    p_G = X[:, 8, None, :3, 3]
    J = np.empty((len(X), 6, 7))
    J[:, :3, :] = np.swapaxes(np.cross(z, p_G - p), 1, 2)
    J[:, 3:, :] = np.swapaxes(z, 1, 2)
    return J


def manipulability(q: np.ndarray, robot: RobotModel) -> np.ndarray:
    """Yoshikawa's manipulability sqrt(det(J J^T)) of the gripper's geometric Jacobian per
    configuration (M,). Its unit is m^3 (three translational rows in m, three rotational
    dimensionless); it is 0 at a singularity and depends on the reference point (G's origin)."""
    J = gripper_jacobians(q, robot)
    det = np.linalg.det(J @ np.swapaxes(J, 1, 2))
    return np.sqrt(np.maximum(det, 0.0))


def can_tilts_deg(q: np.ndarray, robot: RobotModel, X_GC: np.ndarray) -> np.ndarray:
    """Angle (deg) between a held can's axis (z of its frame C) and the world's vertical +z, per
    configuration (M,): 0 upright, 90 lying, 180 upside down.

    Args:
        q: configurations (M, 7), rad.
        robot: the robot model (forward kinematics of the gripper frame G).
        X_GC: the can's pose in the gripper frame (4, 4).
    """
    R_WC = robot.gripper_pose(np.atleast_2d(q))[:, :3, :3] @ np.asarray(X_GC, float)[:3, :3]
    return np.degrees(np.arccos(np.clip(R_WC[:, 2, 2], -1.0, 1.0)))


def carried_upright_can(world) -> np.ndarray | None:
    """X_GC of the can the world's gripper holds if that can stood upright when picked, else None."""
    held = getattr(world, "held", None)
    if held is None or held.can.lying:
        return None
    return np.asarray(held.X_GC, float)


def tilt_max_deg(q: np.ndarray, robot: RobotModel, X_GC: np.ndarray | None) -> float:
    """The largest can tilt (deg) over configurations, NaN without a carried upright can."""
    if X_GC is None:
        return math.nan
    return float(np.max(can_tilts_deg(q, robot, X_GC)))
