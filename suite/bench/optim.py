"""Figures of the optimization-based planners (`ik`, `trajopt`) on generated scenes.

`ik`: every can's whole pick-and-place cycle (its five problems); a can counts when all five are
solved and every path passes the validator (python-fcl at 0.01 rad); the cycle time is the sum
of the five `plan` calls (building the planner's IK programs included; the scene's own Drake and
python-fcl worlds are built beforehand, as a worker's cache would hold them).
`trajopt`: every transit problem; valid success = SUCCESS and the validator accepts the path.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from planners.base import PlanningProblem, PlanStatus

log = logging.getLogger(__name__)

VALIDATE_RESOLUTION_RAD = 0.01
#: A goal this far (largest joint change, rad) from its start posture is on another IK branch.
BRANCH_JUMP_RAD = 2.0


def cycles(*, scenes: int, variant: str, time_limit_s: float, first_seed: int = 0) -> list[list[PlanningProblem]]:
    """The five problems of every can of `scenes` generated scenes (ground-truth grasps)."""
    from suite.problems.cycle import benchmark_cycles

    return benchmark_cycles(scenes=scenes, variant=variant, time_limit_s=time_limit_s, first_seed=first_seed)


def _valid(problem: PlanningProblem, path) -> bool:
    from planners.worlds import collision_world

    return path is not None and collision_world(problem).path_free(path, resolution_rad=VALIDATE_RESOLUTION_RAD) < 0


def _warm(problem: PlanningProblem) -> None:
    from planners.worlds import collision_world, drake_plan_scene

    collision_world(problem)
    drake_plan_scene(problem)


def bench_ik(all_cycles: list[list[PlanningProblem]]) -> dict:
    """Whole cycles with the `ik` planner."""
    from planners.registry import make_planner

    planner = make_planner("ik")
    cycle_s, ok, posable, jumps, fails = [], 0, 0, 0, {}
    for cycle in all_cycles:
        if any(p.pre_status is not None for p in cycle):
            continue
        posable += 1
        jump = any(float(np.max(np.abs(p.q_goal - p.q_start))) > BRANCH_JUMP_RAD
                   for p in cycle if p.kind in ("approach", "descend", "lift"))
        jumps += jump
        total, good = 0.0, True
        for p in cycle:
            _warm(p)
            t0 = time.perf_counter()
            r = planner.plan(p)
            total += time.perf_counter() - t0
            valid = r.status is PlanStatus.SUCCESS and _valid(p, r.path)
            if not valid:
                good = False
                key = f"{p.kind}:{'invalid_path' if r.status is PlanStatus.SUCCESS else r.status.value}"
                fails[key] = fails.get(key, 0) + 1
                log.info("ik %s seed %d: %s %s", p.name, p.scene.seed, r.status.value, r.stats.get("reason"))
        cycle_s.append(total)
        ok += good
    return {
        "cans": len(all_cycles), "posable_cans": posable, "cans_solved": ok,
        "solved_pct": 100.0 * ok / max(posable, 1),
        "cans_with_goal_branch_jump": jumps,
        "median_cycle_s": float(np.median(cycle_s)) if cycle_s else None,
        "p90_cycle_s": float(np.percentile(cycle_s, 90)) if cycle_s else None,
        "failures": fails,
    }


def bench_trajopt(problems: list[PlanningProblem]) -> dict:
    """Every transit problem with the `trajopt` planner."""
    from planners.registry import make_planner

    planner = make_planner("trajopt")
    times, valid, statuses, resolves, unconverged = [], 0, {}, 0, 0
    for p in problems:
        _warm(p)
        t0 = time.perf_counter()
        r = planner.plan(p)
        times.append(time.perf_counter() - t0)
        good = r.status is PlanStatus.SUCCESS and _valid(p, r.path)
        valid += good
        key = r.status.value if r.status is not PlanStatus.SUCCESS or good else "invalid_path"
        statuses[key] = statuses.get(key, 0) + 1
        resolves += r.stats.get("resolves", 0) > 0
        unconverged += good and not r.stats.get("solver_converged", True)
    return {
        "transits": len(problems), "valid_success": valid,
        "valid_pct": 100.0 * valid / max(len(problems), 1),
        "median_s": float(np.median(times)) if times else None,
        "p90_s": float(np.percentile(times, 90)) if times else None,
        "with_resolves": resolves, "accepted_unconverged": unconverged,
        "statuses": statuses,
    }


def run_bench(*, scenes: int, variant: str, time_limit_s: float = 5.0, first_seed: int = 0) -> dict:
    """Print and return the figures of `ik` (whole cycles) and `trajopt` (transits) on one variant."""
    all_cycles = cycles(scenes=scenes, variant=variant, time_limit_s=time_limit_s, first_seed=first_seed)
    ik = bench_ik(all_cycles)
    print(f"[{variant}] ik: {ik['cans_solved']}/{ik['posable_cans']} posable cans solved "
          f"({ik['solved_pct']:.1f}%; {ik['cans'] - ik['posable_cans']} cans not posable, "
          f"{ik['cans_with_goal_branch_jump']} with a goal on another IK branch), "
          f"cycle median {ik['median_cycle_s']:.3f} s, p90 {ik['p90_cycle_s']:.3f} s; failures {ik['failures']}")
    transits = [c[3] for c in all_cycles if c[3].pre_status is None]
    tj = bench_trajopt(transits)
    print(f"[{variant}] trajopt: {tj['valid_success']}/{tj['transits']} transits valid "
          f"({tj['valid_pct']:.1f}%), median {tj['median_s']:.3f} s, p90 {tj['p90_s']:.3f} s, "
          f"{tj['with_resolves']} needed re-solves, {tj['accepted_unconverged']} accepted unconverged; "
          f"statuses {tj['statuses']}")
    return {"variant": variant, "scenes": scenes, "ik": ik, "trajopt": tj}
