"""Choosing a planner's settings from the records of its candidates on a tuning split.

Two weightings of the same rule. "family" (the shipped one) weighs every family equally: step 1
compares the mean over families of each family's solved fraction, and step 2 the median over
families of each family's median figure, so that an easy family with many problems cannot decide
for a hard one. "pooled" (the rule before recycle-v3) counts problems and takes medians over all
of them; its choice is reported beside the shipped one.

Rule (documented in docs/ and written into the tuned-config file):
0. a candidate that solves under half of a family's problems while another candidate solves more
   of them is out, if any candidate is left (the issue's requirement: no shipped setting below 50%
   on a family where a documented one does better; `weak_families`);
1. the most distinct problems solved wins;
2. among candidates that solve as many, a feasibility planner ("time") takes the lowest median
   time to solve (failures at the budget), an optimizing planner ("length") the lowest median
   length over the best known path on the problems every candidate solved;
3. a difference within `TOLERANCE` (10% in time, 1% in length), or within `ABS_TOLERANCE` (5 ms
   in time), is a tie, and a tie keeps the earlier candidate (the grid lists class defaults first).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from suite.report.outcomes import Outcome, outcomes, solved_count

#: The rule in one line, as written into a tuned-config file.
RULE = ("candidates under 50% on a family where another candidate solves more of it are out (if any is left); "
        "then most distinct problems solved; ties: lowest median time to solve (failures at the budget) for "
        "objective 'time', lowest median length ratio on the problems every candidate solved for 'length', "
        "within 10% or 5 ms (time) or 1% (length) counted as equal; then the earlier candidate")
#: How the rule weighs families: its name, and what it changes in RULE.
WEIGHTINGS = {
    "family": "families weigh equally: 'solved' is the mean over families of each family's solved fraction, "
              "and each median is the median over families of that family's median",
    "pooled": "problems weigh equally: 'solved' counts problems and each median is over all problems",
}
TUNING_METRICS = ("planning_time_s", "length_ratio", "path_length_rad")
#: Relative differences of the tie-break figure treated as equal: 10% in median time (timings on a
#: shared machine vary that much), 1% in median length ratio.
TOLERANCE = {"time": 0.10, "length": 0.01}
#: Absolute differences treated as equal: 5 ms in median time. With compiled checks `rrt`'s medians
#: are 2-3 ms, where 10% is 0.3 ms: below what a trial's clock can tell apart on a shared 2-core
#: machine (one scheduler quantum is 4 ms at Linux's common CONFIG_HZ=250), and two tunings of
#: the same candidates chose differently. None for length (a ratio: no absolute scale).
ABS_TOLERANCE = {"time": 0.005, "length": 0.0}


@dataclasses.dataclass(frozen=True)
class CandidateResult:
    """One candidate setting's results on the tuning problems."""

    settings: dict[str, Any]
    problems: int
    solved: float
    by_family: dict[str, tuple[float, int]]
    time_to_solve_median_s: float
    planning_time_median_s: float
    length_ratio_common_median: float
    family_solved_mean: float = math.nan
    family_time_to_solve_median_s: float = math.nan
    family_length_ratio_common_median: float = math.nan


def _median(values: Sequence[float]) -> float:
    arr = np.asarray([v for v in values if math.isfinite(v)], float)
    return float(np.median(arr)) if len(arr) else math.nan


