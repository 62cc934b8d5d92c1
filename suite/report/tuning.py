"""Choosing a planner's settings from the records of its candidates on a tuning split.

Two weightings of the same rule. "family" (the shipped one) weighs every family equally: step 1
compares the mean over families of each family's solved fraction, and step 2 the median over
families of each family's median figure, so that an easy family with many problems cannot decide
for a hard one. "pooled" (the rule before recycle-v3) counts problems and takes medians over all
of them; its choice is reported beside the shipped one.

Rule (documented in docs/planners.md and written into the tuned-config file):
-1. for a planner with offline work and a bound on it (`offline_bound_s` on its class: `gcs`'s
   regions, which a user builds), a candidate whose offline seconds per world exceed the bound
   at the 90th percentile over the tuning worlds is out, if any candidate is left (the default
   must be one a user can build);
0. a candidate that solves under half of a family's problems while another candidate solves more
   of them is out, if any candidate is left (`weak_families`);
1. the most distinct problems solved wins;
2. among candidates that solve as many, the objective decides: a feasibility planner ("time") the
   lowest median time to solve (failures at the budget), an optimizing planner ("length") the
   lowest median length over the best known path on the problems every candidate solved;
3. a candidate ties with the best on a metric unless the two differ beyond noise and beyond a
   margin: a paired bootstrap over the problems both ran (`paired_ratio`: per problem the log ratio
   of the two candidates' figures, the same weighting of families, scenes resampled within each
   family) gives a 95% interval of the ratio, and the difference is real only when that interval
   excludes 1 and the ratio is beyond `MARGIN` (10% in time, 1% in length: differences that would
   not change a reader's conclusion). The noise is measured on the candidates' own trials; there
   is no absolute band;
4. among the candidates tied on the objective, the better value of the other metric wins (shorter
   paths for a time tie, faster for a length tie), with the same test for a tie; only candidates
   tied on both metrics are decided by list order (the class defaults come first: nothing measured
   tells them apart, so the default stays).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from suite.report.outcomes import Outcome, outcomes, solved_count
from suite.run.records import TrialRecord

#: The rule in one line, as written into a tuned-config file.
RULE = ("candidates whose offline seconds per world exceed the planner's bound at p90 are out (if any is left); "
        "candidates under 50% on a family where another candidate solves more of it are out (if any is left); "
        "then most distinct problems solved; then the objective: lowest median time to solve (failures at the "
        "budget) for 'time', lowest median length ratio on the problems every candidate solved for 'length'; a "
        "candidate ties with the best unless a paired bootstrap over the problems both ran (95%, scenes resampled "
        "within families) excludes equality and the ratio is beyond 10% (time) or 1% (length); a tie on the "
        "objective goes to the better value of the other metric (same test); list order only between candidates "
        "tied on both")
#: How the rule weighs families: its name, and what it changes in RULE.
WEIGHTINGS = {
    "family": "families weigh equally: 'solved' is the mean over families of each family's solved fraction, "
              "and each median is the median over families of that family's median",
    "pooled": "problems weigh equally: 'solved' counts problems and each median is over all problems",
}
TUNING_METRICS = ("planning_time_s", "length_ratio", "path_length_rad")
#: The equivalence margin: a real difference (beyond noise) smaller than this share is still a tie,
#: 10% in median time, 1% in median length ratio. Not a noise estimate: the noise is the paired
#: bootstrap's interval (`paired_ratio`), measured on the candidates' own trials.
MARGIN = {"time": 0.10, "length": 0.01}
#: The paired bootstrap: resamples, interval level and its generator's seed (fixed, so that a
#: re-evaluation of the same records chooses the same candidate).
BOOTSTRAP_RESAMPLES = 2000
BOOTSTRAP_LEVEL = 0.95
BOOTSTRAP_SEED = 20261128
#: The other metric of each objective: what a tie on the objective is broken on.
OTHER = {"time": "length", "length": "time"}


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
    #: per distinct problem (key) its family, scene, time to solve (failures at the budget) and
    #: length ratio (NaN unless solved): what the paired tests compare
    per_problem: dict[tuple, tuple[str, tuple, float, float]] = dataclasses.field(default_factory=dict, compare=False)
    #: offline seconds per world (`offline_per_world`: CPU time where recorded, else wall time; each
    #: world once): the 90th percentile and the worlds counted; NaN and 0 for a planner without one
    offline_p90_s: float = math.nan
    offline_worlds: int = 0


def offline_per_world(records: Sequence[TrialRecord]) -> dict[str, float]:
    """world -> the offline seconds its records report, by `stats.world_hash`: the build's CPU time
    (`stats.offline_cpu_s`: one IRIS thread, so the wall time on a core of its own, whatever else
    the machine ran) where recorded, else its wall time (`stats.offline_s`); the largest when
    records of one world differ. Records without offline work are left out."""
    out: dict[str, float] = {}
    for r in records:
        stats = r.stats or {}
        world = stats.get("world_hash")
        seconds = stats.get("offline_cpu_s") if stats.get("offline_cpu_s") is not None else stats.get("offline_s")
        if world is not None and seconds is not None and seconds > 0:
            out[world] = max(float(seconds), out.get(world, 0.0))
    return out


def p90(values: Sequence[float]) -> float:
    """The 90th percentile (linear interpolation, numpy's default); NaN for no values."""
    return float(np.percentile(np.asarray(values, float), 90)) if len(values) else math.nan


def _median(values: Sequence[float]) -> float:
    arr = np.asarray([v for v in values if math.isfinite(v)], float)
    return float(np.median(arr)) if len(arr) else math.nan


def evaluate(candidates: Sequence[tuple[dict[str, Any], Sequence[TrialRecord]]]) -> list[CandidateResult]:
    """Per candidate (its settings and its trial records) the figures the rule ranks on."""
    per: list[dict[tuple, Outcome]] = [outcomes(recs, metrics=TUNING_METRICS) for _, recs in candidates]
    common = set.intersection(*[{k for k, o in oc.items() if o.successes} for oc in per]) if per else set()
    out = []
    for (settings, recs), oc in zip(candidates, per):
        offline = offline_per_world(recs)
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
            per_problem={k: (o.family, o.scene, o.time_to_solve_s,
                             o.metrics["length_ratio"] if o.successes else math.nan) for k, o in oc.items()},
            offline_p90_s=p90(list(offline.values())),
            offline_worlds=len(offline),
        ))
    return out


