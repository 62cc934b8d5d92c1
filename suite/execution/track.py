"""Release on the move: the gripper catches up with the moving bin and follows it while it opens.

The arm arrives at the drop pose above the bin at rest. Released there, a can would fall
straight down while the bin walks on; released from a gripper that moves with the bin, it keeps
the bin's horizontal velocity while it falls and lands in it. `tracking_motion` gives that motion:
the gripper's desired velocity in the world is v_xy r(t) in x and y, 0 in z and 0 in rotation,
with r the smoothstep 3u^2 - 2u^3 (u = t / ramp_s) from 0 to 1 over the ramp, then 1 (its
derivative is 0 at both ends, so the acceleration is continuous; its peak is 1.5 |v| / ramp_s).

The joints follow from Drake's differential IK (`DoDifferentialInverseKinematics`, with the
robot model's joint position and velocity limits) on a bare plant of the arm and gripper, for
the WSG body frame G (`scenes.robot_model.RobotModel.gripper_pose`). The desired pose is the start
pose carried along by the integral of the desired velocity, and the commanded spatial velocity
adds FEEDBACK_GAIN_PER_S times the pose error to the feedforward, so linearization errors do not
accumulate. The joint ODE is integrated with Heun's method, so the positions on the grid are the
trapezoidal integral of the velocities there and the cubic Hermite through (q, qd) accelerates
almost uniformly between gridpoints. Differential IK bounds no acceleration: the ramp sets them
(0.3 m/s over 0.15 s from the open family's drop pose reaches 94% of a joint's limit).

During the ramp the gripper falls behind a point moving at v_xy all along by `ramp_lag_m`
(v ramp_s / 2): the caller aims the arrival that far ahead of the bin.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

from scenes.robot_model import load_robot, robot_variant

#: The pose error's gain (1/s) in the commanded gripper velocity.
FEEDBACK_GAIN_PER_S = 10.0
#: The largest deviation of the final gripper pose from the ideal one (m, rad) a motion may have.
POSITION_TOLERANCE_M = 5e-3
ORIENTATION_TOLERANCE_RAD = 0.02


@dataclasses.dataclass(frozen=True, eq=False)
class TrackTrajectory:
    """A tracking motion on a time grid (`sample` like `TimedTrajectory.sample`).

    Attributes:
        duration_s: its length.
        t_s: grid times (K,), from 0 to duration_s.
        q, qd: joint positions (rad) and velocities (rad/s) at t_s, (K, 7); q[0] is the start at
            rest (qd[0] = 0), qd[-1] the bin's velocity mapped to the joints.
    """

    duration_s: float
    t_s: np.ndarray
    q: np.ndarray
    qd: np.ndarray

    ok = True
    status = "ok"

    @functools.cached_property
    def _spline(self):
        from scipy.interpolate import CubicHermiteSpline

        return CubicHermiteSpline(self.t_s, self.q, self.qd, axis=0)

    def sample(self, t_s) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions, velocities and accelerations at times t_s (scalar or (K,)), clipped to
        [0, duration_s], by cubic Hermite interpolation of (q, qd). Returns (7,) or (K, 7) each."""
        t = np.asarray(t_s, float)
        scalar = t.ndim == 0
        t = np.clip(np.atleast_1d(t), 0.0, self.duration_s)
        out = tuple(self._spline(t, nu) for nu in (0, 1, 2))
        return tuple(o[0] for o in out) if scalar else out


def _ramp_integral(t: float, ramp_s: float) -> float:
    """The integral (s) of r from 0 to t: the distance covered at unit speed."""
    if t >= ramp_s:
        return ramp_s / 2 + (t - ramp_s)
    u = t / ramp_s
    return ramp_s * (u**3 - u**4 / 2)


def ramp_lag_m(v_xy, ramp_s: float) -> np.ndarray:
    """How far (2,) m the gripper is behind a point that moved at v_xy (m/s) since the ramp began,
    once the ramp is over: the integral of v (1 - r), v ramp_s / 2 for the smoothstep."""
    return np.asarray(v_xy, float) * ramp_s / 2


@functools.lru_cache(maxsize=None)
def _arm(robot_name: str):
    """A finalized MultibodyPlant of the robot alone (iiwa welded to the world, the gripper welded
    on link 7 as `scenes.drake_scene` mounts it, the fingers welded shut) and its frame G; one per
    robot and process (building it is slow)."""
    from pydrake.math import RigidTransform
    from pydrake.multibody.parsing import Parser
    from pydrake.multibody.plant import MultibodyPlant

    robot, variant = load_robot(robot_name), robot_variant(robot_name)
    plant = MultibodyPlant(0.0)
    parser = Parser(plant)
    (iiwa,) = parser.AddModels(str(variant.iiwa_urdf))
    (wsg,) = parser.AddModels(str(variant.wsg_urdf))
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("iiwa_link_0", iiwa))
    G = plant.GetFrameByName("body", wsg)
    plant.WeldFrames(plant.GetFrameByName("iiwa_link_7", iiwa), G, RigidTransform(robot.X_7G))
    if not robot.welded_fingers:  # the fingers do not move the frame G: weld them
        for name, X_GF in robot.finger_offsets(0.0).items():
            plant.RemoveJoint(plant.GetJointByName(f"{name}_sliding_joint", wsg))
            plant.WeldFrames(G, plant.GetFrameByName(name, wsg), RigidTransform(X_GF))
    plant.Finalize()
    return plant, G


