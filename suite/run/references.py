"""A dataset problem's best known path (its reference) and witness, planned in worker processes.

`reference_job` tries AORRTC, RRT-Connect runs and the optimizers as tuned, keeps the shortest path
the validator accepts and the exact check certifies, and searches a witness with margin
(`suite.run.witnesses`). Used by `suite dataset build` and `recertify`.
"""

from __future__ import annotations

import sys
import time
from typing import Any

import numpy as np

#: Budget (s) of each optimizing planner tried for a problem's best known path.
OPTIMIZER_BUDGET_S = 5.0


def straight_certified(problem) -> bool:
    """True if the exact check certifies the problem's straight joint segment."""
    from planners.worlds import collision_world
    from suite.scoring.validate import certify_path

    path = np.array([problem.q_start, problem.q_goal], float)
    return certify_path(path, collision_world(problem))["verdict"] == "certified"


def reference_job(arg: tuple) -> dict[str, Any]:
    """The shortest path found for one non-trivial problem that the validator accepts and the exact
    check certifies (`suite.scoring.validate.certify_path`); runs in a worker process."""
    from planners.registry import make_planner, planner_class
    from planners.worlds import collision_world
    from suite.run.trial import make_config
    from suite.scoring.validate import certify_path, validate_path

    problem, budget_s, rrt_runs = arg[:3]
    paddings = arg[3] if len(arg) > 3 else ()
    optimizers = arg[4] if len(arg) > 4 else ()
    world = collision_world(problem)
    attempts = [("aorrtc", {"simplifier": "rope+full", "simplify_time_s": 1.0}, budget_s, 1)]
    attempts += [("rrt", {"simplifier": "rope+full", "simplify_time_s": 0.5}, 5.0, 100 + k) for k in range(rrt_runs)]
    # optimizers as tuned, seeded from the problem alone (never from another attempt's path)
    attempts += [(name, {}, OPTIMIZER_BUDGET_S, 0) for name in optimizers]
    best, tried = None, []
    for name, cfg, budget, seed in attempts:
        t0 = time.perf_counter()
        planner = make_planner(name, make_config(planner_class(name), cfg))
        result = planner.plan(problem.with_(time_limit_s=budget, seed=seed))
        elapsed = time.perf_counter() - t0
        if result.path is None or validate_path(problem, result.path, world) is not None:
            tried.append({"planner": name, "status": result.status.value, "time_s": round(elapsed, 3)})
            continue
        path = np.asarray(result.path, float).round(12)  # certified as it is stored
        length = float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)))
        verdict = certify_path(path, world)["verdict"]
        tried.append({"planner": name, "status": "success", "length_rad": round(length, 6), "time_s": round(elapsed, 3),
                      "certification": verdict})
        if verdict != "certified":  # a witness must be free between the validator's samples too
            continue
        if best is None or length < best["length_rad"]:
            best = {"path": path.round(12).tolist(), "length_rad": length, "planner": name,
                    "config": cfg or {"tuned": True},
                    "time_s": round(elapsed, 3)}
    from suite.run.witnesses import witness_search

    witness = witness_search(problem, paddings, tried) if paddings else None
    return {"reference": best, "witness": witness, "attempts": tried}


def plan_references(todo: list[tuple[str, Any]], *, reference_time_s: float, rrt_runs: int,
                    paddings: tuple[float, ...], jobs: int, progress_bar: bool,
                    optimizers: tuple[str, ...] = ()) -> dict[str, dict]:
    """problem_id -> `reference_job`'s result for each (problem_id, problem), in worker processes;
    a job that fails gives no reference."""
    from tqdm import tqdm

    from suite.run.executors import Job, LocalExecutor
    from suite.run.runner import worker_init

    budget = reference_time_s + 5.0 * rrt_runs + OPTIMIZER_BUDGET_S * len(optimizers) + 10.0
    work = [Job(pid, reference_job, (p, reference_time_s, rrt_runs, paddings, optimizers),
                 3 * budget + 60 + 20 * len(paddings), group=p.scene.key()) for pid, p in todo]
    out: dict[str, dict] = {}
    if not work:
        return out
    ex = LocalExecutor(jobs=min(jobs, len(work)), init=worker_init)
    bar = tqdm(total=len(work), desc="references", unit="problem", disable=not progress_bar, file=sys.stderr)
    for outcome in ex.run(work):
        out[outcome.job.key] = outcome.result if outcome.failure is None else {"reference": None, "attempts": [
            {"failure": outcome.failure, "message": outcome.message}]}
        bar.update(1)
    bar.close()
    return out


def clearance_summary(values: list[float]) -> dict[str, Any]:
    """Quantiles of the witnesses' clearance (m) and how many reach 1 mm or fall below 0.1 mm."""
    if not values:
        return {}
    v = np.asarray(values, float)
    return {"n": len(v), **{k: round(float(np.quantile(v, q)), 6) for k, q in
                            (("min", 0), ("p05", 0.05), ("q1", 0.25), ("median", 0.5), ("max", 1))},
            "at_least_1mm": int(np.sum(v >= 1e-3)), "below_0.1mm": int(np.sum(v < 1e-4))}
