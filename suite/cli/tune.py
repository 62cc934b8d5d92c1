"""`python -m suite tune --planner NAME`: choose a planner's settings on a dataset's tuning split.

Every candidate of the planner's documented search (its class's `search_space`, class defaults
first) runs on the same non-trivial problems of the dataset's `tune` split (all of them, or up
to `--per-family` per family, the lowest problem ids: a fixed, content-defined sample), through the
ordinary trial machinery (validation, TOPP-RA, metrics). The rule of `suite.report.tuning` picks
one, and `--write` stores it with the whole table in planners/configs/NAME.yaml, which every later
run uses as the planner's defaults. Runs are kept under `--out` (one directory per candidate), so
an interrupted tuning resumes where it stopped.
"""

from __future__ import annotations

import argparse
import datetime as dt
import hashlib
import itertools
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from scenes.errors import SuiteError
from suite.cli.args import positive_float, positive_int
from suite.problems import DEFAULT_DATASET
from suite.run.atomic import write_text_atomically

if TYPE_CHECKING:
    from suite.run.records import TrialRecord


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--planner", required=True, help="the planner to tune (see planners/tuned.py for its search)")
    p.add_argument("--dataset", default=DEFAULT_DATASET, help=f"dataset whose tune split is used (default {DEFAULT_DATASET})")
    p.add_argument("--per-family", type=positive_int, default=None,
                   help="at most this many non-trivial tuning problems per family (default: all of them; a "
                        "small sample misses what a hard family tells apart)")
    p.add_argument("--time-limit-s", type=positive_float, default=5.0, help="budget per problem, s (default 5)")
    p.add_argument("--jobs", type=positive_int, default=2, help="worker processes (default 2)")
    p.add_argument("--seed", type=int, default=0, help="run seed (default 0)")
    p.add_argument("--out", default=None, help="where the candidates' runs go (default results/tune/PLANNER)")
    p.add_argument("--write", action="store_true", help="write planners/configs/PLANNER.yaml with the choice")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def grid(planner: str) -> list[dict]:
    """Every candidate of the planner's search, class defaults first."""
    from planners.registry import known_planners
    from planners.tuned import search_space

    space = search_space(planner)
    if not space:
        with_one = []
        for name in sorted(known_planners()):
            try:
                if search_space(name):
                    with_one.append(name)
            except (ImportError, SuiteError):  # an optional planner not installed
                continue
        raise SuiteError(f"planner {planner!r} has no tuning search; planners with one: {', '.join(with_one)}")
    names = list(space)
    excluded = search_exclude(planner)
    return [c for c in (dict(zip(names, values)) for values in itertools.product(*(space[n] for n in names)))
            if not any(all(c.get(k) == v for k, v in rule.items()) for rule, _ in excluded)]


def search_exclude(planner: str) -> list[tuple[dict, str]]:
    """The candidates of the product the planner leaves out of its search, each with its reason
    (its class's `search_exclude`: [(partial settings, reason)])."""
    from planners.registry import planner_class

    return [(dict(rule), str(reason)) for rule, reason in getattr(planner_class(planner), "search_exclude", ()) or ()]


def offline_bound(planner: str) -> float | None:
    """The bound on the planner's offline seconds per world at p90 (its class's `offline_bound_s`), or None."""
    from planners.registry import planner_class

    return getattr(planner_class(planner), "offline_bound_s", None)


def candidate_trials(planner: str, settings: dict, problems, *, seed: int) -> list:
    """One candidate's trials on the tuning problems [(problem, meta)]: the planner with these
    settings over its class defaults (not over its tuned file), the run seed `seed`."""
    from planners.registry import planner_class
    from suite.run.trial import config_dict, make_config, make_trial

    config = config_dict(make_config(planner_class(planner), settings, tuned=False))
    return [make_trial(p, planner=planner, planner_config=config, run_seed=seed, meta=meta) for p, meta in problems]


def recorded(run_dir: Path, trials) -> list[TrialRecord]:
    """The records in run_dir of these trials (a candidate's directory may hold others)."""
    from suite.run.records import read_trials

    wanted = {t.trial_id for t in trials}
    return [r for r in read_trials(run_dir) if r.trial_id in wanted] if (run_dir / "trials.jsonl").is_file() else []


def _candidate_dir(out: Path, settings: dict) -> Path:
    digest = hashlib.sha256(json.dumps(settings, sort_keys=True, default=str).encode()).hexdigest()[:10]
    return out / f"candidate-{digest}"


def run(args: argparse.Namespace) -> int:
    import multiprocessing

    from suite.run.interrupt import Interrupted, SignalGuard, reap_children
    from suite.run.lock import RunLock

    from planners.registry import planner_class

    planner_class(args.planner)  # an unknown planner, or one without a search, fails before anything is written
    grid(args.planner)
    out = Path(args.out or Path("results") / "tune" / args.planner)
    before = frozenset(c.pid for c in multiprocessing.active_children())
    with SignalGuard():
        lock = RunLock(out, what="tuning").acquire()  # one tuning per directory: candidates share it
        try:
            return _tune(args, out)
        except Interrupted as exc:
            print(f"interrupted by {exc.name}: the candidates' trials recorded in {out} are kept and "
                  f"{'planners/configs/' + args.planner + '.yaml was not written' if args.write else 'nothing was chosen'}; "
                  "run the same command again to carry on", file=sys.stderr)
            return exc.exit_code
        finally:
            reap_children(keep=before)
            lock.release()


