"""Splicing a new plan into a moving arm's command without a jump: the join, and the stopping blend.

The join (`join_path`, every replan of the moving bin): the planner plans from the commanded
position at the splice, q_s; the arm arrives there moving (v_s, a_s). A quintic per joint bends
the current motion onto the new path: from (q_s, v_s, a_s) to the state (q_j, v_j, a_j) in which
TOPP-RA's timing of the path's remainder begins, q_j a point of the path a short arc length L
ahead, the remainder timed from a path speed sd > 0 (`time_parameterize(sd_start=...)`), so v_j
is tangent to the path. The command is then continuous in position and velocity at the splice
and at the join, the blend matches the acceleration at both ends (TOPP-RA's own acceleration is
piecewise constant, so it steps anyway at its gridpoints), and the arm does not stop. The join tries the speed it
arrives with first (sd = |v_s|, capped by the joint velocity limits along the path's first
direction), then half and a quarter of it, on two arc lengths each (as far as the speed change
needs at the acceleration limits, and three times that); only when none is within the
limits (the path's start may turn too sharply, or be too short to stop on from that speed) does
the arm stop: the stopping blend, then the path from where it stopped (back to q_s first;
`Join.at_rest`, recorded). The blend leaves the planned path: its samples are part of the
polyline the validator checks.

The stopping blend (`stopping_blend`, below) brings the arm to rest: after a release on the move,
and for a protective stop.

A new plan is timed by TOPP-RA from rest (its start speed along the path is a scalar, and the
arm's velocity at the splice generally points elsewhere), so it cannot follow the current
command directly. The blend bridges them: a quintic per joint from the commanded state at the
splice (q0, v0, a0) to rest at q1 = q0 + v0 T/2 + a0 T^2/12. With a0 = 0 its velocity is
v0 (1 - 3 u^2 + 2 u^3), u = t/T: it never reverses and never exceeds |v0|, and its acceleration
peaks at 1.5 |v0| / T. T is the shortest duration on a grid whose dense samples keep every joint
within its velocity and acceleration limits and its position limits. The command is then
continuous in position, velocity and acceleration at the splice, and in position and velocity
(both at rest) where the new plan begins.

A start at a joint's velocity limit that still accelerates along it (TOPP-RA's profile, sampled
between its gridpoints) has no such stop within the limits: the speed would grow first. Then the
blend starts from (q0, v0, 0) instead: continuous in position and velocity, its acceleration
stepping from a0 to 0 at the splice (`BlendTrajectory.matches_acceleration` says which).
"""

from __future__ import annotations

import dataclasses

import numpy as np

#: The share of the acceleration limits a blend may use (the rest absorbs the dense check's
#: sampling), and of the velocity limits (TOPP-RA's own tolerance: a start at the velocity limit
#: that still accelerates, as a sampled command may, overshoots it for an instant).
LIMIT_SHARE = 0.95
VELOCITY_SHARE = 1.01
#: Samples per blend for its checks and its polyline.
SAMPLES = 101


def _coefficients(q0, v0, a0, q1, T, v1=0.0, a1=0.0):
    """Quintic coefficients (6, 7) from (q0, v0, a0) at 0 to (q1, v1, a1) at T."""
    d = q1 - q0
    c3 = (20 * d - (8 * v1 + 12 * v0) * T - (3 * a0 - a1) * T**2) / (2 * T**3)
    c4 = (-30 * d + (14 * v1 + 16 * v0) * T + (3 * a0 - 2 * a1) * T**2) / (2 * T**4)
    c5 = (12 * d - 6 * (v1 + v0) * T - (a0 - a1) * T**2) / (2 * T**5)
    return np.stack([q0, v0, a0 / 2, c3, c4, c5])


def _eval(c, t):
    q = c[0] + t * (c[1] + t * (c[2] + t * (c[3] + t * (c[4] + t * c[5]))))
    v = c[1] + t * (2 * c[2] + t * (3 * c[3] + t * (4 * c[4] + t * 5 * c[5])))
    a = 2 * c[2] + t * (6 * c[3] + t * (12 * c[4] + t * 20 * c[5]))
    return q, v, a


