"""The unit of replication: one outcome per distinct problem and planner.

A run may hold several trials of one problem (repeated seeds, or a generated run whose scenes repeat
a station). Counting each trial as an observation would weigh one problem many times and make tests
look far more certain than the evidence allows. Every statistic of the report therefore starts here:
a planner's trials of one problem (same `problem_key`) collapse into one `Outcome`:

- `solved`: the share of its trials that succeeded (1 or 0 when the problem was tried once);
- `metrics`: the median of each metric over its successful trials;
- `time_to_solve_s`: the median over its trials of the planning time, a failed trial counted at the
  trial's budget (`time_limit_s`), the success-aware time of the report.

Problems are clustered by scene (`scene`): problems of one station share its obstacles and are not
independent, so bootstraps resample scenes, not problems (`cluster_bootstrap_median_ci`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from suite.run.records import TrialRecord, is_success, metric, problem_key

#: Below this many distinct problems a comparison is flagged as resting on too little evidence.
FEW_PROBLEMS = 20


@dataclasses.dataclass(frozen=True)
class Outcome:
    """One planner on one distinct problem (its trials collapsed)."""

    key: tuple
    scene: tuple
    family: str
    kind: str
    trials: int
    successes: int
    metrics: dict[str, float]
    time_to_solve_s: float

    @property
    def solved(self) -> float:
        """The share of this problem's trials that succeeded."""
        return self.successes / self.trials


def scene_of(rec: TrialRecord) -> tuple:
    """The cluster a record's problem belongs to: its station (scene key, else seed and variant)."""
    return (str(rec.scene_key or rec.scene_seed), str(rec.variant))


def family_of(rec: TrialRecord) -> str:
    """The scene family of a record (the dataset's family, else the generated scene's variant)."""
    return str(rec.family or rec.variant)


#: Metrics that time the planner: their medians are over warm trials only (`is_cold`).
TIMES = ("planning_time_s", "time_to_trajectory_s")


def is_cold(rec: TrialRecord) -> bool:
    """True for a worker's first trial of its planner (imports, caches, first solve in its time);
    records without the flag (imports, runs before it existed) count as warm."""
    return rec.warm is False


def _time_at_budget(rec: TrialRecord) -> float:
    t = metric(rec, "planning_time_s")
    if is_success(rec):
        return t
    budget = rec.time_limit_s
    if isinstance(budget, (int, float)) and not isinstance(budget, bool) and math.isfinite(budget):
        return float(budget)
    return t


def outcomes(records: Iterable[TrialRecord], *, metrics: Sequence[str]) -> dict[tuple, Outcome]:
    """One planner's trials collapsed to one `Outcome` per distinct problem (in first-seen order).

    Args:
        records: the trials of ONE planner.
        metrics: the metric names to collapse (see `suite.run.records.metric`).
    """
    groups: dict[tuple, list[TrialRecord]] = {}
    for r in records:
        groups.setdefault(problem_key(r), []).append(r)
    out = {}
    for key, recs in groups.items():
        ok = [r for r in recs if is_success(r)]
        values = {}
        for name in metrics:
            use = [r for r in ok if not is_cold(r)] if name in TIMES else ok
            vals = [v for v in (metric(r, name) for r in use) if math.isfinite(v)]
            values[name] = float(np.median(vals)) if vals else math.nan
        times = [t for t in map(_time_at_budget, [r for r in recs if not is_cold(r)]) if math.isfinite(t)]
        out[key] = Outcome(
            key=key,
            scene=scene_of(recs[0]),
            family=family_of(recs[0]),
            kind=str(recs[0].problem),
            trials=len(recs),
            successes=len(ok),
            metrics=values,
            time_to_solve_s=float(np.median(times)) if times else math.nan,
        )
    return out


def solved_count(group: Iterable[Outcome]) -> float | int:
    """How many problems were solved: each problem counts once, as the share of its trials solved
    (an int when every problem was tried once or solved in all or none of its trials)."""
    k = float(sum(o.solved for o in group))
    return int(k) if k.is_integer() else k


def common_subset(per_planner: dict[str, dict[tuple, Outcome]], name: str) -> set[tuple]:
    """The problems on which every planner has a finite value of a metric (all of them solved it)."""
    sets = [{k for k, o in oc.items() if math.isfinite(o.metrics.get(name, math.nan))} for oc in per_planner.values()]
    return set.intersection(*sets) if sets else set()


def wilson_interval(k: float, n: int, *, z: float = 1.959963984540054) -> tuple[float, float]:
    """The Wilson score interval of a binomial proportion k/n (95% by default); NaNs for n = 0.

    Unlike the normal approximation it stays inside [0, 1] and is not degenerate at 0/n or n/n.
    """
    if n <= 0:
        return math.nan, math.nan
    p = k / n
    den = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return max(0.0, centre - half), min(1.0, centre + half)


def cluster_bootstrap_median_ci(
    values: np.ndarray, clusters: Sequence[Any], *, rng: np.random.Generator, n_resamples: int, level: float = 0.95
) -> tuple[float, float]:
    """Percentile-bootstrap CI of the median of `values`, resampling whole clusters (scenes).

    Each resample draws as many clusters as there are, with replacement, and takes every value of
    the drawn clusters. With one value per cluster this is the ordinary bootstrap. NaNs if fewer
    than 2 values or 2 clusters: one scene cannot tell how much the median varies between scenes.
    """
    values = np.asarray(values, dtype=float)
    labels = {c: i for i, c in enumerate(dict.fromkeys(clusters))}
    if len(values) < 2 or len(labels) < 2:
        return math.nan, math.nan
    # A resample is the multiset of the drawn clusters' values: each value weighted by how often its
    # cluster was drawn. Its median is read off the sorted values and the cumulative weights (the
    # same number np.median gives on the concatenated values), for all resamples at once.
    order = np.argsort(values, kind="stable")
    sorted_values = values[order]
    cluster_of = np.array([labels[c] for c in clusters])[order]
    n_clusters = len(labels)
    drawn = rng.integers(0, n_clusters, size=(n_resamples, n_clusters))
    times_drawn = np.zeros((n_resamples, n_clusters), dtype=np.int64)
    np.add.at(times_drawn, (np.arange(n_resamples)[:, None], drawn), 1)
    cum = np.cumsum(times_drawn[:, cluster_of], axis=1)
    total = cum[:, -1]
    lower = np.argmax(cum > ((total - 1) // 2)[:, None], axis=1)
    upper = np.argmax(cum > (total // 2)[:, None], axis=1)
    medians = (sorted_values[lower] + sorted_values[upper]) / 2
    alpha = (1.0 - level) / 2
    lo, hi = np.percentile(medians, [100 * alpha, 100 * (1 - alpha)])
    return float(lo), float(hi)
