"""Path and trajectory metrics, computed identically for every planner's validated path.

Geometric metrics are computed on resampled versions of the piecewise-linear joint path, so they do
not depend on how many waypoints a planner emits:
- `resample_uniform(path, step)`: points at equal joint-space arc length (L2, rad) along the
  polyline, first and last waypoint included (corners between samples are cut). Used for
  smoothness.
- `densify(path, step)`: every waypoint kept, each segment cut into equal pieces of at most step.
  Used for the gripper's Cartesian path and for clearance (it keeps the corners).
All functions are pure; `score` computes them all for one path.
"""

from __future__ import annotations

import math

import numpy as np

from suite.scoring.timing import TimedTrajectory, TimingOptions, time_parameterize

#: Joint-space step (L2, rad) of the resampled paths the geometric metrics are computed on.
METRIC_STEP_RAD = 0.05
#: Consecutive waypoints closer than this (L2, rad) count as one.
DUPLICATE_TOL_RAD = 1e-9


def _as_path(path) -> np.ndarray:
    path = np.asarray(path, float)
    if path.ndim != 2 or path.shape[1] != 7 or len(path) == 0:
        raise ValueError(f"path must be an (N, 7) array with N >= 1, got shape {path.shape}")
    return path


def _dedupe(path: np.ndarray) -> np.ndarray:
    if len(path) < 2:
        return path
    step = np.linalg.norm(np.diff(path, axis=0), axis=1)
    return path[np.concatenate([[True], step > DUPLICATE_TOL_RAD])]


def path_length_rad(path) -> float:
    """Joint-space path length: sum_i ||q_{i+1} - q_i||_2 over the waypoints, in rad.

    This is OMPL's PathGeometric::length() in a RealVectorStateSpace (L2 distance). MoveIt's
    path-length metric uses the L1 norm instead; this one is L2.
    """
    path = _as_path(path)
    return float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)))


def resample_uniform(path, step_rad: float = METRIC_STEP_RAD) -> np.ndarray:
    """Points at equal arc length along the polyline: n = ceil(L / step_rad) equal steps of L / n
    (<= step_rad, L2 rad), (n + 1, 7). A path that does not move gives its single point."""
    path = _dedupe(_as_path(path))
    if len(path) == 1:
        return path.copy()
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    n = max(1, math.ceil(s[-1] / step_rad))
    s_new = np.linspace(0.0, s[-1], n + 1)
    j = np.clip(np.searchsorted(s, s_new, side="right") - 1, 0, len(seg) - 1)
    w = np.clip((s_new - s[j]) / seg[j], 0.0, 1.0)
    out = path[j] + w[:, None] * (path[j + 1] - path[j])
    out[-1] = path[-1]
    return out


def densify(path, step_rad: float = METRIC_STEP_RAD) -> np.ndarray:
    """Every waypoint, with each segment cut into ceil(len / step_rad) equal pieces (L2 rad)."""
    path = _dedupe(_as_path(path))
    if len(path) == 1:
        return path.copy()
    d = np.diff(path, axis=0)
    n = np.maximum(1, np.ceil(np.linalg.norm(d, axis=1) / step_rad).astype(int))
    seg = np.repeat(np.arange(len(d)), n)
    frac = np.concatenate([np.arange(k) / k for k in n])
    return np.vstack([path[seg] + frac[:, None] * d[seg], path[-1:]])