def evaluate(candidates: Sequence[tuple[dict[str, Any], Sequence[dict]]]) -> list[CandidateResult]:
    """Per candidate (its settings and its trial records) the figures the rule ranks on."""
    per: list[dict[tuple, Outcome]] = [outcomes(recs, metrics=TUNING_METRICS) for _, recs in candidates]
    common = set.intersection(*[{k for k, o in oc.items() if o.successes} for oc in per]) if per else set()
    out = []
    for (settings, _), oc in zip(candidates, per):
        families: dict[str, list[Outcome]] = {}
        for o in oc.values():
            families.setdefault(o.family, []).append(o)
        fam_common = {f: [oc[k].metrics["length_ratio"] for k in common if oc[k].family == f] for f in families}
        out.append(CandidateResult(
            settings=dict(settings),
            problems=len(oc),
            solved=solved_count(oc.values()),
            by_family={f: (solved_count(v), len(v)) for f, v in sorted(families.items())},
            time_to_solve_median_s=_median([o.time_to_solve_s for o in oc.values()]),
            planning_time_median_s=_median([o.metrics["planning_time_s"] for o in oc.values()]),
            length_ratio_common_median=_median([oc[k].metrics["length_ratio"] for k in common]),
            family_solved_mean=float(np.mean([solved_count(v) / len(v) for v in families.values()])) if families else math.nan,
            family_time_to_solve_median_s=_median([_median([o.time_to_solve_s for o in v]) for v in families.values()]),
            family_length_ratio_common_median=_median([_median(v) for v in fam_common.values()]),
        ))
    return out


def choose(results: Sequence[CandidateResult], *, objective: str, weighting: str = "family") -> int:
    """The index of the chosen candidate (see the module's rule) under a weighting of WEIGHTINGS."""
    if objective not in ("time", "length"):
        raise ValueError(f"objective must be 'time' or 'length', got {objective!r}")
    if weighting not in WEIGHTINGS:
        raise ValueError(f"weighting must be one of {sorted(WEIGHTINGS)}, got {weighting!r}")
    admissible = [i for i in range(len(results)) if not weak_families(results, chosen=i)]
    pool = admissible or list(range(len(results)))
    family = weighting == "family"

    def solved(r: CandidateResult) -> float:
        return r.family_solved_mean if family else r.solved

    def cost(r: CandidateResult) -> float:
        if objective == "time":
            v = r.family_time_to_solve_median_s if family else r.time_to_solve_median_s
        else:
            v = r.family_length_ratio_common_median if family else r.length_ratio_common_median
        return v if math.isfinite(v) else math.inf

    best = max(solved(results[i]) for i in pool)
    tied = [i for i in pool if solved(results[i]) >= best - 1e-12]
    lowest = min(cost(results[i]) for i in tied)
    # a difference within the tolerance is noise: the earlier candidate (the defaults first) keeps it
    band = max(lowest * TOLERANCE[objective], ABS_TOLERANCE[objective])
    return next(i for i in tied if cost(results[i]) <= lowest + band)


def table_rows(results: Sequence[CandidateResult], *, chosen: int, pooled: int | None = None) -> list[dict[str, Any]]:
    """The justification table as plain values (one row per candidate)."""
    def num(v: float, digits: int = 4) -> float | None:
        return round(v, digits) if math.isfinite(v) else None

    return [{
        "chosen": i == chosen,
        **({} if pooled is None else {"chosen_pooled": i == pooled}),
        "settings": {k: v for k, v in r.settings.items()},
        "solved": f"{r.solved:g}/{r.problems}",
        "by_family": {f: f"{k:g}/{n}" for f, (k, n) in r.by_family.items()},
        "time_to_solve_median_s": num(r.time_to_solve_median_s),
        "planning_time_median_s": num(r.planning_time_median_s),
        "length_ratio_common_median": num(r.length_ratio_common_median),
        "family_solved_mean": num(r.family_solved_mean),
        "family_time_to_solve_median_s": num(r.family_time_to_solve_median_s),
        "family_length_ratio_common_median": num(r.family_length_ratio_common_median),
    } for i, r in enumerate(results)]


def weak_families(results: Sequence[CandidateResult], *, chosen: int) -> list[str]:
    """Families where the chosen setting solves under half the problems although another candidate
    solves more of them there (the issue's rule: no shipped setting below 50% where a documented
    one does better)."""
    out = []
    for fam, (k, n) in results[chosen].by_family.items():
        if n and k / n < 0.5 and any(r.by_family.get(fam, (0, 0))[0] > k for r in results):
            out.append(fam)
    return out
