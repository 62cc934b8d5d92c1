"""Summary statistics: per-planner success rates and metric quartiles, and paired planner comparisons.

Groups are one planner's trials over all problems, per problem kind or per scene variant (`summarize`);
paired comparisons take the differences on the problems both planners solved, with a percentile-bootstrap
CI of their median and a Wilcoxon signed-rank p-value (`paired_comparisons`). Everything is computed
from the saved trial records alone (see `suite.run.records`).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from suite.run.records import (
    SUCCESS,
    is_success,
    metric,
    metric_values,
    planners_in,
    problem_key,
    problem_kinds_in,
    statuses_in,
)

#: The metrics of the summary: record field -> column label (with unit).
SUMMARY_METRICS: dict[str, str] = {
    "planning_time_s": "planning time (s)",
    "path_length_rad": "path length (rad)",
    "length_ratio": "length / reference",
    "turning_angle_rad": "turning angle (rad)",
    "sparc": "SPARC (higher: smoother)",
    "clearance_min_m": "min clearance (m)",
    "duration_s": "duration (s)",
}
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
    """One planner's results over a group of problems (all of them, or one problem kind)."""

    planner: str
    problem: str  # a problem kind, or "all"
    variant: str  # a scene variant, or "all"
    n: int
    successes: int
    status_counts: dict[str, int]
    metrics: dict[str, MetricStats]

    @property
    def success_rate(self) -> float:
        return self.successes / self.n if self.n else math.nan


@dataclasses.dataclass(frozen=True)
class PairedComparison:
    """Paired differences (planner_a - planner_b) of one metric over the problems both solved.

    Attributes:
        n: number of problems both planners solved.
        median_diff: median of the paired differences (the metric's unit).
        ci_low, ci_high: percentile-bootstrap 95% CI of that median (NaN if n < 2).
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


# --- computation ---------------------------------------------------------------------------------


def _group(records: Sequence[dict], *, planner: str, problem: str, variant: str) -> GroupSummary:
    counts = {s: 0 for s in statuses_in(records)}
    for r in records:
        counts[str(r["status"])] += 1
    return GroupSummary(
        planner=planner,
        problem=problem,
        variant=variant,
        n=len(records),
        successes=counts.get(SUCCESS, 0),
        status_counts={s: c for s, c in counts.items() if c},
        metrics={m: MetricStats.of(metric_values(records, m)) for m in SUMMARY_METRICS},
    )


def summarize(
    records: Sequence[dict[str, Any]], *, by: str | None = None, planners: Sequence[str] | None = None
) -> list[GroupSummary]:
    """Per-planner summaries, over all records or split by "problem" kind or "variant".

    Args:
        records: trial records.
        by: None for one row per planner, "problem" or "variant" for one row per planner and value.
        planners: the planners in display order (default: order of appearance).
    """
    if by not in (None, "problem", "variant"):
        raise ValueError(f"by must be None, 'problem' or 'variant', got {by!r}")
    planners = list(planners) if planners is not None else planners_in(records)
    out = []
    for p in planners:
        mine = [r for r in records if r["planner"] == p]
        if by is None:
            out.append(_group(mine, planner=p, problem=ALL, variant=ALL))
            continue
        values = problem_kinds_in(mine) if by == "problem" else sorted({str(r["variant"]) for r in mine})
        for v in values:
            sub = [r for r in mine if str(r[by]) == v]
            out.append(
                _group(sub, planner=p, problem=v if by == "problem" else ALL, variant=v if by == "variant" else ALL)
            )
    return out


def bootstrap_median_ci(
    diffs: np.ndarray, *, rng: np.random.Generator, n_resamples: int = N_RESAMPLES, level: float = 0.95
) -> tuple[float, float]:
    """Percentile-bootstrap confidence interval of the median of `diffs` (NaNs if fewer than 2)."""
    diffs = np.asarray(diffs, dtype=float)
    if len(diffs) < 2:
        return math.nan, math.nan
    idx = rng.integers(0, len(diffs), size=(n_resamples, len(diffs)))
    medians = np.median(diffs[idx], axis=1)
    alpha = (1.0 - level) / 2
    lo, hi = np.percentile(medians, [100 * alpha, 100 * (1 - alpha)])
    return float(lo), float(hi)


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


def _per_problem_values(records: Sequence[dict], name: str) -> dict[tuple, float]:
    """problem key -> the metric over that planner's successful trials of it (median of repeats)."""
    values: dict[tuple, list[float]] = {}
    for r in records:
        if is_success(r):
            v = metric(r, name)
            if math.isfinite(v):
                values.setdefault(problem_key(r), []).append(v)
    return {k: float(np.median(v)) for k, v in values.items()}


def paired_comparisons(
    records: Sequence[dict[str, Any]],
    *,
    rng: np.random.Generator,
    metrics: Sequence[str] = tuple(SUMMARY_METRICS),
    planners: Sequence[str] | None = None,
    n_resamples: int = N_RESAMPLES,
) -> list[PairedComparison]:
    """Paired comparisons of every planner pair on every metric.

    Trials pair on (scene_seed, variant, can_id, problem); only problems both planners solved
    count. A planner with several successful trials of one problem contributes their median.

    Args:
        records: trial records.
        rng: the generator the bootstrap resamples with.
        metrics: metric names (see `suite.run.records.metric`).
        planners: planners in order; each pair (a, b) has a before b and differences a - b.
        n_resamples: bootstrap resamples.
    """
    planners = list(planners) if planners is not None else planners_in(records)
    by_planner = {p: [r for r in records if r["planner"] == p] for p in planners}
    out = []
    for name in metrics:
        values = {p: _per_problem_values(by_planner[p], name) for p in planners}
        for a, b in itertools.combinations(planners, 2):
            common = sorted(set(values[a]) & set(values[b]))
            diffs = np.array([values[a][k] - values[b][k] for k in common])
            lo, hi = bootstrap_median_ci(diffs, rng=rng, n_resamples=n_resamples)
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
                )
            )
    return out
