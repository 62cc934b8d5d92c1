"""`python -m suite bench single-tree`: is `rrtstar`'s failure on the `wall` transits RRT*'s or its
single tree's?

An ablation, not a suite planner: OMPL's plain RRT (one goal-biased tree grown from the start, no
rewiring, stopping at its first solution) runs on the same OMPL adapter, python-fcl checks and
problems as `rrtstar` with its tuned settings, at the same budget, at each of a few ranges. A path
counts only if the suite's independent validator accepts it (`suite.scoring.validate.validate_path`:
ends, joint limits, python-fcl at 0.01 rad), as in every trial. If the plain tree
fails on the same share of problems, RRT*'s rewiring and settings are not what fails.
"""

from __future__ import annotations

import argparse
import json
import time

from suite.cli.args import positive_float, positive_int

DEFAULT_DATASET = "recycle-v2:test:family=wall,kind=transit"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--dataset", default=DEFAULT_DATASET, help=f"NAME[:TIER[:FILTERS]] (default {DEFAULT_DATASET})")
    p.add_argument("--budget", type=positive_float, default=1.0, help="seconds per problem (default 1)")
    p.add_argument("--ranges", default="none,1.0,0.5,0.25",
                   help="plain RRT's ranges, comma-separated rad, 'none' for OMPL's default (default none,1.0,0.5,0.25)")
    p.add_argument("--limit", type=positive_int, default=None, help="only the first K problems")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")


def _plain_rrt_class():
    from ompl import geometric as og

    from planners.ompl_rrt import RRTstarConfig
    from planners.ompl_solve import OmplPlanner

    class PlainRRT(OmplPlanner):
        """OMPL's RRT: one goal-biased tree from the start (RRT*'s settings, without its rewiring)."""

        name = "rrt-single-tree"
        Config = RRTstarConfig
        solver = "RRT"
        optimizing = False

        def _make(self, si):
            p = og.RRT(si)
            if self.config.range_rad is not None:
                p.setRange(self.config.range_rad)
            p.setGoalBias(self.config.goal_bias)
            return p

    return PlainRRT


def parse_ranges(text: str) -> list[float | None]:
    from scenes.errors import SuiteError

    out: list[float | None] = []
    for item in text.split(","):
        item = item.strip()
        try:
            value = None if item == "none" else float(item)
        except ValueError:
            raise SuiteError(f"--ranges: {item!r} is not a number or 'none'") from None
        if value is not None and not value > 0:
            raise SuiteError(f"--ranges: {item!r} must be > 0")
        out.append(value)
    return out


def solved(planner, problems) -> tuple[int, float]:
    """(problems whose path the suite's validator accepts, wall seconds)."""
    from planners.base import PlanStatus
    from planners.worlds import collision_world
    from suite.scoring.validate import validate_path

    t0 = time.perf_counter()
    ok = 0
    for p in problems:
        r = planner.plan(p)
        ok += r.status is PlanStatus.SUCCESS and validate_path(p, r.path, collision_world(p)) is None
    return ok, time.perf_counter() - t0


def measure(text: str, *, budget_s: float, ranges: list[float | None], limit: int | None = None) -> dict:
    import dataclasses

    from planners.ompl_rrt import RRTstarPlanner
    from suite.problems.dataset import load_dataset
    from suite.run.trial import make_config

    ds = load_dataset(text, time_limit_s=budget_s)
    problems = [p for p in ds.problems if p.pre_status is None and p.q_goal is not None][:limit]
    tuned = make_config(RRTstarPlanner, None)
    rows = []
    ok, wall = solved(RRTstarPlanner(tuned), problems)
    rows.append({"planner": "rrtstar (tuned)", "range_rad": tuned.range_rad, "goal_bias": tuned.goal_bias,
                 "solved": ok, "wall_s": round(wall, 1)})
    plain = _plain_rrt_class()
    for rng in ranges:
        cfg = dataclasses.replace(tuned, range_rad=rng)
        ok, wall = solved(plain(cfg), problems)
        rows.append({"planner": "plain RRT", "range_rad": rng, "goal_bias": cfg.goal_bias, "solved": ok,
                     "wall_s": round(wall, 1)})
    return {"dataset": text, "problems": len(problems), "budget_s": budget_s, "rows": rows}


def run(args: argparse.Namespace) -> int:
    out = measure(args.dataset, budget_s=args.budget, ranges=parse_ranges(args.ranges), limit=args.limit)
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    from tabulate import tabulate

    n = out["problems"]
    print(f"{n} problems of {out['dataset']}, {out['budget_s']:g} s each; solved = accepted by the validator")
    print(tabulate([[r["planner"], "OMPL default" if r["range_rad"] is None else r["range_rad"], r["goal_bias"],
                     f"{r['solved']}/{n} ({100 * r['solved'] / max(n, 1):.0f}%)", r["wall_s"]] for r in out["rows"]],
                   headers=["planner", "range (rad)", "goal bias", "solved", "wall s"], tablefmt="github"))
    return 0
