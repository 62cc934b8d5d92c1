"""Summary tables: the terminal table and the tables of summary.md (per planner, kind and variant,
failures, pairs); `suite.report.summary` puts summary.md together."""

from __future__ import annotations

import math
import re
import textwrap
from collections.abc import Sequence
from typing import Any

import numpy as np
from tabulate import tabulate

from suite.report.outcomes import FEW_PROBLEMS, family_of
from suite.report.summary_stats import (
    SUMMARY_METRICS,
    GroupSummary,
    MetricStats,
    PairedComparison,
    summarize,
)
from suite.run.records import SUCCESS, TrialRecord, problem_counts

#: The success-aware time column: every problem counts, a failure at its budget.
TIME_TO_SOLVE_LABEL = "time to solve, failures at budget (s)"


def format_number(v: float) -> str:
    """A table cell's number: 3 significant digits (exponent form if very large or small), "n/a" if not finite."""
    if not math.isfinite(v):
        return "n/a"
    if v == 0:
        return "0"
    if abs(v) >= 1000 or abs(v) < 0.001:
        return f"{v:.2e}"
    return f"{v:.3g}"


def _stat(s: MetricStats) -> str:
    if s.n == 0:
        return "n/a"
    return f"{format_number(s.median)} [{format_number(s.q1)}, {format_number(s.q3)}]"


def _count(k: float) -> str:
    return f"{k:g}" if float(k).is_integer() else f"{k:.1f}"


def _rate(g: GroupSummary) -> str:
    """"k/n (rate%, 95% Wilson interval)" over distinct problems."""
    if not g.n:
        return "0/0"
    lo, hi = g.success_ci95
    return f"{_count(g.successes)}/{g.n} ({100 * g.success_rate:.0f}% [{100 * lo:.0f}, {100 * hi:.0f}])"


def group_rows(groups: Sequence[GroupSummary], *, key: str | None) -> tuple[list[str], list[list[str]]]:
    headers = (["planner"] + ([{"variant": "family"}.get(key, key)] if key else []) + ["success (95% CI)", TIME_TO_SOLVE_LABEL]
               + list(SUMMARY_METRICS.values()))
    rows = []
    for g in groups:
        row = [g.planner] + ([getattr(g, key)] if key else []) + [_rate(g), _stat(g.time_to_solve)]
        rows.append(row + [_stat(g.metrics[m]) for m in SUMMARY_METRICS])
    return headers, rows


def common_rows(stats: dict[str, dict[str, MetricStats]], planners: Sequence[str]) -> tuple[list[str], list[list[str]]]:
    headers = ["metric (common subset)", "n"] + list(planners)
    rows = []
    for m, label in SUMMARY_METRICS.items():
        n = next(iter(stats[m].values())).n if stats[m] else 0
        rows.append([label, n] + [format_number(stats[m][p].median) if n else "n/a" for p in planners])
    return headers, rows


#: The terminal table's metric columns (medians over each planner's solved problems); every metric
#: with its IQR is in summary.md.
TERMINAL_METRICS = {"length_ratio": "length /\nreference", "clearance_min_m": "clearance\n(mm)"}


def summary_table(records: Sequence[TrialRecord], *, planners: Sequence[str] | None = None,
                  wide: bool = False) -> str:
    """The per-planner table for the terminal, narrow enough for 80 columns: success k/n with its
    interval, the median time to solve (failures at the budget) and the medians of a few metrics,
    over distinct problems; then the composition line (and its warning when too few), the exact
    verdicts, and where the rest is. `wide`: every metric with its quartiles (summary.md's table,
    about 250 columns)."""
    if not records:
        return "no trial records"
    groups = summarize(records, planners=planners)
    if wide:
        headers, rows = group_rows(groups, key=None)
    else:
        headers = ["planner", "success (95% CI)", "time to\nsolve (s)", *TERMINAL_METRICS.values()]
        rows = [_terminal_row(g) for g in groups]
    lines = [composition(records), certification_line(records, [g.planner for g in groups]),
             "Medians [quartiles]; per family and kind: summary.md (and report.html)." if wide else
             "Medians; every metric with its quartiles (--wide), per family and kind: summary.md (and report.html)."]
    return tabulate(rows, headers=headers, tablefmt="simple") + "\n" + "\n".join(
        textwrap.fill(ln, width=80, break_on_hyphens=False) for ln in "\n".join(lines).split("\n"))


