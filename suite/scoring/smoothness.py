"""Smoothness of a path's geometry (turning angle; OMPL's formula) and of its timed motion (SPARC, jerk).

- `turning_angle_rad`: the headline geometric smoothness. It depends on the polyline only (not on
  the waypoint density), is 0 for a straight segment and grows with every kink.
- `ompl_smoothness`: OMPL's PathGeometric::smoothness(), kept for the Planner Arena export. It is
  ~0 for any straight segment and grows without bound for small kinks on dense paths, so it is
  not a headline figure.
- `sparc`: the spectral arc length of a speed profile (Balasubramanian, Melendez-Calderon,
  Roby-Brami, Burdet 2015, "On the analysis of movement smoothness", J. NeuroEng. Rehabil.
  12:112). Applied to the joint-space speed of the TOPP-RA trajectory, it barely moves with
  TOPP-RA's grid, whereas jerk does (see `jerk`).
"""

from __future__ import annotations

import math

import numpy as np

from suite.scoring.polyline import angle_between_rad, simplify
from suite.scoring.timing import TimedTrajectory

#: SPARC's parameters, the paper's recommended values: zero padding (powers of two beyond the
#: signal's), the largest cut-off frequency (Hz), and the spectrum amplitude threshold.
SPARC_PAD_LEVEL = 4
SPARC_MAX_CUTOFF_HZ = 10.0
SPARC_AMPLITUDE_THRESHOLD = 0.05
#: Rate (Hz) at which the timed trajectory's speed is sampled for SPARC.
SPARC_SAMPLE_HZ = 100.0


def turning_angles_rad(path) -> np.ndarray:
    """The angle (rad) between consecutive segment directions at each corner of the simplified path.

    Zero-length segments and collinear points are dropped first (`polyline.simplify`), so inserting
    waypoints on the segments changes nothing. A full reversal counts pi.
    """
    poly = simplify(path)
    if len(poly) < 3:
        return np.zeros(0)
    d = np.diff(poly, axis=0)
    u = d / np.linalg.norm(d, axis=1, keepdims=True)
    return angle_between_rad(u[:-1], u[1:])


def turning_angle_rad(path) -> float:
    """Total turning angle of the joint path: the sum of `turning_angles_rad`, rad (0 for a straight
    segment, pi/2 for one right-angle corner; a smooth curve gives its total curvature)."""
    return float(np.sum(turning_angles_rad(path)))


def ompl_smoothness(states) -> float:
    """OMPL's PathGeometric::smoothness() of a sequence of states (dimensionless sum, 1/rad^2).

    For consecutive segments of lengths a = d(s_{i-2}, s_{i-1}), b = d(s_{i-1}, s_i) and the chord
    c = d(s_{i-2}, s_i) (L2 distances), the turning angle is theta = pi - acos((a^2 + b^2 - c^2) /
    (2ab)) and the term is (2 theta / (a + b))^2; the smoothness is the sum of the terms. As in
    OMPL, a term is skipped unless -1 < (a^2 + b^2 - c^2) / (2ab) < 1 (straight continuations and
    full reversals add nothing). Lower is smoother; 0 for a straight line.

    Call it on `polyline.resample_uniform(path, step)` so that it does not depend on the waypoints.
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


def sparc(speed, *, sample_hz: float, pad_level: int = SPARC_PAD_LEVEL, max_cutoff_hz: float = SPARC_MAX_CUTOFF_HZ,
          amplitude_threshold: float = SPARC_AMPLITUDE_THRESHOLD) -> float:
    """Spectral arc length of a speed profile sampled at sample_hz (dimensionless, <= 0).

    The magnitude spectrum of the zero-padded profile is normalized by its peak; the cut-off is the
    highest frequency up to max_cutoff_hz whose magnitude is at least amplitude_threshold; SPARC is
    minus the length of the spectrum's curve up to the cut-off, with frequency scaled by the
    cut-off. Closer to 0 is smoother (a bell-shaped speed profile scores about -1.4; every extra
    speed-up and slow-down lowers it). Sign as in the paper.

    Returns:
        SPARC, or 0.0 for a profile that never moves.
    """
    v = np.asarray(speed, float)
    if v.size < 2 or not np.any(v > 0):
        return 0.0
    n_fft = 2 ** (math.ceil(math.log2(v.size)) + pad_level)
    f = np.arange(n_fft // 2 + 1) * (sample_hz / n_fft)
    mag = np.abs(np.fft.rfft(v, n_fft))
    mag = mag / mag.max()
    inside = f <= max_cutoff_hz
    f, mag = f[inside], mag[inside]
    above = np.nonzero(mag >= amplitude_threshold)[0]
    last = int(above[-1]) if above.size else 0
    f, mag = f[: last + 1], mag[: last + 1]
    if f.size < 2:
        return 0.0
    return -float(np.sum(np.hypot(np.diff(f) / f[-1], np.diff(mag))))


def joint_speed_sparc(timed: TimedTrajectory, *, sample_hz: float = SPARC_SAMPLE_HZ) -> float:
    """SPARC of the joint-space speed ||qd(t)||_2 of a timed trajectory, sampled at sample_hz
    (0.0 for a trajectory that does not move; NaN if timing failed)."""
    if not timed.ok:
        return math.nan
    if timed.duration_s <= 0.0:
        return 0.0
    n = max(2, round(timed.duration_s * sample_hz) + 1)
    t = np.linspace(0.0, timed.duration_s, n)
    _, qd, _ = timed.sample(t)
    return sparc(np.linalg.norm(qd, axis=1), sample_hz=(n - 1) / timed.duration_s)


def jerk(timed: TimedTrajectory) -> np.ndarray:
    """Joint jerk (rad/s^3), (K-1, 7): finite differences of the accelerations sampled at dt_s.

    TOPP-RA's constant-path-acceleration output has acceleration steps at its gridpoints, which
    appear here as jerk Delta(qdd) / dt: jerk figures are comparable only at one fixed dt_s and
    one TOPP-RA grid.
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