@dataclasses.dataclass(frozen=True)
class PairedRatio:
    """How candidate b's figure compares with candidate a's on the problems both have a value for:
    the ratio b/a (the weighting's median of per-problem log ratios, exponentiated) and its
    paired-bootstrap interval; NaNs when there is nothing to pair (then only the margin decides)."""

    ratio: float
    lo: float
    hi: float
    problems: int


def _metric_value(entry: tuple[str, tuple, float, float], metric: str) -> float:
    return entry[2] if metric == "time" else entry[3]


def _weighted_median(logs: np.ndarray, families: np.ndarray, *, family: bool) -> float:
    if not family:
        return float(np.median(logs))
    return float(np.median([np.median(logs[families == f]) for f in np.unique(families)]))


def paired_ratio(a: CandidateResult, b: CandidateResult, *, metric: str, weighting: str = "family") -> PairedRatio:
    """Candidate b against candidate a on one metric ("time": time to solve, failures at the
    budget, on every problem both ran; "length": length ratio on the problems both solved).

    Per problem the log of b's figure over a's; the statistic is their median (pooled) or the
    median over families of each family's median (family); the interval resamples scenes with
    replacement within each family (`BOOTSTRAP_RESAMPLES`, seeded), so that one station's
    problems count as one observation and every family keeps its weight."""
    keys = [k for k in a.per_problem if k in b.per_problem]
    rows = []
    for k in keys:
        va, vb = _metric_value(a.per_problem[k], metric), _metric_value(b.per_problem[k], metric)
        if math.isfinite(va) and math.isfinite(vb) and va > 0 and vb > 0:
            rows.append((a.per_problem[k][0], a.per_problem[k][1], math.log(vb / va)))
    if not rows:
        return PairedRatio(math.nan, math.nan, math.nan, 0)
    family = weighting == "family"
    fams = np.array([r[0] for r in rows])
    logs = np.array([r[2] for r in rows], float)
    point = _weighted_median(logs, fams, family=family)
    if len(rows) < 2:
        return PairedRatio(math.exp(point), math.nan, math.nan, len(rows))
    # scenes within families: index lists per (family, scene)
    strata: dict[str, dict[tuple, list[int]]] = {}
    for i, (f, scene, _) in enumerate(rows):
        strata.setdefault(f, {}).setdefault(scene, []).append(i)
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    stats = np.empty(BOOTSTRAP_RESAMPLES)
    groups = {f: list(by_scene.values()) for f, by_scene in strata.items()}
    for n in range(BOOTSTRAP_RESAMPLES):
        idx: list[int] = []
        for members in groups.values():
            for j in rng.integers(0, len(members), size=len(members)):
                idx.extend(members[j])
        sel = np.asarray(idx)
        stats[n] = _weighted_median(logs[sel], fams[sel], family=family)
    alpha = (1 - BOOTSTRAP_LEVEL) / 2
    lo, hi = np.percentile(stats, [100 * alpha, 100 * (1 - alpha)])
    return PairedRatio(math.exp(point), math.exp(float(lo)), math.exp(float(hi)), len(rows))


def _cost(r: CandidateResult, metric: str, *, family: bool) -> float:
    if metric == "time":
        v = r.family_time_to_solve_median_s if family else r.time_to_solve_median_s
    else:
        v = r.family_length_ratio_common_median if family else r.length_ratio_common_median
    return v if math.isfinite(v) else math.inf


