"""Time parameterization of a validated joint path with TOPP-RA, identical for every planner.

The validated path is piecewise linear in joint space (the collision validator checks the straight
segments between waypoints). Its polyline is simplified first (duplicate and collinear waypoints
dropped, `suite.scoring.polyline.simplify`), so the timing depends on the path, not on how many
waypoints describe it. A cubic spline through sparse waypoints would overshoot between them
and leave the checked segments, so the path is first densified: every segment is cut into pieces
of at most `TimingOptions.densify_step_rad` (L2, rad) and the spline (`toppra.SplineInterpolator`,
not-a-knot, parameterized by joint-space arc length s in rad) goes through all those points. On the
straight parts the spline then stays on the segment; at a corner it rounds the corner within a
distance that shrinks with the step (measured: under 0.1 of the step, 3-5 mrad at the default
0.05 rad), and TOPP-RA
slows down there as the spline's curvature demands. The largest distance of the timed trajectory
from the validated polyline is measured and reported (`path_deviation_rad`).

TOPP-RA (`toppra.algorithm.TOPPRA`, seidel solver, interpolation discretization) runs on the iiwa's
joint velocity and acceleration limits from the robot model (the URDF). Its output is turned into
a trajectory with `ParametrizeConstAccel` (constant path acceleration between gridpoints). The
limits hold at the gridpoints but not necessarily between them (by 10-40% with a uniform grid on
a path with corners: the curvature changes fast there), so the gridpoints are made denser where
the spline bends, the result is checked densely (`check_substeps` points inside every grid
interval, in s, plus the fixed-dt samples), and intervals over the limits are split and the
problem solved again (at most `max_refinements` times; then, as a last resort, once more with the
limits tightened by the remaining excess). A trajectory still over the limits by more than
`limit_tolerance` gets status "timing_failed".
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time

import numpy as np
import toppra
import toppra.algorithm
import toppra.constraint
from scipy.interpolate import CubicSpline

from scenes.robot_model import RobotModel, load_robot
from suite.scoring.polyline import simplify

log = logging.getLogger(__name__)

OK = "ok"
TIMING_FAILED = "timing_failed"
SPLIT = 4  # a grid interval over the limits is split into this many
MIN_GRID_INTERVALS = 32


@dataclasses.dataclass(frozen=True)
class TimingOptions:
    """How paths are timed and checked.

    Attributes:
        densify_step_rad: longest piece (L2 joint distance, rad) of the densified polyline
            that the spline goes through.
        sample_dt_s: the time step of the sampled arrays (plots, execution, jerk).
        limit_tolerance: allowed relative excess over a velocity or acceleration limit (0.01 = 1%).
        check_substeps: points checked inside each grid interval.
        max_refinements: rounds of splitting grid intervals that exceed the limits.
        grid_curvature_gain: extra gridpoints where the path bends (see `_initial_grid`).
        duplicate_tol_rad: consecutive waypoints closer than this (L2, rad) are merged.
    """

    densify_step_rad: float = 0.05
    sample_dt_s: float = 0.01
    limit_tolerance: float = 0.01
    check_substeps: int = 8
    max_refinements: int = 2
    grid_curvature_gain: float = 8.0
    duplicate_tol_rad: float = 1e-9


@dataclasses.dataclass(frozen=True, eq=False)
class TimedTrajectory:
    """A time-parameterized joint path.

    Attributes:
        status: "ok" or "timing_failed".
        reason: why timing failed ("" when ok).
        duration_s: total time (0 for a path that does not move; nan when timing failed).
        t_s: sample times (K,) at `dt_s`, the last one exactly at duration_s.
        q, qd, qdd: positions (rad), velocities (rad/s), accelerations (rad/s^2) at t_s, (K, 7).
        dt_s: the sample time step.
        velocity_ratio: max over the dense check of |qd_i| / limit_i (1.0 = at the limit).
        acceleration_ratio: max over the dense check of |qdd_i| / limit_i.
        path_deviation_rad: the largest L2 distance (rad) from the timed trajectory to the
            validated piecewise-linear path, measured at the dense check points.
        timing_time_s: wall time spent timing and checking.
        n_gridpoints: TOPP-RA gridpoints of the final solve.
    """

    status: str
    reason: str
    duration_s: float
    t_s: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    dt_s: float
    velocity_ratio: float
    acceleration_ratio: float
    path_deviation_rad: float
    timing_time_s: float
    n_gridpoints: int
    spline: CubicSpline | None = dataclasses.field(default=None, repr=False)
    s_grid: np.ndarray | None = dataclasses.field(default=None, repr=False)
    sd_grid: np.ndarray | None = dataclasses.field(default=None, repr=False)
    t_grid: np.ndarray | None = dataclasses.field(default=None, repr=False)
    q_hold: np.ndarray | None = dataclasses.field(default=None, repr=False)

    @property
    def ok(self) -> bool:
        return self.status == OK

    def sample(self, t_s) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions, velocities and accelerations at times t_s (scalar or (K,)), clipped to
        [0, duration_s]. Returns arrays of shape (7,) or (K, 7) each."""
        if not self.ok:
            raise ValueError(f"cannot sample a trajectory with status {self.status!r}")
        t = np.asarray(t_s, float)
        scalar = t.ndim == 0
        t = np.atleast_1d(t)
        if self.spline is None:  # a path that does not move
            q = np.broadcast_to(self.q_hold, (len(t), 7)).copy()
            z = np.zeros_like(q)
            out = (q, z, z.copy())
        else:
            out = _eval_const_accel(self.spline, self.s_grid, self.sd_grid, self.t_grid, t)
        return tuple(o[0] for o in out) if scalar else out