def _terminal_row(g: GroupSummary) -> list[str]:
    cells = [g.planner, _rate(g), "n/a" if g.time_to_solve.n == 0 else format_number(g.time_to_solve.median)]
    for m in TERMINAL_METRICS:
        st = g.metrics[m]
        scale = 1000.0 if m == "clearance_min_m" else 1.0
        cells.append("n/a" if st.n == 0 else format_number(scale * st.median))
    return cells


def certification_line(records: Sequence[TrialRecord], planners: Sequence[str]) -> str:
    """One line: per planner, its successes by exact verdict."""
    parts = []
    for p in planners:
        c = certification_counts(records, p)
        parts.append(f"{p} " + ", ".join(f"{c[v]} {v}" for v in (*VERDICTS, "not checked") if c[v] or v == "certified"))
    return "Exact verdict of the successes (docs/certification.md): " + "; ".join(parts) + "."


#: A path within this fraction of its problem's best known length equals it (0.1%).
BEST_KNOWN_EQUAL = 1e-3
BEST_KNOWN_INTRO = (
    "Each successful trial's joint path length against its problem's best known length (the dataset's "
    "reference): equal within 0.1%, or shorter. A certified path shorter by more than 0.1% beats the best "
    "known, and is listed by problem: the dataset's best known is not the best there is.")


def best_known_agreement(records: Sequence[TrialRecord], planner: str) -> dict[str, Any]:
    """A planner's successes against the best known lengths: {successes (with a best known),
    equal (within BEST_KNOWN_EQUAL), beaten: [{problem_id, length_rad, best_known_rad, ratio}] for
    the certified ones shorter by more than that, longest gain first}."""
    n = equal = 0
    beaten = []
    for r in records:
        if r.planner != planner or r.status != SUCCESS:
            continue
        best, length = r.reference_length_rad, (r.metrics or {}).get("path_length_rad")
        if not best or length is None:
            continue
        n += 1
        ratio = float(length) / float(best)
        if abs(ratio - 1.0) <= BEST_KNOWN_EQUAL:
            equal += 1
        elif ratio < 1.0 - BEST_KNOWN_EQUAL and (r.certification or {}).get("verdict") == "certified":
            beaten.append({"problem_id": r.problem_id, "length_rad": round(float(length), 6),
                           "best_known_rad": round(float(best), 6), "ratio": round(ratio, 4)})
    beaten.sort(key=lambda b: b["ratio"])
    return {"successes": n, "equal": equal, "beaten": beaten}


def best_known_rows(records: Sequence[TrialRecord], planners: Sequence[str]) -> tuple[list[str], list[list[Any]]]:
    headers = ["planner", "successes with a best known", "equal (0.1%)", "certified and shorter", "problems (ratio)"]
    rows = []
    for p in planners:
        a = best_known_agreement(records, p)
        shown = ", ".join(f"{b['problem_id']} ({b['ratio']:.3f})" for b in a["beaten"][:10])
        more = len(a["beaten"]) - 10
        rows.append([p, a["successes"], a["equal"], len(a["beaten"]), shown + (f", and {more} more" if more > 0 else "")])
    return headers, rows


def composition(records: Sequence[TrialRecord]) -> str:
    """One line: on how many distinct problems (how many trivial) and scenes the figures rest, and a
    warning when they are fewer than `FEW_PROBLEMS`."""
    c = problem_counts(records)
    trivial = (f", {c['trivial']} of them trivial (the straight joint segment is already valid)"
               if c["known_trivial"] else "")
    line = f"{c['distinct']} distinct problems from {c['scenes']} scenes{trivial}."
    if c["distinct"] < FEW_PROBLEMS:
        line += (f" WARNING: fewer than {FEW_PROBLEMS} distinct problems: too few to tell planners apart; "
                 "read every figure as anecdotal.")
    return line


#: The exact verdicts of `scenes.collision.certify`, in table order; "not checked": a record written
#: before certification existed.
VERDICTS = ("certified", "unproved", "collision")


def certification_counts(records: Sequence[TrialRecord], planner: str) -> dict[str, int]:
    """Per verdict, the planner's successful trials (the 0.01 rad rule) with that exact verdict."""
    out = dict.fromkeys((*VERDICTS, "not checked"), 0)
    for r in records:
        if r.planner == planner and r.status == SUCCESS:
            verdict = (r.certification or {}).get("verdict", "not checked")
            out[verdict] = out.get(verdict, 0) + 1
    return out


def certification_rows(records: Sequence[TrialRecord], planners: Sequence[str]) -> tuple[list[str], list[list[Any]]]:
    headers = ["planner", "successes (0.01 rad)", *VERDICTS, "not checked"]
    rows = []
    for p in planners:
        c = certification_counts(records, p)
        rows.append([p, sum(c.values()), *(c[v] for v in VERDICTS), c["not checked"]])
    return headers, rows


