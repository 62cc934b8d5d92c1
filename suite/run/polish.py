"""A local optimizer of joint path length that keeps every segment certified (offline best known paths).

`polish` shortens a certified piecewise-straight joint path. Each round it
1. splits every segment longer than a piece length at its midpoint (the geometry is unchanged, and
   a corner can now slide along the obstacle it wraps around),
2. moves every interior waypoint a fraction `step` of the way towards the midpoint of its two
   neighbours. |x - a| + |x - b| is convex in x and least on the segment a-b, of which the
   midpoint is a point; so no move lengthens the path. A move is kept only if the exact segment
   check (`scenes.collision.certify`) certifies both of the waypoint's segments,
3. removes every interior waypoint whose neighbours are joined by a certified segment (a shortcut
   never lengthens a path: the triangle inequality).
A round that shortens the path by less than `tol_rad` halves `step`; the search ends when `step`
falls below `min_step` or the time is spent. Waypoints stay inside the joint limits: a midpoint
and a move towards it are convex combinations of states inside the limits' box.

Every accepted path is certified segment by segment, so the result is certified whenever the input
was. The optimizer never calls a benchmarked planner: it is used after the offline search of
`suite.run.best_known`, started from several of its paths.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from planners.base import resample_by_length  # noqa: F401 (moved to planners.base; still importable here)
from scenes.collision.certify import CERTIFIED

#: The exact check's state budget for one move's two segments; an unproved move is refused.
MOVE_MAX_STATES = 20_000


def path_length(Q: np.ndarray) -> float:
    """The joint-space length of a polyline (N, 7): the sum of its segments' L2 norms (rad)."""
    return float(np.sum(np.linalg.norm(np.diff(Q, axis=0), axis=1)))


@dataclasses.dataclass(frozen=True)
class Polished:
    """What `polish` returns: the path (N, 7), its length before and after (rad), rounds run,
    moves tried and kept, and seconds."""

    path: np.ndarray
    length_before_rad: float
    length_rad: float
    rounds: int
    moves_tried: int
    moves_kept: int
    time_s: float


def polish(path: np.ndarray, certifier, *, time_s: float = 5.0, piece_rad: float = 0.3, step: float = 0.5,
           min_step: float = 1 / 64, tol_rad: float = 1e-4) -> Polished:
    """Shorten the certified path (N, 7) on `certifier`'s world (see the module docstring)."""
    t0 = time.perf_counter()
    Q = np.array(path, float)
    before = path_length(Q)
    tried = kept = rounds = 0

    def free(*states: np.ndarray) -> bool:
        nonlocal tried
        tried += 1
        return certifier.certify(np.stack(states), max_states=MOVE_MAX_STATES).verdict == CERTIFIED

    while step >= min_step and time.perf_counter() - t0 < time_s:
        rounds += 1
        start_len = path_length(Q)
        # 1. pieces short enough for corners to slide
        rows = [Q[0]]
        for a, b in zip(Q[:-1], Q[1:]):
            n = max(1, int(np.ceil(np.linalg.norm(b - a) / piece_rad)))
            rows.extend(a + (b - a) * (k / n) for k in range(1, n))
            rows.append(b)  # the waypoint itself, to the bit (a + (b - a) need not be b)
        Q = np.array(rows)
        # 2. every interior waypoint towards its neighbours' midpoint
        for i in range(1, len(Q) - 1):
            if time.perf_counter() - t0 >= time_s:
                break
            target = Q[i] + step * (0.5 * (Q[i - 1] + Q[i + 1]) - Q[i])
            if np.max(np.abs(target - Q[i])) > 1e-9 and free(Q[i - 1], target, Q[i + 1]):
                Q[i] = target
                kept += 1
        # 3. shortcuts over single waypoints
        i = 1
        while i < len(Q) - 1 and time.perf_counter() - t0 < time_s:
            if free(Q[i - 1], Q[i + 1]):
                Q = np.delete(Q, i, axis=0)
                kept += 1
            else:
                i += 1
        if start_len - path_length(Q) < tol_rad:
            step *= 0.5
    return Polished(Q, before, path_length(Q), rounds, tried, kept, time.perf_counter() - t0)


def seeded_trajopt(problem, path: np.ndarray, *, time_s: float, control_points: int | None = None):
    """Drake's KinematicTrajectoryOptimization (the `trajopt` planner's program, at its tuned
    settings, or with `control_points`) started from `path` instead of its own guess: control
    points spread evenly along the path's length. Its returned `PlanResult` (the path sampled from the
    spline, checked densely by the planner)."""
    from planners.registry import planner_class
    from planners.trajopt import TrajoptPlanner
    from suite.run.trial import make_config

    seed = np.asarray(path, float)

    class SeededTrajopt(TrajoptPlanner):
        def _initial_control_points(self, problem, ds, plant_context, counter):
            return resample_by_length(seed, self.config.num_control_points), "path"

    cfg = make_config(planner_class("trajopt"), {} if control_points is None else
                      {"num_control_points": control_points})
    return SeededTrajopt(cfg).plan(problem.with_(time_limit_s=time_s))
