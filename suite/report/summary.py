"""The summary of a run: success rates, metric medians with IQR, failures by status, and paired
comparisons between planners, written as summary.md, summary.csv and paired.csv.

Everything here is computed from the saved trial records alone (see `suite.run.records`).
"""

from __future__ import annotations

import csv
import dataclasses
import itertools
import logging
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from tabulate import tabulate

from suite.run.records import (
    BACK_ON_PLATE,
    ELSEWHERE,
    NOT_ATTEMPTED,
    STATUSES,
    SUCCESS,
    fate_counts,
    is_success,
    metric,
    metric_values,
    planners_in,
    problem_key,
    problem_kinds_in,
    statuses_in,
)

log = logging.getLogger(__name__)

#: The metrics of the summary: record field -> column label (with unit).
SUMMARY_METRICS: dict[str, str] = {
    "planning_time_s": "planning time (s)",
    "path_length_rad": "path length (rad)",
    "smoothness": "smoothness",
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


# --- formatting ----------------------------------------------------------------------------------


def _num(v: float) -> str:
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
    return f"{_num(s.median)} [{_num(s.q1)}, {_num(s.q3)}]"


def _rate(g: GroupSummary) -> str:
    pct = f" ({100 * g.success_rate:.0f}%)" if g.n else ""
    return f"{g.successes}/{g.n}{pct}"


def _rows(groups: Sequence[GroupSummary], *, key: str | None) -> tuple[list[str], list[list[str]]]:
    headers = ["planner"] + ([key] if key else []) + ["success"] + list(SUMMARY_METRICS.values())
    rows = []
    for g in groups:
        row = [g.planner] + ([getattr(g, key)] if key else []) + [_rate(g)]
        rows.append(row + [_stat(g.metrics[m]) for m in SUMMARY_METRICS])
    return headers, rows


def summary_table(records: Sequence[dict[str, Any]], *, planners: Sequence[str] | None = None) -> str:
    """The per-planner table for the terminal: success k/n and median [IQR] of each metric."""
    if not records:
        return "no trial records"
    headers, rows = _rows(summarize(records, planners=planners), key=None)
    return tabulate(rows, headers=headers, tablefmt="simple")


def _failure_rows(groups: Sequence[GroupSummary], statuses: Sequence[str]) -> tuple[list[str], list[list[Any]]]:
    failures = [s for s in statuses if s != SUCCESS]
    headers = ["planner", "trials", "failed"] + failures
    rows = [
        [g.planner, g.n, g.n - g.successes] + [g.status_counts.get(s, 0) for s in failures] for g in groups
    ]
    return headers, rows


def _paired_rows(pairs: Sequence[PairedComparison]) -> tuple[list[str], list[list[Any]]]:
    headers = ["metric", "A - B", "n", "median diff", "95% CI", "Wilcoxon p"]
    rows = []
    for c in pairs:
        ci = "n/a" if not math.isfinite(c.ci_low) else f"[{_num(c.ci_low)}, {_num(c.ci_high)}]"
        p = "n/a" if not math.isfinite(c.p_value) else f"{c.p_value:.3g}"
        rows.append([SUMMARY_METRICS.get(c.metric, c.metric), f"{c.planner_a} - {c.planner_b}", c.n, _num(c.median_diff), ci, p])
    return headers, rows


def summary_markdown(
    records: Sequence[dict[str, Any]],
    *,
    pairs: Sequence[PairedComparison],
    planners: Sequence[str] | None = None,
    title: str = "Run summary",
) -> str:
    """summary.md: per-planner, per-kind (and per-variant) tables, failures and paired comparisons."""
    planners = list(planners) if planners is not None else planners_in(records)
    scenes = sorted({(int(r["scene_seed"]), str(r["variant"])) for r in records})
    problems = {problem_key(r) for r in records}
    md = [
        f"# {title}",
        "",
        f"{len(records)} trials: {len(planners)} planners ({', '.join(planners)}) on {len(problems)} "
        f"planning problems from {len(scenes)} scenes. Metrics are over successful trials only: "
        "median [first quartile, third quartile].",
        "",
        "## Per planner",
        "",
    ]
    md.append(tabulate(*reversed(_rows(summarize(records, planners=planners), key=None)), tablefmt="github"))
    md += ["", "## Failures by status", ""]
    groups = summarize(records, planners=planners)
    md.append(tabulate(*reversed(_failure_rows(groups, statuses_in(records))), tablefmt="github"))
    md += ["", "## Per planner and problem kind", ""]
    md.append(tabulate(*reversed(_rows(summarize(records, by="problem", planners=planners), key="problem")), tablefmt="github"))
    if len({r["variant"] for r in records}) > 1:
        md += ["", "## Per planner and scene variant", ""]
        md.append(
            tabulate(*reversed(_rows(summarize(records, by="variant", planners=planners), key="variant")), tablefmt="github")
        )
    md += [
        "",
        "## Paired comparisons",
        "",
        "Differences A - B on the problems both planners solved (paired by scene seed, variant, can "
        f"and problem kind): median, percentile-bootstrap 95% CI of the median ({N_RESAMPLES} "
        "resamples), two-sided Wilcoxon signed-rank p-value. Negative means A is lower.",
        "",
    ]
    md.append(tabulate(*reversed(_paired_rows(pairs)), tablefmt="github") if pairs else "(fewer than two planners)")
    return "\n".join(md) + "\n"


def _csv_rows(groups: Sequence[GroupSummary]) -> tuple[list[str], list[list[Any]]]:
    headers = ["planner", "problem", "variant", "n", "successes", "success_rate"]
    for m in SUMMARY_METRICS:
        headers += [f"{m}_n", f"{m}_median", f"{m}_q1", f"{m}_q3"]
    headers += [f"status_{s}" for s in STATUSES]
    rows = []
    for g in groups:
        row: list[Any] = [g.planner, g.problem, g.variant, g.n, g.successes, g.success_rate]
        for m in SUMMARY_METRICS:
            s = g.metrics[m]
            row += [s.n, s.median, s.q1, s.q3]
        row += [g.status_counts.get(s, 0) for s in STATUSES]
        rows.append(row)
    return headers, rows


def _write_csv(path: Path, headers: list[str], rows: list[list[Any]]) -> None:
    with path.open("w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(headers)
        for row in rows:
            w.writerow(["" if isinstance(v, float) and not math.isfinite(v) else v for v in row])


EXECUTION_INTRO = """## Execution in physics

Each planner's timed plans for every can of a scene, chained (approach, descend, close, lift,
transit, open, return) and run in a Drake simulation with contact (see suite/execution/).
Cans in bin / picked but back on the plate / elsewhere: where the cans ended. Execution stops at
the first can whose cycle was not fully planned; the cans from there on are "not attempted". Collisions: unintended contact episodes (robot with the scene or
with a can it was not picking, the carried can with the scene). Peak tracking: largest joint
error. Peak slip: largest motion of a carried can in the gripper. Clear time: median simulated
time until the last can was in the bin. Real-time factor: simulated / wall time (median).
"""


def execution_table(executions: Sequence[dict[str, Any]], *, planners: Sequence[str] | None = None,
                    tablefmt: str = "github") -> str:
    """Per planner: where the cans ended after physics execution, contacts, tracking and time.

    "fully planned" counts the scenes whose every problem was planned, and the cans recycled in
    those scenes: the figure that judges execution apart from planning failures.
    """
    planners = list(planners) if planners is not None else list(dict.fromkeys(e["planner"] for e in executions))
    headers = ["planner", "scenes", "cans in bin", "not attempted", "picked, on plate", "elsewhere",
               "fully planned: in bin",
               "collisions", "peak tracking (mrad)", "peak slip (mm)", "clear time (s)", "real-time factor", "errors"]
    rows = []
    for p in planners:
        runs = [e for e in executions if e["planner"] == p]
        ok = [e for e in runs if "error" not in e]
        if not runs:
            continue
        total = sum(e["cans_total"] for e in runs)
        in_bin = sum(e["cans_in_bin"] for e in ok)
        full = [e for e in ok if not e["stopped"] and e["cans_attempted"] == e["cans_total"]]
        full_total = sum(e["cans_total"] for e in full)
        full_bin = sum(e["cans_in_bin"] for e in full)
        clear = [e["clear_time_s"] for e in ok if e["clear_time_s"] is not None]
        fates = fate_counts(ok)
        rows.append([
            p, len(runs), f"{in_bin}/{total} ({100 * in_bin / max(total, 1):.0f}%)",
            fates[NOT_ATTEMPTED], fates[BACK_ON_PLATE], fates[ELSEWHERE],
            f"{full_bin}/{full_total} in {len(full)} scenes" if full else "-",
            sum(e["collisions"] for e in ok),
            _num(1e3 * max((e["peak_tracking_error_rad"] for e in ok), default=float("nan"))),
            _num(1e3 * max((e.get("peak_slip_m", float("nan")) for e in ok), default=float("nan"))),
            _num(float(np.median(clear))) if clear else "-",
            _num(float(np.median([e["real_time_factor"] for e in ok]))) if ok else "-",
            len(runs) - len(ok),
        ])
    return tabulate(rows, headers=headers, tablefmt=tablefmt)


def write_summary(
    run_dir: str | Path,
    records: Sequence[dict[str, Any]],
    *,
    planners: Sequence[str] | None = None,
    seed: int = 0,
    title: str | None = None,
    executions: Sequence[dict[str, Any]] = (),
) -> list[Path]:
    """Write summary.md, summary.csv (per planner, per planner x kind, per planner x variant) and paired.csv.

    Args:
        run_dir: the run directory to write into.
        records: the run's trial records.
        planners: planners in display order (default: order of appearance).
        seed: seeds the bootstrap's generator, so the written CIs are reproducible.
        title: the summary's heading (default: "Run summary: <run directory name>").
        executions: the run's physics execution records (execution.json), if it was executed.

    Returns:
        The written files.
    """
    run_dir = Path(run_dir)
    planners = list(planners) if planners is not None else planners_in(records)
    pairs = paired_comparisons(records, rng=np.random.default_rng(seed), planners=planners)
    md_path, csv_path, paired_path = run_dir / "summary.md", run_dir / "summary.csv", run_dir / "paired.csv"
    md = summary_markdown(records, pairs=pairs, planners=planners, title=title or f"Run summary: {run_dir.name}")
    if executions:
        md += "\n" + EXECUTION_INTRO + "\n" + execution_table(executions, planners=planners) + "\n"
    md_path.write_text(md, encoding="utf-8")
    groups = [
        *summarize(records, planners=planners),
        *summarize(records, by="problem", planners=planners),
        *summarize(records, by="variant", planners=planners),
    ]
    _write_csv(csv_path, *_csv_rows(groups))
    _write_csv(
        paired_path,
        ["metric", "planner_a", "planner_b", "n", "median_diff", "ci95_low", "ci95_high", "wilcoxon_p"],
        [[c.metric, c.planner_a, c.planner_b, c.n, c.median_diff, c.ci_low, c.ci_high, c.p_value] for c in pairs],
    )
    log.info("wrote %s, %s, %s", md_path, csv_path, paired_path)
    return [md_path, csv_path, paired_path]