def cold_start(records: Sequence[TrialRecord], planner: str) -> dict[str, Any]:
    """A planner's cold trials (a worker's first of it) against its warm ones: how many, and the
    median planning and setup time (s) of each (None where there is no such trial)."""
    from suite.report.outcomes import is_cold

    mine = [r for r in records if r.planner == planner and r.warm is not None]
    cold = [r for r in mine if is_cold(r)]
    warm = [r for r in mine if not is_cold(r)]

    def med(rs, field):
        v = [float(getattr(r, field)) for r in rs if isinstance(getattr(r, field), (int, float))]
        return float(np.median(v)) if v else None

    return {"cold_trials": len(cold), "warm_trials": len(warm),
            "planning_time_s": {"cold": med(cold, "planning_time_s"), "warm": med(warm, "planning_time_s")},
            "setup_time_s": {"cold": med(cold, "setup_time_s"), "warm": med(warm, "setup_time_s")}}


def cold_rows(records: Sequence[TrialRecord], planners: Sequence[str]) -> tuple[list[str], list[list[Any]]]:
    headers = ["planner", "cold trials", "planning time, cold (s)", "planning time, warm (s)", "setup, cold (s)",
               "setup, warm (s)"]
    rows = []
    for p in planners:
        c = cold_start(records, p)
        rows.append([p, c["cold_trials"], *(format_number(math.nan if v is None else v) for v in (
            c["planning_time_s"]["cold"], c["planning_time_s"]["warm"], c["setup_time_s"]["cold"],
            c["setup_time_s"]["warm"]))])
    return headers, rows


def attribution_summary(records: Sequence[TrialRecord], planner: str) -> dict[str, Any] | None:
    """Medians over a planner's warm trials that carry `attribution`: collision queries, seconds per
    query, query share of planning time; None if none carries it."""
    from suite.report.outcomes import is_cold

    att = [r.attribution for r in records if r.planner == planner and r.attribution
           and not is_cold(r)]
    if not att:
        return None
    per = [a["s_per_query"] for a in att if a.get("s_per_query")]
    return {"engine": att[0].get("engine"), "trials": len(att),
            "queries": float(np.median([a["queries"] for a in att])),
            "s_per_query": float(np.median(per)) if per else None,
            "query_share": float(np.median([a["query_share"] for a in att]))}


def attribution_rows(records: Sequence[TrialRecord], planners: Sequence[str]) -> tuple[list[str], list[list[Any]]]:
    headers = ["planner", "engine", "trials", "collision queries", "us per query", "share of planning time"]
    rows = []
    for p in planners:
        a = attribution_summary(records, p)
        if a is None:
            rows.append([p, "not counted", "-", "-", "-", "-"])
        else:
            rows.append([p, a["engine"], a["trials"], format_number(a["queries"]),
                         format_number(1e6 * a["s_per_query"]) if a["s_per_query"] else "n/a",
                         f"{100 * a['query_share']:.0f}%"])
    return headers, rows


ATTRIBUTION_INTRO = (
    "Medians over warm trials of what a planning time went to: the collision and distance queries the planner "
    "asked, and the rest (the planner's own work and the Python around it). python-fcl state checks (every "
    "planner's motion checks) are clocked around each call; the distance queries SNOPT makes through Drake's "
    "constraint (`ik`, `trajopt`) are counted exactly and timed by replaying a sample of them (docs/timing.md); "
    "roboplan's checks in C++ (`roboplan-rrt`), which it does not count, are a lower bound: the edges kept in its "
    "trees at a calibrated cost per check (docs/peers.md).")


COLD_INTRO = (
    "A worker's first trial of a planner is cold: its planning time includes what only the first pays (lazy "
    "imports, caches, a solver's first set-up). Every time median in these tables is over warm trials only; "
    "a problem whose only trial was cold has no time. Records written before the flag existed count as warm. "
    "Medians over all trials of a kind, not per problem:")


CERTIFICATION_INTRO = (
    "Success is the field's rule: the path is free at every state sampled with at most 0.01 rad of joint "
    "motion between states (OMPL's and MoveIt's benchmarks use such a rule). Beside it, each successful path "
    "gets an exact verdict (docs/certification.md): `certified` (every straight segment proved free by distance "
    "bounds and bisection: nothing can collide between samples), `collision` (a state between the samples "
    "collides), `unproved` (a segment shorter than 1e-6 rad still unproved: a graze within micrometres).")