def smoothness(states) -> float:
    """OMPL's PathGeometric::smoothness() of a sequence of states (dimensionless sum, 1/rad^2).

    For consecutive segments of lengths a = d(s_{i-2}, s_{i-1}), b = d(s_{i-1}, s_i) and the chord
    c = d(s_{i-2}, s_i) (L2 distances), the turning angle is theta = pi - acos((a^2 + b^2 - c^2) /
    (2ab)) and the term is (2 theta / (a + b))^2; the smoothness is the sum of the terms. As in
    OMPL, a term is skipped unless -1 < (a^2 + b^2 - c^2) / (2ab) < 1 (straight continuations and
    full reversals add nothing). Lower is smoother; 0 for a straight line.

    Call it on `resample_uniform(path)` so that it does not depend on the waypoint count.
    """
    q = np.asarray(states, float)
    if len(q) < 3:
        return 0.0
    a = np.linalg.norm(q[1:-1] - q[:-2], axis=1)
    b = np.linalg.norm(q[2:] - q[1:-1], axis=1)
    c = np.linalg.norm(q[2:] - q[:-2], axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        cos_v = (a * a + b * b - c * c) / (2.0 * a * b)
        valid = (cos_v > -1.0) & (cos_v < 1.0)
        angle = math.pi - np.arccos(np.where(valid, cos_v, 0.0))
        k = 2.0 * angle / (a + b)
    return float(np.sum(np.where(valid, k * k, 0.0)))


def rotation_angle_rad(R_AB: np.ndarray) -> np.ndarray:
    """Angle (rad) of rotation matrices (..., 3, 3), accurate for small and large angles:
    atan2(|vee(R - R^T)| / 2, (trace R - 1) / 2)."""
    w = np.stack([R_AB[..., 2, 1] - R_AB[..., 1, 2], R_AB[..., 0, 2] - R_AB[..., 2, 0], R_AB[..., 1, 0] - R_AB[..., 0, 1]], -1)
    tr = R_AB[..., 0, 0] + R_AB[..., 1, 1] + R_AB[..., 2, 2]
    return np.arctan2(0.5 * np.linalg.norm(w, axis=-1), 0.5 * (tr - 1.0))


def ee_path_length_m(X_WG: np.ndarray) -> float:
    """Cartesian path length of the gripper frame origin: sum_k ||p_WG[k+1] - p_WG[k]||, metres.

    Args:
        X_WG: gripper poses (M, 4, 4) along the densified path.
    """
    p = X_WG[:, :3, 3]
    return float(np.sum(np.linalg.norm(np.diff(p, axis=0), axis=1)))


def ee_rotation_deg(X_WG: np.ndarray) -> float:
    """Total rotation of the gripper: sum_k angle(R_WG[k]^T R_WG[k+1]), degrees.

    Args:
        X_WG: gripper poses (M, 4, 4) along the densified path.
    """
    R = X_WG[:, :3, :3]
    rel = np.swapaxes(R[:-1], -1, -2) @ R[1:]
    return float(np.degrees(np.sum(rotation_angle_rad(rel)))) if len(R) > 1 else 0.0


def jerk(timed: TimedTrajectory) -> np.ndarray:
    """Joint jerk (rad/s^3), (K-1, 7): finite differences of the accelerations sampled at dt_s.

    TOPP-RA's constant-path-acceleration output has acceleration steps at its gridpoints, which
    appear here as jerk Delta(qdd) / dt: jerk figures are comparable only at one fixed dt_s.
    """
    if len(timed.qdd) < 2:
        return np.zeros((0, 7))
    return np.diff(timed.qdd, axis=0) / np.diff(timed.t_s)[:, None]


def jerk_max(timed: TimedTrajectory) -> float:
    """max over samples and joints of |jerk|, rad/s^3 (0 for a trajectory that does not move)."""
    j = jerk(timed)
    return float(np.max(np.abs(j))) if j.size else 0.0


def jerk_sq_integral(timed: TimedTrajectory) -> float:
    """Integral of the squared jerk norm: sum_k ||jerk_k||^2 dt_k, rad^2/s^5."""
    j = jerk(timed)
    return float(np.sum(np.sum(j * j, axis=1) * np.diff(timed.t_s))) if j.size else 0.0


def clearance_stats_m(world, states: np.ndarray) -> tuple[float, float]:
    """(min, mean) signed distance (metres, negative in penetration) between robot (with any held
    can) and scene over the given configurations, from the python-fcl world."""
    c = world.clearances(states)
    return float(np.min(c)), float(np.mean(c))


def goal_error(X_WG: np.ndarray, X_WG_goal: np.ndarray) -> tuple[float, float]:
    """Position error ||p_WG - p_WG_goal|| (metres) and rotation angle of R_WG^T R_WG_goal
    (degrees) of a gripper pose against its target."""
    X_WG, X_WG_goal = np.asarray(X_WG, float), np.asarray(X_WG_goal, float)
    err_m = float(np.linalg.norm(X_WG[:3, 3] - X_WG_goal[:3, 3]))
    err_deg = float(np.degrees(rotation_angle_rad(X_WG[:3, :3].T @ X_WG_goal[:3, :3])))
    return err_m, err_deg


def score(
    *,
    path,
    world,
    X_WG_goal: np.ndarray,
    timed: TimedTrajectory | None = None,
    timing_options: TimingOptions = TimingOptions(),
    step_rad: float = METRIC_STEP_RAD,
) -> dict[str, float]:
    """All metrics of one validated path, as plain floats (nan where timing failed).

    Args:
        path: the validated joint path (N, 7), rad.
        world: the problem's `scenes.fcl_world.CollisionWorld` (robot, held can, remaining cans).
        X_WG_goal: the target gripper pose (4, 4) the path should end at.
        timed: its TOPP-RA trajectory, if already computed (else computed here).
        timing_options: used when `timed` is None.
        step_rad: joint-space step (L2, rad) of the resampled paths.

    Returns:
        path_length_rad, ee_path_length_m, ee_rotation_deg, smoothness, jerk_max (rad/s^3),
        jerk_sq_integral (rad^2/s^5), clearance_min_m, clearance_mean_m, duration_s,
        goal_error_m, goal_error_deg, timing_time_s, and the timing checks velocity_limit_ratio,
        acceleration_limit_ratio, path_deviation_rad.
    """
    path = _as_path(path)
    if timed is None:
        timed = time_parameterize(path, robot=world.robot, options=timing_options)
    dense = densify(path, step_rad)
    X_WG = world.robot.gripper_pose(dense)
    c_min, c_mean = clearance_stats_m(world, dense)
    err_m, err_deg = goal_error(X_WG[-1], X_WG_goal)
    nan = math.nan
    return {
        "path_length_rad": path_length_rad(path),
        "ee_path_length_m": ee_path_length_m(X_WG),
        "ee_rotation_deg": ee_rotation_deg(X_WG),
        "smoothness": smoothness(resample_uniform(path, step_rad)),
        "jerk_max": jerk_max(timed) if timed.ok else nan,
        "jerk_sq_integral": jerk_sq_integral(timed) if timed.ok else nan,
        "clearance_min_m": c_min,
        "clearance_mean_m": c_mean,
        "duration_s": float(timed.duration_s) if timed.ok else nan,
        "goal_error_m": err_m,
        "goal_error_deg": err_deg,
        "timing_time_s": float(timed.timing_time_s),
        "velocity_limit_ratio": float(timed.velocity_ratio),
        "acceleration_limit_ratio": float(timed.acceleration_ratio),
        "path_deviation_rad": float(timed.path_deviation_rad),
    }