def _densify(path: np.ndarray, step_rad: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split each segment into equal pieces of at most step_rad.

    Returns the points (M, 7), their arc length s (M,) and, for each of the M-1 pieces, the index
    of the original segment it lies on.
    """
    seg = np.diff(path, axis=0)
    seg_len = np.linalg.norm(seg, axis=1)
    n = np.maximum(1, np.ceil(seg_len / step_rad).astype(int))
    seg_of_piece = np.repeat(np.arange(len(seg)), n)
    frac = np.concatenate([np.arange(k) / k for k in n])  # start fraction of each piece
    pts = np.vstack([path[seg_of_piece] + frac[:, None] * seg[seg_of_piece], path[-1:]])
    s_start = np.concatenate([[0.0], np.cumsum(seg_len)])
    s = np.concatenate([s_start[seg_of_piece] + frac * seg_len[seg_of_piece], [s_start[-1]]])
    return pts, s, seg_of_piece


def _grid_times(s_grid: np.ndarray, sd_grid: np.ndarray) -> np.ndarray:
    """Times at the gridpoints under constant path acceleration between them."""
    ds = np.diff(s_grid)
    return np.concatenate([[0.0], np.cumsum(2.0 * ds / np.maximum(sd_grid[:-1] + sd_grid[1:], 1e-300))])


def _eval_const_accel(spline, s_grid, sd_grid, t_grid, t):
    """q, qd, qdd at times t of the constant-path-acceleration parameterization.

    The same formulas as toppra's ParametrizeConstAccel, vectorized: within grid interval i,
    sdd = u_i = (sd_{i+1}^2 - sd_i^2) / (2 ds_i), sd = sd_i + u_i dt, s = s_i + sd_i dt + u_i dt^2/2.
    """
    u = 0.5 * np.diff(sd_grid**2) / np.diff(s_grid)
    t = np.clip(t, 0.0, t_grid[-1])
    i = np.clip(np.searchsorted(t_grid, t, side="right") - 1, 0, len(u) - 1)
    dt = t - t_grid[i]
    sd = np.maximum(sd_grid[i] + u[i] * dt, 0.0)
    s = np.clip(s_grid[i] + sd_grid[i] * dt + 0.5 * u[i] * dt**2, s_grid[i], s_grid[i + 1])
    qs = spline(s, 1)
    return spline(s), qs * sd[:, None], spline(s, 2) * (sd**2)[:, None] + qs * u[i][:, None]


def _check_intervals(spline, s_grid, sd_grid, v_lim, a_lim, substeps):
    """Per grid interval, the max velocity and acceleration ratios over substeps+1 points in s.

    Returns (v_ratio (N,), a_ratio (N,), the checked s values (N, substeps+1)).
    """
    x = sd_grid**2
    ds = np.diff(s_grid)
    u = 0.5 * np.diff(x) / ds
    f = np.linspace(0.0, 1.0, substeps + 1)
    s = s_grid[:-1, None] + f[None, :] * ds[:, None]
    xs = np.maximum(x[:-1, None] + 2.0 * u[:, None] * (s - s_grid[:-1, None]), 0.0)
    flat = s.ravel()
    qs = spline(flat, 1).reshape(s.shape + (-1,))
    qss = spline(flat, 2).reshape(s.shape + (-1,))
    qd = qs * np.sqrt(xs)[..., None]
    qdd = qss * xs[..., None] + qs * u[:, None, None]
    v_ratio = np.max(np.abs(qd) / v_lim, axis=(1, 2))
    a_ratio = np.max(np.abs(qdd) / a_lim, axis=(1, 2))
    return v_ratio, a_ratio, s


def _deviation(spline, s_checked, s_knots, seg_of_piece, polyline) -> float:
    """Largest distance (L2, rad) of the spline from the polyline over the checked s values; each is
    measured to the original segment it lies on and its two neighbours (an upper bound on the
    distance to the whole polyline at that point)."""
    s = s_checked.ravel()
    q = spline(s)
    piece = np.clip(np.searchsorted(s_knots, s, side="right") - 1, 0, len(seg_of_piece) - 1)
    j = seg_of_piece[piece]
    A, D = polyline[:-1], np.diff(polyline, axis=0)
    L2 = np.einsum("ij,ij->i", D, D)
    best = np.full(len(s), np.inf)
    for off in (-1, 0, 1):
        k = np.clip(j + off, 0, len(D) - 1)
        w = np.clip(np.einsum("ij,ij->i", q - A[k], D[k]) / L2[k], 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(q - A[k] - w[:, None] * D[k], axis=1))
    return float(best.max())


def _initial_grid(spline, knots_s: np.ndarray, gain: float) -> np.ndarray:
    """Gridpoints: every knot, and more inside the pieces where the path bends.

    Between gridpoints the limits are only met approximately, and the excess grows with how much
    the path's curvature changes over an interval: a piece of length ds whose second derivative
    reaches |q''| (rad/rad^2) is cut into 1 + gain * ds * |q''| intervals (at most 16), and the
    whole path has at least MIN_GRID_INTERVALS intervals.
    """
    ds = np.diff(knots_s)
    qss = np.abs(spline(knots_s, 2)).max(axis=1)
    bend = np.maximum(qss[:-1], qss[1:]) * ds
    n = np.clip(1 + np.floor(gain * bend).astype(int), 1, 16)
    # A short path has few knots; TOPP-RA needs interior gridpoints to speed up at all.
    n = np.maximum(n, math.ceil(MIN_GRID_INTERVALS / len(ds)))
    frac = np.concatenate([np.arange(k) / k for k in n])
    start = np.repeat(knots_s[:-1], n)
    return np.append(start + frac * np.repeat(ds, n), knots_s[-1])


def _solve(spline_path, grid, v_lim, a_lim, sd_start=0.0):
    """One TOPP-RA solve: the path velocities sd at the gridpoints (from sd_start), or None."""
    vel = toppra.constraint.JointVelocityConstraint(np.column_stack([-v_lim, v_lim]))
    acc = toppra.constraint.JointAccelerationConstraint(
        np.column_stack([-a_lim, a_lim]),
        discretization_scheme=toppra.constraint.DiscretizationType.Interpolation,
    )
    instance = toppra.algorithm.TOPPRA(
        [vel, acc], spline_path, gridpoints=grid, parametrizer="ParametrizeConstAccel", solver_wrapper="seidel"
    )
    if sd_start > 0:  # an uncontrollable start speed is an answer here (the join tries slower), not a warning
        reach_log = logging.getLogger("toppra.algorithm.reachabilitybased.reachability_algorithm")
        level = reach_log.level
        reach_log.setLevel(logging.ERROR)
        try:
            instance.compute_parameterization(sd_start, 0.0)
        finally:
            reach_log.setLevel(level)
    else:
        instance.compute_parameterization(0.0, 0.0)
    data = instance.problem_data
    if data.return_code != toppra.algorithm.ParameterizationReturnCode.Ok or data.sd_vec is None:
        return None
    sd = np.asarray(data.sd_vec, float)
    if not np.all(np.isfinite(sd)):
        return None
    return np.maximum(sd, 0.0)


def _failed(reason: str, start: float, dt_s: float, quiet: bool = False, **extra) -> TimedTrajectory:
    (log.debug if quiet else log.warning)("timing failed: %s", reason)
    empty = np.zeros((0, 7))
    fields = dict(velocity_ratio=math.nan, acceleration_ratio=math.nan, path_deviation_rad=math.nan, n_gridpoints=0)
    fields.update(extra)
    return TimedTrajectory(
        status=TIMING_FAILED, reason=reason, duration_s=math.nan, t_s=np.zeros(0), q=empty, qd=empty,
        qdd=empty, dt_s=dt_s, timing_time_s=time.perf_counter() - start, **fields,
    )


def time_parameterize(
    path: np.ndarray,
    *,
    robot: RobotModel | None = None,
    options: TimingOptions = TimingOptions(),
    sd_start: float = 0.0,
) -> TimedTrajectory:
    """Time-optimal trajectory along a validated joint path within the robot's limits.

    Args:
        path: waypoints (N, 7) in rad, N >= 1, joined by straight joint-space segments.
        robot: whose velocity and acceleration limits apply (the project's iiwa 14 by default).
        options: densification, sampling and checking settings.
        sd_start: the path speed at the start (rad/s of joint-space arc length; 0: from rest, as
            every trial is timed). A moving start (the moving bin's joins) needs it inside TOPP-RA's
            controllable set, else the status is "timing_failed".

    Returns:
        A TimedTrajectory; status "timing_failed" (never an exception) when TOPP-RA finds no
        parameterization or the result exceeds the limits beyond the tolerance.
    """
    start = time.perf_counter()
    robot = robot or load_robot()
    path = np.asarray(path, float)
    if path.ndim != 2 or path.shape[1] != 7 or len(path) == 0:
        raise ValueError(f"path must be an (N, 7) array with N >= 1, got shape {path.shape}")
    if not np.all(np.isfinite(path)):
        return _failed("path contains non-finite values", start, options.sample_dt_s)
    v_lim, a_lim = robot.velocity_limits_rad_s, robot.acceleration_limits_rad_s2
    # The polyline itself, whatever waypoints describe it: collinear waypoints would move the
    # spline's knots and TOPP-RA's grid, and with them the timing, without changing the path.
    poly = simplify(path, duplicate_tol_rad=options.duplicate_tol_rad)
    if len(poly) == 1:  # zero-length: nothing to time
        q = poly[:1].copy()
        z = np.zeros_like(q)
        return TimedTrajectory(
            status=OK, reason="", duration_s=0.0, t_s=np.zeros(1), q=q, qd=z, qdd=z.copy(),
            dt_s=options.sample_dt_s, velocity_ratio=0.0, acceleration_ratio=0.0, path_deviation_rad=0.0,
            timing_time_s=time.perf_counter() - start, n_gridpoints=0, q_hold=poly[0].copy(),
        )

    knots_q, knots_s, seg_of_piece = _densify(poly, options.densify_step_rad)
    spline_path = toppra.SplineInterpolator(knots_s, knots_q)
    spline = spline_path.cspl
    grid = _initial_grid(spline, knots_s, options.grid_curvature_gain)

    tol = options.limit_tolerance
    v_scale = a_scale = 1.0
    rounds = 0
    for round_ in range(options.max_refinements + 2):
        rounds += 1
        try:
            sd = _solve(spline_path, grid, v_lim * v_scale, a_lim * a_scale, sd_start)
        except (toppra.exceptions.ToppraError, ValueError, ZeroDivisionError) as e:
            return _failed(f"TOPP-RA raised {type(e).__name__}: {e}", start, options.sample_dt_s)
        if sd is None:  # from a moving start, an expected answer (the join tries a slower one)
            return _failed("TOPP-RA found no feasible parameterization", start, options.sample_dt_s,
                           quiet=sd_start > 0, n_gridpoints=len(grid))
        v_ratio, a_ratio, s_checked = _check_intervals(spline, grid, sd, v_lim, a_lim, options.check_substeps)
        bad = (v_ratio > 1.0 + 0.8 * tol) | (a_ratio > 1.0 + 0.8 * tol)
        if not bad.any():
            break
        if round_ < options.max_refinements:
            # Split the offending intervals in four: the excess between gridpoints shrinks
            # quadratically with the interval length.
            idx = np.nonzero(bad)[0]
            ds = np.diff(grid)[idx]
            extra = (grid[idx, None] + ds[:, None] * (np.arange(1, SPLIT) / SPLIT)).ravel()
            grid = np.union1d(grid, extra)
        else:
            # Last resort: tighten the limits by the remaining excess and solve once more.
            v_scale /= max(1.0, float(v_ratio.max()))
            a_scale /= max(1.0, float(a_ratio.max()))
    log.debug("timing: %d solves, %d gridpoints", rounds, len(grid))
    v_max, a_max = float(v_ratio.max()), float(a_ratio.max())

    t_grid = _grid_times(grid, sd)
    duration = float(t_grid[-1])
    if not math.isfinite(duration) or np.any(sd[:-1] + sd[1:] <= 0.0):
        return _failed("TOPP-RA returned a parameterization that stops on the path", start,
                       options.sample_dt_s, n_gridpoints=len(grid))
    dt = options.sample_dt_s
    t = np.arange(0.0, duration, dt)
    t = np.append(t[t < duration - 1e-9], duration)
    q, qd, qdd = _eval_const_accel(spline, grid, sd, t_grid, t)
    v_max = max(v_max, float(np.max(np.abs(qd) / v_lim)))
    a_max = max(a_max, float(np.max(np.abs(qdd) / a_lim)))
    deviation = _deviation(spline, s_checked, knots_s, seg_of_piece, poly)
    common = dict(
        duration_s=duration, t_s=t, q=q, qd=qd, qdd=qdd, dt_s=dt, velocity_ratio=v_max,
        acceleration_ratio=a_max, path_deviation_rad=deviation, n_gridpoints=len(grid),
        spline=spline, s_grid=grid, sd_grid=sd, t_grid=t_grid,
    )
    if v_max > 1.0 + tol or a_max > 1.0 + tol:
        reason = f"limits exceeded after {options.max_refinements} refinements: velocity x{v_max:.4f}, acceleration x{a_max:.4f}"
        log.warning("timing failed: %s", reason)
        return TimedTrajectory(status=TIMING_FAILED, reason=reason, timing_time_s=time.perf_counter() - start, **common)
    return TimedTrajectory(status=OK, reason="", timing_time_s=time.perf_counter() - start, **common)
