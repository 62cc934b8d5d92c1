"""`python -m suite bench budget-flip`: would a planner's tuned choice change within ±20% of the budget?

It reads a finished `suite tune` run (every candidate's trials at the tuning budget B) and asks the
same rule (`suite.report.tuning.choose`, families weighing equally) at other budgets:

- below B, exactly and without planning: a success that took longer than the smaller budget is a
  timeout there. The planners whose choice this check serves stop at their first solution (`rrt`,
  `ik`) or converge before their budget (`trajopt`), so a trial that ended sooner would have ended
  the same way;
- above B, by planning again only the trials that timed out at B, at the larger budget (into
  `CANDIDATE/budget-Xs/` beside the candidate's trials); every other trial keeps its outcome.

So each budget differs from B in the budget alone, not in a fresh draw of every trial's seed.
It prints the choice at each budget beside the tuned one and each candidate's figures there.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from suite.cli.args import positive_float, positive_int
from suite.run.records import TrialRecord

TIMEOUTS = ("timeout", "killed_timeout")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--planner", required=True, help="a planner with a tuning search (planners/tuned.py)")
    p.add_argument("--tune-dir", default=None, help="the tuning run (default results/tune/PLANNER)")
    p.add_argument("--dataset", default=None, help="the dataset it was tuned on (default: the tuned file's)")
    p.add_argument("--per-family", type=positive_int, default=None,
                   help="as given to tune (default: the tuned file's)")
    p.add_argument("--budget", type=positive_float, default=None, help="the tuning budget, s (default: the tuned file's)")
    p.add_argument("--factors", default="0.8,1.2", help="budgets to ask at, as factors of the tuning budget (default 0.8,1.2)")
    p.add_argument("--jobs", type=positive_int, default=2, help="worker processes for the re-planned trials (default 2)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")


def at_smaller_budget(records: list[TrialRecord], budget_s: float) -> list[TrialRecord]:
    """The records as they would read at a smaller budget: a success later than it is a timeout."""
    out = []
    for r in records:
        r = r.with_(time_limit_s=budget_s)
        if r.succeeded and float(r.planning_time_s or 0.0) > budget_s:
            r.status = "timeout"
        out.append(r)
    return out


def _factors(text: str) -> list[float]:
    from scenes.errors import SuiteError

    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        values = []
    if not values or any(not v > 0 for v in values):
        raise SuiteError(f"--factors must be positive numbers separated by commas, got {text!r}")
    return values


def run(args: argparse.Namespace) -> int:
    from planners.registry import planner_class
    from planners.tuned import objective as tuning_objective
    from planners.tuned import read_tuned
    from scenes.errors import SuiteError
    from suite.cli.tune import _candidate_dir, candidate_trials, grid, recorded
    from suite.problems.dataset import tuning_problems
    from suite.report.tuning import choose, evaluate
    from suite.run.runner import run_trials

    planner_class(args.planner)  # an unknown planner fails here, before anything is read
    factors = _factors(args.factors)
    tuned = read_tuned(args.planner) or {}
    ds_info = tuned.get("dataset") or {}
    dataset = args.dataset or ds_info.get("name")
    budget = args.budget or tuned.get("time_limit_s")
    per_family = args.per_family if args.per_family is not None else ds_info.get("per_family")
    if not dataset or not budget:
        raise SuiteError(f"planner {args.planner!r} has no tuned file to read the dataset and budget from; "
                         "give --dataset and --budget")
    tune_dir = Path(args.tune_dir or Path("results") / "tune" / args.planner)
    objective = tuning_objective(args.planner)
    candidates = grid(args.planner)
    _, problems = tuning_problems(dataset, per_family=per_family, time_limit_s=float(budget))
    base: list[tuple[dict, list[TrialRecord]]] = []
    for settings in candidates:
        trials = candidate_trials(args.planner, settings, problems, seed=0)
        d = _candidate_dir(tune_dir, settings)
        recs = recorded(d, trials)
        if len(recs) != len(trials):
            raise SuiteError(f"{d}: {len(recs)} of the {len(trials)} trials of candidate {json.dumps(settings)} are "
                             f"recorded; finish the tuning first (python -m suite tune --planner {args.planner} --out {tune_dir})")
        base.append((settings, recs))

    rows = []
    for factor in [1.0, *factors]:
        b = round(float(budget) * factor, 6)
        evaluated = []
        for settings, recs in base:
            if b <= float(budget):
                evaluated.append((settings, at_smaller_budget(recs, b)))
                continue
            late = {r.problem_id for r in recs if r.status in TIMEOUTS}
            kept = [r.with_(time_limit_s=b) for r in recs if r.problem_id not in late]
            trials = candidate_trials(args.planner, settings, [(p.with_(time_limit_s=b), m) for p, m in problems
                                                               if m["problem_id"] in late], seed=0)
            again: list[TrialRecord] = []
            if trials:
                out = _candidate_dir(tune_dir, settings) / f"budget-{b:g}s"
                out.mkdir(parents=True, exist_ok=True)
                print(f"{json.dumps(settings)}: planning the {len(trials)} timed-out trials again at {b:g} s",
                      file=sys.stderr)
                run_trials(trials, out=out, jobs=args.jobs, progress_bar=not args.no_progress)
                again = recorded(out, trials)
            evaluated.append((settings, kept + again))
        results = evaluate(evaluated)
        chosen = choose(results, objective=objective, weighting="family")
        rows.append({
            "factor": factor, "budget_s": b, "chosen": results[chosen].settings,
            "candidates": [{"settings": r.settings, "family_solved_mean": round(r.family_solved_mean, 4),
                            "solved": r.solved, "problems": r.problems,
                            "family_time_to_solve_median_s": round(r.family_time_to_solve_median_s, 4),
                            "family_length_ratio_common_median": round(r.family_length_ratio_common_median, 4)}
                           for r in results],
        })
    tuned_choice = tuned.get("settings")
    if args.json:
        print(json.dumps({"planner": args.planner, "objective": objective, "tuned": tuned_choice, "budgets": rows}, indent=1))
        return 0
    print(f"{args.planner} ({objective} objective, families weigh equally), tuned at {budget:g} s on {dataset}: "
          f"{json.dumps(tuned_choice)}")
    for row in rows:
        flip = "" if row["chosen"] == rows[0]["chosen"] else "   <- a different choice"
        print(f"  at {row['budget_s']:g} s (x{row['factor']:g}): {json.dumps(row['chosen'])}{flip}")
        for c in row["candidates"]:
            print(f"      {json.dumps(c['settings']):58s} solved/family {c['family_solved_mean']:.3f} "
                  f"({c['solved']:g}/{c['problems']})  time {c['family_time_to_solve_median_s']:.3f} s  "
                  f"length {c['family_length_ratio_common_median']:.3f}")
    return 0
