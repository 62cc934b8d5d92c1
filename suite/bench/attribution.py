"""`python -m suite bench attribution`: how good the estimate of the Drake query time is.

`ik` and `trajopt` count their distance queries exactly and estimate their seconds from a replay of
REPLAY_QUERIES sampled queries (`planners.drake_queries`). This bench plans each problem twice in
one process, after one untimed warm-up trial per planner: once as every run does, and once
replaying every query of the plan. SNOPT and the planners are deterministic, so both plans make
the same queries. It reports per planner:
- the ratio of the estimate to the full replay (median, p10 and p90 over problems);
- the query count, the query share of planning time and the seconds per query (medians);
- the extra time of the sampled replay, per plan.
"""

from __future__ import annotations

import argparse
import json
from typing import TYPE_CHECKING

import numpy as np

from suite.cli.args import positive_int
from suite.problems import DEFAULT_TIER

if TYPE_CHECKING:
    from suite.run.records import TrialRecord

PLANNERS = ("ik", "trajopt")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--dataset", default=f"{DEFAULT_TIER}:family=wall",
                   help=f"NAME[:TIER[:FILTERS]] of the problems (default {DEFAULT_TIER}:family=wall)")
    p.add_argument("--planners", default=",".join(PLANNERS), help="comma-separated, of ik,trajopt (default both)")
    p.add_argument("--problems", type=positive_int, default=12, help="non-trivial problems, lowest ids first (default 12)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")


def _trial(problem, meta, planner: str) -> TrialRecord:
    from planners.registry import planner_class
    from suite.run.trial import config_dict, make_config, make_trial, run_trial

    cls = planner_class(planner)
    return run_trial(make_trial(problem, planner=planner, planner_config=config_dict(make_config(cls, {})),
                                run_seed=0, meta=meta))


def _drake(record: TrialRecord) -> dict | None:
    return ((record.attribution or {}).get("parts") or {}).get("drake")


def measure(problems: list[tuple], planner: str) -> dict:
    """The figures of one planner over [(problem, meta)] (see the module's docstring)."""
    import planners.drake_queries as dq

    _trial(*problems[0], planner)  # warm-up: imports, the world, the first solve
    ratios, queries, shares, per_query, replay_ms = [], [], [], [], []
    sampled = dq.REPLAY_QUERIES
    for problem, meta in problems:
        est = _trial(problem, meta, planner)
        dq.REPLAY_QUERIES = 10**9  # every query kept and replayed
        try:
            full = _trial(problem, meta, planner)
        finally:
            dq.REPLAY_QUERIES = sampled
        a, b = _drake(est), _drake(full)
        if not a or not b or not b["query_s"] or a["queries"] != b["queries"]:
            continue  # no query, or (not expected) another run made other queries
        ratios.append(a["query_s"] / b["query_s"])
        queries.append(a["queries"])
        shares.append(b["query_s"] / est.planning_time_s)
        per_query.append(b["query_s"] / b["queries"])
        replay_ms.append(1e3 * (sampled + 1) * b["query_s"] / b["queries"])
    q = (lambda v, p: float(np.quantile(v, p)) if len(v) else None)
    return {"planner": planner, "problems": len(problems), "compared": len(ratios),
            "estimate_over_full_median": q(ratios, 0.5), "estimate_over_full_p10": q(ratios, 0.1),
            "estimate_over_full_p90": q(ratios, 0.9), "queries_median": q(queries, 0.5),
            "query_share_median": q(shares, 0.5), "s_per_query_median": q(per_query, 0.5),
            "sampled_replay_ms_median": q(replay_ms, 0.5)}


def run(args: argparse.Namespace) -> int:
    from scenes.errors import SuiteError
    from suite.problems.dataset import load_dataset

    planners = [p.strip() for p in args.planners.split(",") if p.strip()]
    bad = [p for p in planners if p not in PLANNERS]
    if bad or not planners:
        raise SuiteError(f"--planners {args.planners!r}: allowed are {', '.join(PLANNERS)}")
    ds = load_dataset(args.dataset, time_limit_s=5.0)
    chosen = sorted(pid for pid in ds.ids if not ds.meta[pid]["trivial"])[: args.problems]
    if not chosen:
        raise SuiteError(f"--dataset {args.dataset!r} has no non-trivial problem")
    by_id = dict(zip(ds.ids, ds.problems))
    problems = [(by_id[pid], ds.meta[pid]) for pid in chosen]
    out = [measure(problems, p) for p in planners]
    if args.json:
        print(json.dumps(out, indent=1))
        return 0
    print(f"{args.dataset}: {len(problems)} non-trivial problems, each planned with the sampled replay and with a "
          "replay of every query")
    for r in out:
        f = (lambda v, fmt: "n/a" if v is None else fmt.format(v))
        print(f"{r['planner']}: estimate / full replay median {f(r['estimate_over_full_median'], '{:.2f}')} "
              f"(p10 {f(r['estimate_over_full_p10'], '{:.2f}')}, p90 {f(r['estimate_over_full_p90'], '{:.2f}')}) on "
              f"{r['compared']} problems; queries {f(r['queries_median'], '{:.0f}')}, "
              f"{f(r['s_per_query_median'] and 1e6 * r['s_per_query_median'], '{:.0f}')} us each, "
              f"share of planning time {f(r['query_share_median'] and 100 * r['query_share_median'], '{:.0f}')}%; "
              f"the sampled replay adds {f(r['sampled_replay_ms_median'], '{:.1f}')} ms a plan")
    return 0
