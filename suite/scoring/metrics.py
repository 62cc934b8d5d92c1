"""Path and trajectory metrics, computed identically for every planner's validated path.

`score` computes every metric of `suite.scoring.definitions.METRICS` (except the times of `NOT_FROM_PATH`) for
one path. None depends on how many waypoints describe the path: geometric metrics work on the
simplified polyline (`polyline.simplify`) and on samples at a fixed arc-length spacing with its
corners (`polyline.arc_samples`); means along the path are weighted by arc length; the timed
metrics come from TOPP-RA, which simplifies the polyline the same way before timing it.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from suite.scoring import posture
from suite.scoring.definitions import COARSE_STEP_RAD, FINE_PER_COARSE
from suite.scoring.polyline import (
    ArcSamples,
    arc_samples,
    as_path,
    path_length_rad,
    resample_uniform,
)
from suite.scoring.smoothness import (
    jerk_max,
    jerk_sq_integral,
    joint_speed_sparc,
    ompl_smoothness,
    turning_angle_rad,
)
from suite.scoring.timing import TimedTrajectory, TimingOptions, time_parameterize

#: Joint-space step (L2, rad) of the resampling OMPL's smoothness is computed on.
OMPL_SMOOTHNESS_STEP_RAD = 0.05
#: Largest rate of change (m per rad of joint-space L2 motion) of the clearance. It is at most
#: sqrt(sum_j r_j^2), r_j the largest distance of a robot or held-can point from joint j's axis:
#: about 2.3 m/rad for the iiwa's link lengths. Measured on 60 recorded paths at 2 mrad steps:
#: at most 2.5 m/rad (apart from one isolated 6 mm jump of the distance query). 3 for margin.
CLEARANCE_LIPSCHITZ_M_PER_RAD = 3.0
#: The fine minimum clearance may be missed by at most this much (m): samples whose bound is within
#: it of the coarse minimum are not measured (on a flat clearance profile that would be all of them).
CLEARANCE_TOLERANCE_M = 1e-3
#: Straight distances below these make a ratio meaningless (NaN): rad, m.
MIN_STRAIGHT_RAD = 1e-6
MIN_STRAIGHT_M = 0.01


def rotation_angle_rad(R_AB: np.ndarray) -> np.ndarray:
    """Angle (rad) of rotation matrices (..., 3, 3), accurate for small and large angles:
    atan2(|vee(R - R^T)| / 2, (trace R - 1) / 2)."""
    w = np.stack([R_AB[..., 2, 1] - R_AB[..., 1, 2], R_AB[..., 0, 2] - R_AB[..., 2, 0], R_AB[..., 1, 0] - R_AB[..., 0, 1]], -1)
    tr = R_AB[..., 0, 0] + R_AB[..., 1, 1] + R_AB[..., 2, 2]
    return np.arctan2(0.5 * np.linalg.norm(w, axis=-1), 0.5 * (tr - 1.0))


def ee_path_length_m(X_WG: np.ndarray) -> float:
    """Cartesian path length of the gripper frame origin: sum_k ||p_WG[k+1] - p_WG[k]||, metres.

    Args:
        X_WG: gripper poses (M, 4, 4) at samples along the path.
    """
    p = X_WG[:, :3, 3]
    return float(np.sum(np.linalg.norm(np.diff(p, axis=0), axis=1)))


def ee_rotation_deg(X_WG: np.ndarray) -> float:
    """Total rotation of the gripper: sum_k angle(R_WG[k]^T R_WG[k+1]), degrees.

    Args:
        X_WG: gripper poses (M, 4, 4) at samples along the path.
    """
    R = X_WG[:, :3, :3]
    rel = np.swapaxes(R[:-1], -1, -2) @ R[1:]
    return float(np.degrees(np.sum(rotation_angle_rad(rel)))) if len(R) > 1 else 0.0


def clearance_stats_m(world, coarse: ArcSamples, fine: ArcSamples) -> tuple[float, float]:
    """(min, mean) signed distance (metres, negative in penetration) between robot (with any held
    can) and scene along a path, from the python-fcl world.

    The mean is by arc length over the coarse samples. The minimum is over the fine samples (to
    within CLEARANCE_TOLERANCE_M), but only those where the clearance could be lower than that
    are measured: between two coarse samples the clearance changes by at most
    CLEARANCE_LIPSCHITZ_M_PER_RAD per rad of motion.

    Args:
        world: the problem's collision world.
        coarse: samples along the path (`polyline.arc_samples`).
        fine: denser samples along the same path.
    """
    c = world.clearances(coarse.q)
    c_min = float(np.min(c))
    if len(c) > 1:
        s, k = coarse.s_rad, CLEARANCE_LIPSCHITZ_M_PER_RAD
        i = np.clip(np.searchsorted(s, fine.s_rad, side="right") - 1, 0, len(s) - 2)
        bound = np.maximum(c[i] - k * (fine.s_rad - s[i]), c[i + 1] - k * (s[i + 1] - fine.s_rad))
        todo = bound < c_min - CLEARANCE_TOLERANCE_M
        if np.any(todo):
            c_min = min(c_min, float(np.min(world.clearances(fine.q[todo]))))
    return c_min, coarse.mean(c)


def min_clearance_m(world, path) -> float:
    """The metric `clearance_min_m` of a joint path alone (m): its smallest signed distance to the
    scene at samples at most 0.01 rad apart by arc length (`clearance_stats_m`)."""
    path = as_path(path)
    return clearance_stats_m(world, arc_samples(path, COARSE_STEP_RAD),
                             arc_samples(path, COARSE_STEP_RAD, per_step=FINE_PER_COARSE))[0]


def goal_error(X_WG: np.ndarray, X_WG_goal: np.ndarray) -> tuple[float, float]:
    """Position error ||p_WG - p_WG_goal|| (metres) and rotation angle of R_WG^T R_WG_goal
    (degrees) of a gripper pose against its target."""
    X_WG, X_WG_goal = np.asarray(X_WG, float), np.asarray(X_WG_goal, float)
    err_m = float(np.linalg.norm(X_WG[:3, 3] - X_WG_goal[:3, 3]))
    err_deg = float(np.degrees(rotation_angle_rad(X_WG[:3, :3].T @ X_WG_goal[:3, :3])))
    return err_m, err_deg


def _ratio(value: float, reference: float | None, minimum: float) -> float:
    if reference is None or not math.isfinite(reference) or reference < minimum:
        return math.nan
    return value / reference


def score(
    *,
    path,
    world,
    X_WG_goal: np.ndarray,
    timed: TimedTrajectory | None = None,
    timing_options: TimingOptions = TimingOptions(),
    reference_length_rad: float | None = None,
    reference_ee_length_m: float | None = None,
) -> dict[str, float]:
    """All metrics of one validated path, as plain floats (NaN where undefined or timing failed).

    Args:
        path: the validated joint path (N, 7), rad.
        world: the problem's `scenes.collision.world.CollisionWorld` (robot, held can, remaining cans).
        X_WG_goal: the target gripper pose (4, 4) the path should end at.
        timed: its TOPP-RA trajectory, if already computed (else computed here).
        timing_options: used when `timed` is None.
        reference_length_rad: the problem's reference joint path length (for `length_ratio`).
        reference_ee_length_m: the reference path's gripper path length (for `ee_length_ratio`).

    Returns:
        Every metric of `suite.scoring.definitions.METRICS` but those of `NOT_FROM_PATH`, by name.
    """
    path = as_path(path)
    robot = world.robot
    if timed is None:
        timed = time_parameterize(path, robot=robot, options=timing_options)
    coarse = arc_samples(path, COARSE_STEP_RAD)
    fine = arc_samples(path, COARSE_STEP_RAD, per_step=FINE_PER_COARSE)
    f = _fine_stats(fine.q, robot, posture.carried_upright_can(world))
    c_min, c_mean = clearance_stats_m(world, coarse, fine)
    err_m, err_deg = goal_error(f["X_WG_last"], X_WG_goal)
    length = path_length_rad(path)
    ee_length = f["ee_length_m"]
    nan = math.nan
    return {
        "path_length_rad": length,
        "ee_path_length_m": ee_length,
        "ee_rotation_deg": f["ee_rotation_deg"],
        "length_ratio": _ratio(length, reference_length_rad, MIN_STRAIGHT_RAD),
        "length_over_straight": _ratio(length, float(np.linalg.norm(path[-1] - path[0])), MIN_STRAIGHT_RAD),
        "ee_length_ratio": _ratio(ee_length, reference_ee_length_m, MIN_STRAIGHT_M),
        "ee_length_over_straight": _ratio(ee_length, float(np.linalg.norm(f["X_WG_last"][:3, 3]
                                                                          - f["X_WG_first"][:3, 3])), MIN_STRAIGHT_M),
        "turning_angle_rad": turning_angle_rad(path),
        "sparc": joint_speed_sparc(timed),
        "smoothness": ompl_smoothness(resample_uniform(path, OMPL_SMOOTHNESS_STEP_RAD)),
        "jerk_max": jerk_max(timed) if timed.ok else nan,
        "jerk_sq_integral": jerk_sq_integral(timed) if timed.ok else nan,
        "joint_margin_min_frac": f["joint_margin_min_frac"],
        "posture_distance_mean_rad": fine.mean(posture.posture_distances_rad(fine.q)),
        "manipulability_min_m3": f["manipulability_min_m3"],
        "can_tilt_max_deg": f["can_tilt_max_deg"],
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


#: Fine samples whose forward kinematics are computed at once (each costs a few kB of temporaries:
#: a dense claimed path's samples would otherwise hold gigabytes).
FK_CHUNK = 2048


def _fine_stats(q: np.ndarray, robot, X_GC: np.ndarray | None) -> dict[str, Any]:
    """The metrics of the fine samples that need forward kinematics, FK_CHUNK samples at a time
    (consecutive chunks share a sample, so the summed lengths and rotations are those of the whole)."""
    ee_length = rotation = 0.0
    margin = manip = math.inf
    tilt = -math.inf
    first = last = None
    n = len(q)
    for lo in range(0, n, FK_CHUNK):
        block = q[max(lo - 1, 0) : lo + FK_CHUNK]
        X_WG = robot.gripper_pose(block)
        ee_length += ee_path_length_m(X_WG)
        rotation += ee_rotation_deg(X_WG)
        own = block if lo == 0 else block[1:]
        margin = min(margin, float(np.min(posture.joint_limit_margins(own, robot))))
        manip = min(manip, float(np.min(posture.manipulability(own, robot))))
        if X_GC is not None:
            tilt = max(tilt, posture.tilt_max_deg(own, robot, X_GC))
        first = X_WG[0] if first is None else first
        last = X_WG[-1]
    return {"ee_length_m": ee_length, "ee_rotation_deg": rotation, "joint_margin_min_frac": margin,
            "manipulability_min_m3": manip, "can_tilt_max_deg": tilt if X_GC is not None else math.nan,
            "X_WG_first": first, "X_WG_last": last}


def record_metrics(scored: dict[str, Any]) -> dict[str, float | None]:
    """Metrics as a trial record stores them: floats, with NaN as null (JSON has no NaN)."""
    return {k: (float(v) if math.isfinite(v) else None) for k, v in scored.items()
            if isinstance(v, (int, float)) and not isinstance(v, bool)}