def differs(best: CandidateResult, other: CandidateResult, *, metric: str, weighting: str = "family") -> bool:
    """True when `other` is worse than `best` on the metric beyond noise and beyond the margin
    (module rule, step 3). Without per-problem figures (a summary only) the margin alone decides."""
    family = weighting == "family"
    cb, co = _cost(best, metric, family=family), _cost(other, metric, family=family)
    if math.isinf(co) and not math.isinf(cb):
        return True
    if not (math.isfinite(cb) and math.isfinite(co)):
        return False
    beyond_margin = co > cb * (1 + MARGIN[metric])
    pr = paired_ratio(best, other, metric=metric, weighting=weighting)
    if not math.isfinite(pr.lo):
        return beyond_margin
    return beyond_margin and pr.lo > 1.0


@dataclasses.dataclass(frozen=True)
class Choice:
    """The chosen candidate and how the rule got there."""

    index: int
    #: the candidates left after each step: solved, tied on the objective, tied on the other metric
    solved_tied: tuple[int, ...]
    objective_tied: tuple[int, ...]
    other_tied: tuple[int, ...]
    #: which step decided: "solved", "objective", "other metric" or "list order (tied on both metrics)"
    decided_by: str
    #: the candidates over the offline bound at p90 (step -1), left out of the choice
    over_offline_bound: tuple[int, ...] = ()


def within_offline_bound(results: Sequence[CandidateResult], bound_s: float | None) -> list[int]:
    """The candidates whose offline seconds per world at p90 are within `bound_s` (all of them
    when there is no bound, or when none is within it: the rule then has nothing to choose from)."""
    every = list(range(len(results)))
    if bound_s is None:
        return every
    within = [i for i in every if not results[i].offline_p90_s > bound_s]  # NaN (no offline work) is within
    return within or every


def choose_explained(results: Sequence[CandidateResult], *, objective: str, weighting: str = "family",
                     offline_bound_s: float | None = None) -> Choice:
    """The chosen candidate (the module's rule) with the candidates each step left."""
    if objective not in ("time", "length"):
        raise ValueError(f"objective must be 'time' or 'length', got {objective!r}")
    if weighting not in WEIGHTINGS:
        raise ValueError(f"weighting must be one of {sorted(WEIGHTINGS)}, got {weighting!r}")
    buildable = within_offline_bound(results, offline_bound_s)
    over = tuple(i for i in range(len(results)) if i not in buildable)
    admissible = [i for i in buildable if not weak_families([results[j] for j in buildable],
                                                            chosen=buildable.index(i))]
    pool = admissible or buildable
    family = weighting == "family"
    other = OTHER[objective]

    def solved(r: CandidateResult) -> float:
        return r.family_solved_mean if family else r.solved

    best = max(solved(results[i]) for i in pool)
    tied = [i for i in pool if solved(results[i]) >= best - 1e-12]
    lead = min(tied, key=lambda i: (_cost(results[i], objective, family=family), i))
    on_objective = [i for i in tied if not differs(results[lead], results[i], metric=objective, weighting=weighting)]
    lead_other = min(on_objective, key=lambda i: (_cost(results[i], other, family=family), i))
    on_other = [i for i in on_objective
                if not differs(results[lead_other], results[i], metric=other, weighting=weighting)]
    index = min(on_other)
    if len(tied) == 1:
        how = "solved"
    elif len(on_objective) == 1:
        how = "objective"
    elif len(on_other) == 1:
        how = "other metric"
    else:
        how = "list order (tied on both metrics)"
    return Choice(index, tuple(tied), tuple(on_objective), tuple(on_other), how, over)


def choose(results: Sequence[CandidateResult], *, objective: str, weighting: str = "family",
           offline_bound_s: float | None = None) -> int:
    """The index of the chosen candidate (see the module's rule) under a weighting of WEIGHTINGS."""
    return choose_explained(results, objective=objective, weighting=weighting, offline_bound_s=offline_bound_s).index


def table_rows(results: Sequence[CandidateResult], *, chosen: int, pooled: int | None = None) -> list[dict[str, Any]]:
    """The justification table as plain values (one row per candidate): its figures, and its time
    and length against the chosen candidate's (the paired ratio and its 95% interval)."""
    def num(v: float, digits: int = 4) -> float | None:
        return round(v, digits) if math.isfinite(v) else None

    def versus(i: int, metric: str) -> dict[str, list[float | None]]:
        """{"<metric>_vs_chosen": [ratio, lo, hi]}, or {} for the chosen row or nothing to pair."""
        if i == chosen or not results[i].per_problem:
            return {}
        pr = paired_ratio(results[chosen], results[i], metric=metric)
        return {f"{metric}_vs_chosen": [num(pr.ratio, 3), num(pr.lo, 3), num(pr.hi, 3)]} if math.isfinite(pr.ratio) else {}

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
        **({"offline_p90_s": num(r.offline_p90_s, 1), "offline_worlds": r.offline_worlds} if r.offline_worlds else {}),
        **versus(i, "time"),
        **versus(i, "length"),
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