@dataclasses.dataclass(frozen=True, eq=False)
class BlendTrajectory:
    """A timed quintic stop (`sample` like `TimedTrajectory.sample`).

    Attributes:
        duration_s: its length (0: the arm was at rest already).
        coefficients: (6, 7) per joint, in powers of t.
        q: its samples (SAMPLES, 7) at even times (the last one is where it ends, at rest).
    """

    duration_s: float
    coefficients: np.ndarray
    q: np.ndarray
    matches_acceleration: bool = True

    ok = True
    status = "ok"

    def sample(self, t_s):
        t = np.asarray(t_s, float)
        scalar = t.ndim == 0
        t = np.clip(np.atleast_1d(t), 0.0, self.duration_s)[:, None]
        q, v, a = _eval(self.coefficients, t)
        return (q[0], v[0], a[0]) if scalar else (q, v, a)


def stopping_blend(q0, v0, a0, *, v_lim, a_lim, q_lo, q_hi, max_duration_s: float = 3.0) -> BlendTrajectory | None:
    """The shortest quintic stop from (q0, v0, a0) within the limits (see the module docstring), or
    None if none up to `max_duration_s` stays within them (then the caller keeps its plan)."""
    q0, v0, a0 = (np.asarray(x, float) for x in (q0, v0, a0))
    if np.max(np.abs(v0)) < 1e-9 and np.max(np.abs(a0)) < 1e-9:
        return BlendTrajectory(0.0, np.stack([q0, *np.zeros((5, 7))]), q0[None, :].copy())
    lim = dict(v_lim=v_lim, a_lim=a_lim, q_lo=q_lo, q_hi=q_hi, max_duration_s=max_duration_s)
    found = _search(q0, v0, a0, **lim)
    if found is None and np.max(np.abs(a0)) > 0:
        found = _search(q0, v0, np.zeros_like(a0), **lim)
        found = None if found is None else dataclasses.replace(found, matches_acceleration=False)
    return found


def _search(q0, v0, a0, *, v_lim, a_lim, q_lo, q_hi, max_duration_s, end=None) -> BlendTrajectory | None:
    """The shortest quintic on the duration grid within the limits, or None: a stop (end None,
    its rest position q0 + v0 T/2 + a0 T^2/12) or to a given end state (q1, v1, a1)."""
    v_ok, a_ok = VELOCITY_SHARE * np.asarray(v_lim), LIMIT_SHARE * np.asarray(a_lim)
    v1 = a1 = np.zeros_like(v0)
    if end is not None:
        q1, v1, a1 = (np.asarray(x, float) for x in end)
    t_min = max(float(np.max(1.5 * np.abs(v1 - v0) / a_ok)), 0.02)
    u = np.linspace(0.0, 1.0, SAMPLES)[:, None]
    # the ends' own velocity and acceleration may sit at the limit (TOPP-RA's); the blend adds none beyond
    v_bound = np.maximum(v_ok, np.maximum(np.abs(v0), np.abs(v1)))
    a_bound = np.maximum(a_ok, np.maximum(np.abs(a0), np.abs(a1)))
    for T in t_min * 1.1 ** np.arange(60):
        if T > max_duration_s:
            break
        if end is None:
            q1 = q0 + v0 * T / 2 + a0 * T**2 / 12
        c = _coefficients(q0, v0, a0, q1, T, v1, a1)
        q, v, a = _eval(c, u * T)
        if (np.all(np.abs(v) <= v_bound) and np.all(np.abs(a) <= a_bound)
                and np.all(q >= q_lo) and np.all(q <= q_hi)):
            q[-1] = q1
            return BlendTrajectory(float(T), c, q)
    return None


