"""Figures of the OMPL planner family on the transit problems (over the wall in the `wall` variant).

`rrt` plans every transit problem of every scene; the optimizing planners (`rrtstar`, `bitstar`,
`aorrtc`, `prm`) run to their budget, so they get one transit problem per scene. Each path is
re-validated here at 0.01 rad, as the orchestrator does.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from planners.base import PlanningProblem, PlanStatus
from scenes.errors import SuiteError

log = logging.getLogger(__name__)

OMPL_PLANNERS = ("rrt", "rrtstar", "bitstar", "aorrtc", "prm")
VALIDATE_RESOLUTION_RAD = 0.01


def transit_problems(*, scenes: int, variant: str, time_limit_s: float, first_seed: int = 0) -> list[PlanningProblem]:
    """The posable transit problems of `scenes` generated scenes (ground-truth grasps)."""
    from suite.problems.cycle import benchmark_cycles

    cycles = benchmark_cycles(scenes=scenes, variant=variant, time_limit_s=time_limit_s, first_seed=first_seed)
    return [p for cycle in cycles for p in cycle if p.kind == "transit" and p.pre_status is None]


def _median(values) -> float | None:
    values = [v for v in values if v is not None]
    return float(np.median(values)) if values else None


def bench_planner(name: str, problems: list[PlanningProblem], *, config=None) -> dict:
    """Plan every problem with one planner; per-trial rows and a summary."""
    from planners.registry import make_planner
    from planners.worlds import collision_world

    planner = make_planner(name, config)
    rows = []
    for p in problems:
        collision_world(p)  # built once per world, outside the timed call
        t0 = time.perf_counter()
        r = planner.plan(p)
        wall_s = time.perf_counter() - t0
        s = r.stats
        valid = None
        if r.path is not None:
            valid = collision_world(p).path_free(r.path, resolution_rad=VALIDATE_RESOLUTION_RAD) < 0
        solve_s, simp_s = s.get("solve_time_s"), s.get("simplify_time_s")
        rows.append({
            "problem": f"seed{p.scene.seed}/{p.name}",
            "status": r.status.value,
            "valid_0.01": valid,
            "solve_s": solve_s,
            "simplify_s": simp_s,
            "solve_simplify_s": None if solve_s is None or simp_s is None else solve_s + simp_s,
            "wall_s": wall_s,
            "length_before_rad": s.get("length_before_rad"),
            "length_after_rad": s.get("length_after_rad"),
            "waypoints": s.get("waypoints"),
            "collision_checks": s.get("collision_checks"),
            "replanned_fine": s.get("replanned_fine"),
        })
    ok = [r for r in rows if r["status"] == PlanStatus.SUCCESS.value]
    summary = {
        "planner": name,
        "trials": len(rows),
        "success_rate": len(ok) / len(rows) if rows else None,
        "valid_rate": sum(bool(r["valid_0.01"]) for r in ok) / len(ok) if ok else None,
        "median_solve_s": _median(r["solve_s"] for r in ok),
        "median_simplify_s": _median(r["simplify_s"] for r in ok),
        "median_solve_simplify_s": _median(r["solve_simplify_s"] for r in ok),
        "median_wall_s": _median(r["wall_s"] for r in rows),
        "median_length_before_rad": _median(r["length_before_rad"] for r in ok),
        "median_length_after_rad": _median(r["length_after_rad"] for r in ok),
        "median_collision_checks": _median(r["collision_checks"] for r in ok),
        "replanned_fine": sum(bool(r["replanned_fine"]) for r in rows),
        "statuses": {st: sum(r["status"] == st for r in rows) for st in sorted({r["status"] for r in rows})},
    }
    return {"summary": summary, "rows": rows}


def run_bench(
    *,
    scenes: int,
    variant: str,
    planners: tuple[str, ...] = OMPL_PLANNERS,
    rrt_time_limit_s: float = 5.0,
    optimizing_budget_s: float = 1.0,
    first_seed: int = 0,
) -> dict:
    """Benchmark the OMPL planners on the transit problems of `scenes` scenes and print a table.

    Args:
        scenes: how many scenes (each gives one transit problem per can).
        variant: scene variant ("wall" or "open").
        planners: which of the OMPL planners to run.
        rrt_time_limit_s: `rrt`'s budget per problem (it stops at its first solution).
        optimizing_budget_s: the budget of each optimizing planner per problem (it runs it out).

    Returns:
        {"variant", "scenes", "planners": {name: {"summary", "rows"}}}.
    """
    from tabulate import tabulate

    for name in planners:
        if name not in OMPL_PLANNERS:
            raise SuiteError(f"bench_ompl: unknown planner {name!r}; allowed: {', '.join(OMPL_PLANNERS)}")
    t0 = time.perf_counter()
    problems = transit_problems(scenes=scenes, variant=variant, time_limit_s=rrt_time_limit_s, first_seed=first_seed)
    log.info("%d transit problems from %d scenes in %.1f s", len(problems), scenes, time.perf_counter() - t0)
    one_per_scene = list({p.scene.seed: p for p in reversed(problems)}.values())[::-1]
    out = {"variant": variant, "scenes": scenes, "planners": {}}
    for name in planners:
        if name == "rrt":
            subset = problems
        else:
            subset = [p.with_(time_limit_s=optimizing_budget_s) for p in one_per_scene]
        out["planners"][name] = bench_planner(name, subset)

    def ms(v):
        return None if v is None else round(1e3 * v, 1)

    table = []
    for name, res in out["planners"].items():
        s = res["summary"]
        table.append([
            name, s["trials"], f"{100 * s['success_rate']:.0f}%",
            None if s["valid_rate"] is None else f"{100 * s['valid_rate']:.0f}%",
            ms(s["median_solve_s"]), ms(s["median_simplify_s"]), ms(s["median_solve_simplify_s"]),
            ms(s["median_wall_s"]),
            None if s["median_length_before_rad"] is None else round(s["median_length_before_rad"], 2),
            None if s["median_length_after_rad"] is None else round(s["median_length_after_rad"], 2),
            s["median_collision_checks"],
        ])
    print(f"OMPL planners on the transit problems of {scenes} {variant!r} scenes "
          f"(rrt: all {len(problems)} problems; others: {len(one_per_scene)} problems, "
          f"{optimizing_budget_s:g} s budget)")
    print(tabulate(table, headers=[
        "planner", "trials", "success", "valid@0.01", "solve ms", "simplify ms", "solve+simp ms", "plan() ms",
        "length before", "length after", "checks"], tablefmt="github"))
    return out
