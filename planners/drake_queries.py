"""Counting and timing the distance queries that SNOPT makes through Drake's
MinimumDistanceLowerBoundConstraint (the `ik` and `trajopt` planners).

**The count is exact.** SNOPT evaluates every cost and constraint of a program together. A
visualization callback on the program runs once with each such evaluation (checked: 7 calls for 7
evaluations of a cost and a constraint). So the callback's calls, times the distance-constraint
bindings in the program, are the distance queries. Each query covers every robot-scene and
robot-robot pair within the influence distance, with gradients. The callback costs one Python
call per evaluation: about a microsecond, against about 0.1 ms for an evaluation.

**The time is estimated by replay.** The constraint runs in C++ inside the solver, so its calls
cannot be clocked from outside. Wrapping each one in a clocked Python function measures the
wrapper instead: the gradient crosses into Python as AutoDiff arrays. On `ik` that made
planning 1.6x slower and a query look 1.8 ms long instead of 0.1-0.3 ms (measured on a shared
machine; see docs/timing.md).

Instead, the callback keeps a uniform sample of the iterates the solver evaluated
(REPLAY_QUERIES of them, reservoir-sampled and seeded). After the solve, the constraint is
evaluated again, with gradients as wide as the solver's, at the configurations of those
iterates. The mean time of one replayed evaluation, times the count, gives the seconds.

The replay costs REPLAY_QUERIES + 1 evaluations per plan, about 1.5 ms, counted inside the
planning time. `python -m suite bench attribution` compares the estimate against a replay of
every query of a plan: 1.15x for `ik` (its sample replays colder than the full run) and 1.02x for
`trajopt`, medians over 8 `wall` problems.
"""

from __future__ import annotations

import random
import time

import numpy as np

#: Sampled queries replayed per plan (after one warm-up evaluation).
REPLAY_QUERIES = 16


class EvaluationCounter:
    """A visualization callback that counts its program's evaluations and keeps a uniform,
    seeded sample of the decision variables they were made at (REPLAY_QUERIES of them, read at
    each call, so that `bench attribution` can keep them all)."""

    def __init__(self) -> None:
        self.calls = 0
        self.sample: list[np.ndarray] = []
        self._rng = random.Random(0)

    def __call__(self, x) -> None:
        self.calls += 1
        if len(self.sample) < REPLAY_QUERIES:
            self.sample.append(np.array(x, float))
        else:
            k = self._rng.randrange(self.calls)
            if k < REPLAY_QUERIES:
                self.sample[k] = np.array(x, float)

    def restart(self) -> None:
        """Forget the sample (the next plan on the same program); the count goes on."""
        self.sample = []
        self._rng = random.Random(0)


def replay_seconds(constraint, configurations, num_derivatives: int | None = None) -> tuple[float, int] | None:
    """(total seconds, evaluations) of `constraint` evaluated with gradients `num_derivatives`
    wide (default: the configuration's size) at each finite configuration (row); None without one."""
    from pydrake.autodiffutils import InitializeAutoDiff

    qs = np.asarray(configurations, float)
    if qs.ndim != 2:
        return None
    qs = qs[np.all(np.isfinite(qs), axis=1)]
    if len(qs) == 0:
        return None
    nd = num_derivatives or qs.shape[1]
    inputs = [InitializeAutoDiff(q, num_derivatives=nd) for q in qs]
    constraint.Eval(inputs[0])  # a first call after building pays one-off allocations
    total = 0.0
    for x in inputs:
        t = time.perf_counter()
        constraint.Eval(x)
        total += time.perf_counter() - t
    return total, len(inputs)


def query_stats(queries: int, constraint, configurations, num_derivatives: int | None = None) -> dict:
    """The `stats` entries of a plan's Drake distance queries: the exact count, and the seconds
    estimated from a replay at `configurations` (the sampled iterates)."""
    out = {"drake_distance_queries": int(queries), "drake_distance_query_s": 0.0}
    replay = replay_seconds(constraint, configurations, num_derivatives) if queries else None
    if replay is not None:
        out["drake_distance_query_s"] = queries * replay[0] / replay[1]
    return out