def gripper_velocity_xy(robot_name: str, q, qd) -> np.ndarray:
    """The gripper frame's horizontal velocity (2,) m/s at joint positions q and velocities qd (7,)."""
    from pydrake.multibody.tree import JacobianWrtVariable

    plant, G = _arm(robot_name)
    ctx = plant.CreateDefaultContext()
    plant.SetPositions(ctx, np.asarray(q, float))
    W = plant.world_frame()
    J = plant.CalcJacobianTranslationalVelocity(ctx, JacobianWrtVariable.kV, G, np.zeros(3), W, W)
    return (J @ np.asarray(qd, float))[:2]


def tracking_motion(robot_name: str, q0: np.ndarray, v_xy_m_s: np.ndarray, *, ramp_s: float, duration_s: float,
                    dt_s: float = 0.01, qd0: np.ndarray | None = None) -> TrackTrajectory | None:
    """The arm's motion from rest at q0 that brings the gripper to the planar velocity v_xy_m_s
    (2,) over ramp_s and keeps it until duration_s (s), its height and orientation held (see the
    module docstring); the grid step is at most dt_s. A (3,) velocity also moves the gripper up or
    down (an escape from the person). From a moving start (joint velocities qd0), the gripper's
    velocity ramps from its velocity there to v_xy_m_s (a release re-aimed at a new estimate).

    Returns None when differential IK finds no solution at some step or the final gripper pose is
    off the ideal one by more than POSITION_TOLERANCE_M or ORIENTATION_TOLERANCE_RAD (a velocity
    the joints cannot give, a limit in the way).

    Raises:
        ValueError: ramp_s not in (0, duration_s].
    """
    from pydrake.multibody.inverse_kinematics import (
        DifferentialInverseKinematicsParameters,
        DifferentialInverseKinematicsStatus,
        DoDifferentialInverseKinematics,
    )

    if not 0 < ramp_s <= duration_s:
        raise ValueError(f"ramp_s must be in (0, duration_s = {duration_s}], got {ramp_s}")
    robot = load_robot(robot_name)
    plant, G = _arm(robot_name)
    ctx = plant.CreateDefaultContext()
    q0 = np.asarray(q0, float)
    v = np.zeros(3)
    v[:len(np.atleast_1d(v_xy_m_s))] = np.asarray(v_xy_m_s, float)  # (2,) planar, or (3,) with a rise
    n = max(1, math.ceil(duration_s / dt_s - 1e-9))
    t_grid = np.linspace(0.0, duration_s, n + 1)
    params = DifferentialInverseKinematicsParameters(7, 7)
    params.set_time_step(duration_s / n)
    params.set_joint_position_limits((robot.lower_rad, robot.upper_rad))
    params.set_joint_velocity_limits((-robot.velocity_limits_rad_s, robot.velocity_limits_rad_s))

    def pose(q):
        plant.SetPositions(ctx, q)
        return plant.CalcRelativeTransform(ctx, plant.world_frame(), G)

    X0 = pose(q0)
    p0, R0 = X0.translation(), X0.rotation()
    qd_start = np.zeros(7) if qd0 is None else np.asarray(qd0, float)
    v0 = np.zeros(3)
    if np.any(qd_start):
        from pydrake.multibody.tree import JacobianWrtVariable

        W = plant.world_frame()
        v0 = plant.CalcJacobianTranslationalVelocity(ctx, JacobianWrtVariable.kV, G, np.zeros(3), W, W) @ qd_start

    def error(q, t):
        """Position (3,) and rotation (3,) error of q from the desired pose at t, in the world."""
        X = pose(q)
        aa = R0.multiply(X.rotation().inverse()).ToAngleAxis()
        return p0 + v0 * t + (v - v0) * _ramp_integral(t, ramp_s) - X.translation(), aa.angle() * aa.axis()

    def joint_velocity(q, t):
        e_p, e_r = error(q, t)
        u = min(t / ramp_s, 1.0)
        V = np.concatenate([FEEDBACK_GAIN_PER_S * e_r, v0 + (v - v0) * (3 * u**2 - 2 * u**3) + FEEDBACK_GAIN_PER_S * e_p])
        if not np.any(V):
            return np.zeros(7)
        plant.SetPositions(ctx, q)
        plant.SetVelocities(ctx, np.zeros(7))
        res = DoDifferentialInverseKinematics(plant, ctx, V, G, params)
        if res.status != DifferentialInverseKinematicsStatus.kSolutionFound:
            return None
        return np.asarray(res.joint_velocities, float)

    q, qd = [q0.copy()], [qd_start.copy()]  # the desired velocity at t = 0 is the start's, the error 0
    for k in range(n):
        h = t_grid[k + 1] - t_grid[k]
        qd_pred = joint_velocity(q[k] + h * qd[k], t_grid[k + 1])
        if qd_pred is None:
            return None
        q.append(q[k] + h * (qd[k] + qd_pred) / 2)
        qd_next = joint_velocity(q[k + 1], t_grid[k + 1])
        if qd_next is None:
            return None
        qd.append(qd_next)
    e_p, e_r = error(q[-1], duration_s)
    if np.linalg.norm(e_p) > POSITION_TOLERANCE_M or np.linalg.norm(e_r) > ORIENTATION_TOLERANCE_RAD:
        return None
    return TrackTrajectory(float(duration_s), t_grid, np.array(q), np.array(qd))
