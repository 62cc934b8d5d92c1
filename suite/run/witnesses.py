"""Witnesses with a margin: a path that proves a problem solvable while keeping off the obstacles.

A dataset's reference is the shortest certified path known (its length is `reference_length_rad`);
shortened paths graze the obstacles. Its witness is searched apart, in the problem's world with
every obstacle grown (`planners.worlds.padded_worlds`), then validated and certified in the true
world, and stored with its clearance.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np


#: A witness with at least this clearance from the scene is kept at once (m).
WITNESS_CLEARANCE_GOAL_M = 1e-3
#: No stored witness keeps less than this from the scene (m): a problem whose every known path
#: passes closer is "solvable" only to a checker's tolerance, and is left out of a dataset.
MIN_WITNESS_CLEARANCE_M = 1e-4
#: Paddings (m) of the second, finer search for a problem whose witness is under the minimum, with
#: a longer budget (FINE_BUDGET_S per padding): narrow passages that 3 and 1.5 mm close.
FINE_PADDINGS_M = (8e-4, 4e-4, 2e-4)
FINE_BUDGET_S = 10.0


def witness_search(problem, paddings: tuple[float, ...], tried: list, *, budget_s: float = 5.0) -> dict[str, Any] | None:
    """A witness path with a margin from the obstacles: planned by RRT-Connect (shortened) in the
    problem's world with every obstacle grown by each padding in turn (`planners.worlds.
    padded_worlds`), then validated and certified in the true world and its clearance measured;
    the first with WITNESS_CLEARANCE_GOAL_M or more is kept, else the one with the most clearance.
    A padding whose grown obstacles already touch the start or the goal is skipped; where the ends
    are nearer the scene than every padding, 0.8 of their clearance is tried last (no witness can
    keep farther off than its ends)."""
    from planners.registry import make_planner, planner_class
    from planners.worlds import collision_world, padded_worlds
    from suite.run.trial import make_config
    from suite.scoring.metrics import min_clearance_m
    from suite.scoring.validate import certify_path, validate_path

    world = collision_world(problem)
    ends_m = min(world.clearance(problem.q_start), world.clearance(problem.q_goal))
    if 0.0 < ends_m < min(paddings):  # the ends cap any witness's clearance: pad up to most of it
        paddings = (*paddings, round(0.8 * ends_m, 6))
    best = None
    for pad in paddings:
        with padded_worlds(pad):
            padded = collision_world(problem)
            if not (padded.is_free(problem.q_start) and padded.is_free(problem.q_goal)):
                tried.append({"planner": "rrt", "padding_m": pad, "status": "ends within the padding"})
                continue
            cfg = {"simplifier": "rope+full", "simplify_time_s": 0.5}  # searched as RRT-Connect, shortened
            t0 = time.perf_counter()
            result = make_planner("rrt", make_config(planner_class("rrt"), cfg)).plan(
                problem.with_(time_limit_s=budget_s, seed=200 + int(round(pad * 1e4))))
            elapsed = round(time.perf_counter() - t0, 3)
        if result.path is None:
            tried.append({"planner": "rrt", "padding_m": pad, "status": result.status.value, "time_s": elapsed})
            continue
        path = np.asarray(result.path, float).round(12)
        if validate_path(problem, path, world) is not None or certify_path(path, world)["verdict"] != "certified":
            tried.append({"planner": "rrt", "padding_m": pad, "status": "not certified", "time_s": elapsed})
            continue
        clearance = min_clearance_m(world, path)
        tried.append({"planner": "rrt", "padding_m": pad, "status": "success", "clearance_min_m": clearance,
                      "time_s": elapsed})
        if best is None or clearance > best["clearance_min_m"]:
            best = {"path": path.tolist(), "planner": "rrt", "config": cfg, "padding_m": pad,
                    "clearance_min_m": clearance}
        if clearance >= WITNESS_CLEARANCE_GOAL_M:
            break
    return best


def choose_witness(problem, reference: dict, margin: dict | None) -> dict[str, Any]:
    """The stored witness: the margin path if it keeps farther from the scene than the reference
    (the shortest path known), else the reference itself; with its clearance (m)."""
    from planners.worlds import collision_world
    from suite.scoring.metrics import min_clearance_m

    own = {"path": reference["path"], "planner": reference["planner"], "padding_m": 0.0,
           "clearance_min_m": min_clearance_m(collision_world(problem), np.asarray(reference["path"], float))}
    if margin is not None and margin["clearance_min_m"] > own["clearance_min_m"]:
        return {k: margin[k] for k in ("path", "planner", "padding_m", "clearance_min_m")}
    return own


def witness_with_margin(problem, witness: dict[str, Any]) -> tuple[dict[str, Any], list]:
    """`witness` if it keeps MIN_WITNESS_CLEARANCE_M from the scene, else the better of it and a
    finer search (FINE_PADDINGS_M, FINE_BUDGET_S); with the finer search's attempts. The result
    may still be under the minimum (the caller leaves such a problem out)."""
    if witness["clearance_min_m"] >= MIN_WITNESS_CLEARANCE_M:
        return witness, []
    tried: list = []
    fine = witness_search(problem, FINE_PADDINGS_M, tried, budget_s=FINE_BUDGET_S)
    if fine is not None and fine["clearance_min_m"] > witness["clearance_min_m"]:
        return {k: fine[k] for k in ("path", "planner", "padding_m", "clearance_min_m")}, tried
    return witness, tried