REASON_CODE_INTRO = (
    "Each failed trial's enumerated cause (`planners.base.FailureReason`): a planner names its own "
    "(no IK at a knot, regions disconnected, solver failed, search failed, budget spent), the judge "
    "names path rejected, late path, timing failed; crashes and kills are the orchestrator's. Records "
    "written before causes were recorded get theirs from their status.")


def failure_rows(groups: Sequence[GroupSummary], statuses: Sequence[str]) -> tuple[list[str], list[list[Any]]]:
    failures = [s for s in statuses if s != SUCCESS]
    headers = ["planner", "trials", "failed"] + failures
    rows = [
        [g.planner, g.n, g.n - g.successes] + [g.status_counts.get(s, 0) for s in failures] for g in groups
    ]
    return headers, rows


def failure_reason(rec: TrialRecord) -> str | None:
    """A trial's stated reason for its status: its planner's (`stats.reason`), or the error of a
    crashed trial; None if it states none."""
    stats = rec.stats or {}
    for value in (stats.get("reason"), stats.get("error")):
        if isinstance(value, str) and value.strip():
            return value.strip()
    return None


#: Numbers in a reason ("knot 24 (t=30)", "5.39 s into a 5 s budget"): masked so that one cause is one row.
_NUMBER = re.compile(r"(?<![A-Za-z_])-?\d+(?:\.\d+)?(?:e-?\d+)?")


def failure_reason_rows(records: Sequence[TrialRecord], planners: Sequence[str]) -> tuple[list[str], list[list[Any]]]:
    """Failed trials by status and stated reason (numbers in the reason shown as #), one column per
    planner, the most frequent first."""
    counts: dict[tuple[str, str], dict[str, int]] = {}
    for r in records:
        if r.status == SUCCESS:
            continue
        reason = failure_reason(r)
        key = (str(r.status), _NUMBER.sub("#", reason) if reason else "(no reason recorded)")
        row = counts.setdefault(key, {})
        row[r.planner] = row.get(r.planner, 0) + 1
    headers = ["status", "reason", *planners]
    ordered = sorted(counts.items(), key=lambda kv: (-sum(kv[1].values()), kv[0]))
    return headers, [[status, reason, *(c.get(p, 0) for p in planners)] for (status, reason), c in ordered]


def cause_counts(records: Sequence[TrialRecord]) -> dict[str, dict[str, dict[str, int]]]:
    """Failed trials by enumerated cause (`planners.base.FailureReason`) and family:
    {planner: {cause: {family: trials}}}."""
    from suite.run.records import reason_code

    out: dict[str, dict[str, dict[str, int]]] = {}
    for r in records:
        code = reason_code(r)
        if code is not None:
            row = out.setdefault(r.planner, {}).setdefault(code, {})
            row[family_of(r)] = row.get(family_of(r), 0) + 1
    return out


def reason_code_rows(records: Sequence[TrialRecord], planners: Sequence[str]) -> tuple[list[str], list[list[Any]]]:
    """`cause_counts` as a table: one row per (planner, cause), one column per family, each
    planner's most frequent causes first."""
    counts = [((p, code), c) for p, causes in cause_counts(records).items() for code, c in causes.items()]
    fams = sorted({f for _, c in counts for f in c})
    order = {p: i for i, p in enumerate(planners)}
    ordered = sorted(counts, key=lambda kv: (order.get(kv[0][0], len(order)), -sum(kv[1].values()), kv[0][1]))
    headers = ["planner", "cause", "all", *fams]
    return headers, [[p, code, sum(c.values()), *(c.get(f, 0) for f in fams)] for (p, code), c in ordered]


def paired_rows(pairs: Sequence[PairedComparison]) -> tuple[list[str], list[list[Any]]]:
    headers = ["metric", "A - B", "problems", "scenes", "median diff", "95% CI", "Wilcoxon p", "note"]
    rows = []
    for c in pairs:
        ci = "n/a" if not math.isfinite(c.ci_low) else f"[{format_number(c.ci_low)}, {format_number(c.ci_high)}]"
        p = "n/a" if not math.isfinite(c.p_value) else f"{c.p_value:.3g}"
        note = f"n < {FEW_PROBLEMS}: too few" if c.few else ""
        rows.append([SUMMARY_METRICS.get(c.metric, c.metric), f"{c.planner_a} - {c.planner_b}", c.n, c.scenes,
                     format_number(c.median_diff), ci, p, note])
    return headers, rows