def _tune(args: argparse.Namespace, out: Path) -> int:
    from planners.tuned import config_path, objective as tuning_objective
    from suite.problems.dataset import tuning_problems
    from suite.report.tuning import RULE, WEIGHTINGS, choose, choose_explained, evaluate, table_rows, weak_families
    from suite.run.runner import run_trials

    candidates = grid(args.planner)
    ds, problems = tuning_problems(args.dataset, per_family=args.per_family, time_limit_s=args.time_limit_s)
    print(f"tuning {args.planner}: {len(candidates)} candidates x {len(problems)} non-trivial problems of "
          f"{ds.name}'s tune split ({args.time_limit_s:g} s each) into {out}", file=sys.stderr)
    evaluated = []
    for i, settings in enumerate(candidates, 1):
        trials = candidate_trials(args.planner, settings, problems, seed=args.seed)
        run_dir = _candidate_dir(out, settings)
        run_dir.mkdir(parents=True, exist_ok=True)
        (run_dir / "candidate.json").write_text(json.dumps({"settings": settings, "config": trials[0].planner_config},
                                                           default=str))
        print(f"[{i}/{len(candidates)}] {json.dumps(settings, default=str)}", file=sys.stderr)
        run_trials(trials, out=run_dir, jobs=args.jobs, progress_bar=not args.no_progress)
        evaluated.append((settings, recorded(run_dir, trials)))
    results = evaluate(evaluated)
    objective = tuning_objective(args.planner)
    bound = offline_bound(args.planner)
    explained = choose_explained(results, objective=objective, weighting="family", offline_bound_s=bound)
    chosen = explained.index
    pooled = choose(results, objective=objective, weighting="pooled", offline_bound_s=bound)
    for i in explained.over_offline_bound:
        print(f"out: {json.dumps(results[i].settings, default=str)} builds its worlds in {results[i].offline_p90_s:.0f} s "
              f"at p90, over the {bound:g} s bound")
    rows = table_rows(results, chosen=chosen, pooled=pooled)
    _print_table(rows)
    weak = weak_families(results, chosen=chosen)
    print(f"chosen ({objective} objective, families weigh equally): {json.dumps(results[chosen].settings, default=str)}, "
          f"decided by {explained.decided_by}"
          + (f"; under 50% on {', '.join(weak)} where another candidate does better" if weak else ""))
    print(f"pooled over problems (the rule before recycle-v3) it would be: {json.dumps(results[pooled].settings, default=str)}")
    if args.write:
        from planners.worlds import checker

        excluded = search_exclude(args.planner)
        from suite.run.manifest import git_commit

        data = {
            "planner": args.planner,
            "settings": results[chosen].settings,
            "chosen_by": "python -m suite " + " ".join(sys.argv[1:]) if sys.argv[1:2] == ["tune"] else "suite tune",
            "rule": RULE,
            "weighting": f"family: {WEIGHTINGS['family']}",
            "objective": objective,
            "decided_by": explained.decided_by,
            **({"offline_bound_s": bound,
                "over_offline_bound": [results[i].settings for i in explained.over_offline_bound]} if bound else {}),
            **({"excluded": [{"settings": rule, "why": why} for rule, why in excluded]} if excluded else {}),
            "ties": {"solved": list(explained.solved_tied), "objective": list(explained.objective_tied),
                     "other_metric": list(explained.other_tied)},
            "pooled_choice": {"settings": results[pooled].settings, "weighting": f"pooled: {WEIGHTINGS['pooled']}"},
            "dataset": {"name": ds.name, "hash": ds.hash, "split": "tune", "problems": len(problems),
                        "per_family": args.per_family, "non_trivial_only": True},
            "time_limit_s": args.time_limit_s,
            "checker": checker(),  # what the candidates' python-fcl checks ran in (planners.worlds)
            "date_utc": dt.datetime.now(dt.UTC).strftime("%Y-%m-%d"),
            "commit": git_commit(),  # "+dirty": the code that ran was not this commit's
            "weak_families": weak,
            "table": rows,
        }
        _write_yaml(config_path(args.planner), data)
        print(f"wrote {config_path(args.planner)}")
    return 0


def _print_table(rows: list[dict]) -> None:
    from tabulate import tabulate

    families = sorted({f for r in rows for f in r["by_family"]})
    headers = ["", "settings", "solved", *families, "time to solve (s)", "per family (s)", "length ratio",
               "per family", "time vs chosen [95%]", "length vs chosen [95%]"]
    body = [[("*" if r["chosen"] else "") + ("p" if r.get("chosen_pooled") else ""), json.dumps(r["settings"], default=str),
             r["solved"], *(r["by_family"].get(f, "-") for f in families), r["time_to_solve_median_s"],
             r["family_time_to_solve_median_s"], r["length_ratio_common_median"],
             r["family_length_ratio_common_median"], _versus(r.get("time_vs_chosen")),
             _versus(r.get("length_vs_chosen"))] for r in rows]
    print("* chosen (families weigh equally); p: the choice pooled over problems")
    print(tabulate(body, headers=headers, tablefmt="simple", missingval="n/a"))


def _versus(v: list | None) -> str:
    """A paired ratio against the chosen candidate, '1.23 [1.10, 1.40]'."""
    if not v:
        return "-"
    fmt = lambda x: "n/a" if x is None else f"{x:.3g}"  # noqa: E731
    return f"{fmt(v[0])} [{fmt(v[1])}, {fmt(v[2])}]"


def _write_yaml(path: Path, data: dict) -> None:
    import yaml

    path.parent.mkdir(parents=True, exist_ok=True)
    head = (f"# {data['planner']}'s settings, chosen by `python -m suite tune --planner {data['planner']}` on the tune split\n"
            "# of the dataset below; every run uses `settings` as this planner's defaults. `table` is every\n"
            "# candidate's result on the same problems (the justification).\n")
    write_text_atomically(path, head + yaml.safe_dump(data, sort_keys=False, width=110))
