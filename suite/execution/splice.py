"""Splicing a new plan into a moving arm's command without a jump: the stopping blend.

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


def _coefficients(q0, v0, a0, q1, T):
    """Quintic coefficients (6, 7) from (q0, v0, a0) at 0 to (q1, 0, 0) at T."""
    d = q1 - q0
    c3 = (20 * d - 12 * v0 * T - 3 * a0 * T**2) / (2 * T**3)
    c4 = (-30 * d + 16 * v0 * T + 3 * a0 * T**2) / (2 * T**4)
    c5 = (12 * d - 6 * v0 * T - a0 * T**2) / (2 * T**5)
    return np.stack([q0, v0, a0 / 2, c3, c4, c5])


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
        c = self.coefficients
        q = c[0] + t * (c[1] + t * (c[2] + t * (c[3] + t * (c[4] + t * c[5]))))
        v = c[1] + t * (2 * c[2] + t * (3 * c[3] + t * (4 * c[4] + t * 5 * c[5])))
        a = 2 * c[2] + t * (6 * c[3] + t * (12 * c[4] + t * 20 * c[5]))
        return (q[0], v[0], a[0]) if scalar else (q, v, a)


def stopping_blend(q0, v0, a0, *, v_lim, a_lim, q_lo, q_hi, max_duration_s: float = 3.0) -> BlendTrajectory | None:
    """The shortest quintic stop from (q0, v0, a0) within the limits (see the module docstring), or
    None if none up to `max_duration_s` stays within them (then the caller keeps its plan)."""
    q0, v0, a0 = (np.asarray(x, float) for x in (q0, v0, a0))
    if np.max(np.abs(v0)) < 1e-9 and np.max(np.abs(a0)) < 1e-9:
        return BlendTrajectory(0.0, np.stack([q0, *np.zeros((5, 7))]), q0[None, :].copy())
    found = _search(q0, v0, a0, v_lim, a_lim, q_lo, q_hi, max_duration_s)
    if found is None and np.max(np.abs(a0)) > 0:
        found = _search(q0, v0, np.zeros_like(a0), v_lim, a_lim, q_lo, q_hi, max_duration_s)
        found = None if found is None else dataclasses.replace(found, matches_acceleration=False)
    return found


def _search(q0, v0, a0, v_lim, a_lim, q_lo, q_hi, max_duration_s) -> BlendTrajectory | None:
    """The shortest quintic stop on the duration grid within the limits, or None."""
    v_ok, a_ok = VELOCITY_SHARE * np.asarray(v_lim), LIMIT_SHARE * np.asarray(a_lim)
    t_min = max(float(np.max(1.5 * np.abs(v0) / a_ok)), 0.02)
    u = np.linspace(0.0, 1.0, SAMPLES)[:, None]
    for T in t_min * 1.1 ** np.arange(60):
        if T > max_duration_s:
            break
        q1 = q0 + v0 * T / 2 + a0 * T**2 / 12
        c = _coefficients(q0, v0, a0, q1, T)
        t = u * T
        q = c[0] + t * (c[1] + t * (c[2] + t * (c[3] + t * (c[4] + t * c[5]))))
        v = c[1] + t * (2 * c[2] + t * (3 * c[3] + t * (4 * c[4] + t * 5 * c[5])))
        a = 2 * c[2] + t * (6 * c[3] + t * (12 * c[4] + t * 20 * c[5]))
        # the start's own acceleration may sit at the limit (TOPP-RA's); the blend adds none beyond it
        a_bound = np.maximum(a_ok, np.abs(a0))
        if (np.all(np.abs(v) <= np.maximum(v_ok, np.abs(v0))) and np.all(np.abs(a) <= a_bound)
                and np.all(q >= q_lo) and np.all(q <= q_hi)):
            q[-1] = q1
            return BlendTrajectory(float(T), c, q)
    return None
