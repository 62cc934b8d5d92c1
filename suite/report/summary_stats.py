"""Summary statistics over distinct problems: success rates with Wilson intervals, metric quartiles
(on each planner's own successes and on the subset every planner solved), and paired comparisons.

The unit of replication is the distinct problem (`suite.report.outcomes`): a problem tried several
times counts once. Groups are one planner's problems overall, per problem kind or per scene family
(`summarize`); `common_subset_stats` measures every planner on the problems all of them solved;
paired comparisons take the differences on the problems both planners solved, with a bootstrap CI of
their median that resamples scenes and a Wilcoxon signed-rank p-value (`paired_comparisons`).
Everything is computed from the saved trial records alone (see `suite.run.records`).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Sequence

import numpy as np

from suite.report.outcomes import (
    FEW_PROBLEMS,
    cluster_bootstrap_median_ci,
    common_subset,
    family_of,
    outcomes,
    solved_count,
    wilson_interval,
)
from suite.run.records import TrialRecord, planners_in, problem_kinds_in, statuses_in
from suite.scoring.definitions import metric_def

#: The metrics of the summary, in its column order: record field -> column label (`MetricDef.column`).
SUMMARY_METRICS: dict[str, str] = {name: metric_def(name).column for name in (
    "planning_time_s", "path_length_rad", "length_ratio", "turning_angle_rad", "sparc", "clearance_min_m",
    "duration_s", "offline_s")}
ALL = "all"
N_RESAMPLES = 2000


@dataclasses.dataclass(frozen=True)
class MetricStats:
    """Median and quartiles of one metric over the successful trials of a group."""

    n: int
    median: float
    q1: float
    q3: float

    @staticmethod
    def of(values: np.ndarray) -> "MetricStats":
        if len(values) == 0:
            return MetricStats(0, math.nan, math.nan, math.nan)
        q1, med, q3 = np.percentile(values, [25, 50, 75])
        return MetricStats(len(values), float(med), float(q1), float(q3))


@dataclasses.dataclass(frozen=True)
class GroupSummary:
    """One planner's results over a group of distinct problems (all of them, one kind or one family).

    `n` counts distinct problems, `successes` the problems solved (a problem tried several times
    counts once, as the share of its trials solved), `trials` the trials behind them. Metrics are
    over the solved problems, one value per problem (the median of its successful trials);
    `time_to_solve` is over every problem, a failure counted at its budget.
    """

    planner: str
    problem: str  # a problem kind, or "all"
    variant: str  # a scene family, or "all"
    n: int
    successes: float
    trials: int
    status_counts: dict[str, int]
    metrics: dict[str, MetricStats]
    time_to_solve: MetricStats

    @property
    def success_rate(self) -> float:
        return self.successes / self.n if self.n else math.nan

    @property
    def success_ci95(self) -> tuple[float, float]:
        """The 95% Wilson interval of the success rate over distinct problems."""
        return wilson_interval(self.successes, self.n)


@dataclasses.dataclass(frozen=True)
class PairedComparison:
    """Paired differences (planner_a - planner_b) of one metric over the distinct problems both solved.

    Attributes:
        n: number of distinct problems both planners solved.
        scenes: number of scenes those problems come from (the bootstrap's clusters).
        median_diff: median of the paired differences (the metric's unit).
        ci_low, ci_high: 95% CI of that median, percentile bootstrap resampling scenes (NaN if n < 2).
        p_value: two-sided Wilcoxon signed-rank p (NaN if n < 2; 1.0 if all differences are 0).
    """

    metric: str
    planner_a: str
    planner_b: str
    n: int
    median_diff: float
    ci_low: float
    ci_high: float
    p_value: float
    scenes: int = 0

    @property
    def few(self) -> bool:
        """True when the comparison rests on fewer than `FEW_PROBLEMS` distinct problems."""
        return self.n < FEW_PROBLEMS


# --- computation ---------------------------------------------------------------------------------


def _group(records: Sequence[TrialRecord], *, planner: str, problem: str, variant: str) -> GroupSummary:
    counts = {s: 0 for s in statuses_in(records)}
    for r in records:
        counts[str(r.status)] += 1
    per_problem = list(outcomes(records, metrics=SUMMARY_METRICS).values())
    return GroupSummary(
        planner=planner,
        problem=problem,
        variant=variant,
        n=len(per_problem),
        successes=solved_count(per_problem),
        trials=len(records),
        status_counts={s: c for s, c in counts.items() if c},
        metrics={m: MetricStats.of(_finite([o.metrics[m] for o in per_problem])) for m in SUMMARY_METRICS},
        time_to_solve=MetricStats.of(_finite([o.time_to_solve_s for o in per_problem])),
    )


def _finite(values: Sequence[float]) -> np.ndarray:
    arr = np.asarray(values, dtype=float)
    return arr[np.isfinite(arr)]


def summarize(
    records: Sequence[TrialRecord], *, by: str | None = None, planners: Sequence[str] | None = None
) -> list[GroupSummary]:
    """Per-planner summaries over distinct problems, over all records or split by "problem" kind or
    "variant" (the scene family).

    Args:
        records: trial records.
        by: None for one row per planner, "problem" or "variant" for one row per planner and value.
        planners: the planners in display order (default: order of appearance).
    """
    if by not in (None, "problem", "variant"):
        raise ValueError(f"by must be None, 'problem' or 'variant', got {by!r}")
    planners = list(planners) if planners is not None else planners_in(records)
    field = {"problem": lambda r: str(r.problem), "variant": family_of}.get(by or "")
    out = []
    for p in planners:
        mine = [r for r in records if r.planner == p]
        if field is None:
            out.append(_group(mine, planner=p, problem=ALL, variant=ALL))
            continue
        values = problem_kinds_in(mine) if by == "problem" else sorted({family_of(r) for r in mine})
        for v in values:
            sub = [r for r in mine if field(r) == v]
            out.append(
                _group(sub, planner=p, problem=v if by == "problem" else ALL, variant=v if by == "variant" else ALL)
            )
    return out


@dataclasses.dataclass(frozen=True)
class RunSummary:
    """Every group statistic the summary files show, computed once: per planner over all problems,
    per problem kind and per scene family, and the common subset (see `common_subset_stats`)."""

    overall: list[GroupSummary]
    by_kind: list[GroupSummary]
    by_family: list[GroupSummary]
    common: dict[str, dict[str, MetricStats]]


def summarize_run(records: Sequence[TrialRecord], *, planners: Sequence[str]) -> RunSummary:
    return RunSummary(
        overall=summarize(records, planners=planners),
        by_kind=summarize(records, by="problem", planners=planners),
        by_family=summarize(records, by="variant", planners=planners),
        common=common_subset_stats(records, planners=planners),
    )


def common_subset_stats(
    records: Sequence[TrialRecord], *, planners: Sequence[str] | None = None,
    metrics: Sequence[str] = tuple(SUMMARY_METRICS),
) -> dict[str, dict[str, MetricStats]]:
    """metric -> planner -> stats over the distinct problems EVERY planner solved (no survivorship).

    A planner that solves only the easy problems looks best on its own successes; on the common
    subset all planners are measured on the same problems.
    """
    planners = list(planners) if planners is not None else planners_in(records)
    per = {p: outcomes([r for r in records if r.planner == p], metrics=metrics) for p in planners}
    out: dict[str, dict[str, MetricStats]] = {}
    for name in metrics:
        keys = common_subset(per, name)
        out[name] = {p: MetricStats.of(_finite([per[p][k].metrics[name] for k in keys])) for p in planners}
    return out


def wilcoxon_p(diffs: np.ndarray) -> float:
    """Two-sided Wilcoxon signed-rank p-value of paired differences.

    NaN for fewer than 2 pairs (no test possible); 1.0 when every difference is zero (the planners
    gave identical values, no evidence of a difference).
    """
    from scipy.stats import wilcoxon

    diffs = np.asarray(diffs, dtype=float)
    if len(diffs) < 2:
        return math.nan
    if np.all(diffs == 0):
        return 1.0
    return float(wilcoxon(diffs).pvalue)


def paired_comparisons(
    records: Sequence[TrialRecord],
    *,
    rng: np.random.Generator,
    metrics: Sequence[str] = tuple(SUMMARY_METRICS),
    planners: Sequence[str] | None = None,
    n_resamples: int = N_RESAMPLES,
) -> list[PairedComparison]:
    """Paired comparisons of every planner pair on every metric, over distinct problems.

    Trials pair on their problem identity (`problem_key`); only problems both planners solved
    count, each once (a planner with several successful trials of one problem contributes their
    median). The CI of the median difference resamples scenes, since problems of one scene are
    not independent.

    Args:
        records: trial records.
        rng: the generator the bootstrap resamples with.
        metrics: metric names (see `suite.run.records.metric`).
        planners: planners in order; each pair (a, b) has a before b and differences a - b.
        n_resamples: bootstrap resamples.
    """
    planners = list(planners) if planners is not None else planners_in(records)
    per = {p: outcomes([r for r in records if r.planner == p], metrics=metrics) for p in planners}
    out = []
    for name in metrics:
        for a, b in itertools.combinations(planners, 2):
            common = [k for k in per[a] if k in per[b]
                      and math.isfinite(per[a][k].metrics[name]) and math.isfinite(per[b][k].metrics[name])]
            diffs = np.array([per[a][k].metrics[name] - per[b][k].metrics[name] for k in common])
            scenes = [per[a][k].scene for k in common]
            lo, hi = cluster_bootstrap_median_ci(diffs, scenes, rng=rng, n_resamples=n_resamples)
            out.append(
                PairedComparison(
                    metric=name,
                    planner_a=a,
                    planner_b=b,
                    n=len(diffs),
                    median_diff=float(np.median(diffs)) if len(diffs) else math.nan,
                    ci_low=lo,
                    ci_high=hi,
                    p_value=wilcoxon_p(diffs),
                    scenes=len(set(scenes)),
                )
            )
    return out