@dataclasses.dataclass(frozen=True, eq=False)
class Join:
    """A new path joined onto a moving command (module docstring).

    Attributes:
        blend: the quintic from the splice state to the timed remainder's start (duration 0 when
            the arm was at rest: the whole path is timed from rest).
        trajectory: the path's remainder from q_j, timed by TOPP-RA from `sd_start_rad_s`.
        polyline: the blend's samples, then the remainder: what the validator checks.
        at_rest: no moving join was within the limits: the blend ends at rest on the path.
    """

    blend: BlendTrajectory
    trajectory: object
    polyline: np.ndarray
    at_rest: bool
    sd_start_rad_s: float


def _cut(path: np.ndarray, length: float) -> np.ndarray:
    """The polyline from the point at arc length `length` on (that point first)."""
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    k = int(np.searchsorted(s, length, side="right")) - 1
    k = min(max(k, 0), len(seg) - 1)
    f = (length - s[k]) / seg[k] if seg[k] > 0 else 0.0
    q = path[k] + f * (path[k + 1] - path[k])
    rest = path[k + 1:]
    if len(rest) and np.linalg.norm(rest[0] - q) < 1e-6:
        rest = rest[1:]
    return np.vstack([q[None, :], rest]) if len(rest) else np.vstack([q, path[-1]])


def join_path(q_s, v_s, a_s, path, *, robot, max_duration_s: float = 2.0) -> Join | None:
    """Join `path` (from q_s) onto the command arriving at q_s with (v_s, a_s) (module
    docstring), or None when not even a stop is within the limits or the path is untimeable."""
    from suite.scoring.timing import time_parameterize

    q_s, v_s, a_s = (np.asarray(x, float) for x in (q_s, v_s, a_s))
    path = np.asarray(path, float)
    lim = dict(v_lim=robot.velocity_limits_rad_s, a_lim=robot.acceleration_limits_rad_s2, q_lo=robot.lower_rad,
               q_hi=robot.upper_rad)
    if np.max(np.abs(v_s)) < 1e-9 and np.max(np.abs(a_s)) < 1e-9:
        rest0 = BlendTrajectory(0.0, np.stack([q_s, *np.zeros((5, 7))]), q_s[None, :].copy())
        timed = time_parameterize(path, robot=robot)
        return Join(rest0, timed, path, False, 0.0) if timed.ok else None
    total = float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)))
    a_ok = LIMIT_SHARE * np.asarray(lim["a_lim"])
    speed = float(np.linalg.norm(v_s))
    u0 = path[1] - path[0] if len(path) > 1 else np.zeros(7)
    u0 = u0 / max(float(np.linalg.norm(u0)), 1e-12)
    # the fastest the path's first direction allows within the joint velocity limits
    cap = min(speed, float(np.min(np.asarray(lim["v_lim"]) / np.maximum(np.abs(u0), 1e-12))))
    for frac in (1.0, 0.5, 0.25) if total > 1e-6 else ():
        sd = frac * cap
        t_need = max(float(np.max(1.5 * np.abs(u0 * sd - v_s) / a_ok)), 0.02)
        for mult in (1.0, 3.0):
            length = min(mult * max(0.5 * (speed + sd) * t_need, 0.02), 0.5 * total)
            remainder = _cut(path, length)
            timed = time_parameterize(remainder, robot=robot, sd_start=sd)
            if not timed.ok:
                continue
            blend = _search(q_s, v_s, a_s, max_duration_s=max_duration_s, end=timed.sample(0.0), **lim)
            if blend is not None:
                return Join(blend, timed, np.vstack([blend.q[:-1], remainder]), False, sd)
    # no moving join within the limits: stop, then follow the path from the stop (back to q_s first)
    blend = stopping_blend(q_s, v_s, a_s, max_duration_s=max_duration_s + 1.0, **lim)
    if blend is None:
        return None
    q_b = blend.q[-1]
    poly = np.vstack([q_b, path]) if np.linalg.norm(q_b - q_s) > 1e-9 else path
    timed = time_parameterize(poly, robot=robot)
    return Join(blend, timed, np.vstack([blend.q[:-1], poly]), True, 0.0) if timed.ok else None
