"""Statistics over distinct problems: Wilson intervals, repeats counted once, the common subset,
success-aware time, scene-clustered bootstrap, summary.json and the few-problems flag."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from suite.report.outcomes import cluster_bootstrap_median_ci, outcomes, wilson_interval
from suite.report.summary import write_summary
from suite.report.summary_stats import (
    common_subset_stats,
    paired_comparisons,
    summarize,
)
from suite.report.summary_tables import composition, summary_table
from tests.suite.report.test_summary import record


def test_wilson_interval_known_values():
    # Wilson (1927) score interval, z = 1.96: textbook values
    assert wilson_interval(5, 10) == pytest.approx((0.2366, 0.7634), abs=1e-4)
    assert wilson_interval(0, 10) == pytest.approx((0.0, 0.2775), abs=1e-4)  # not degenerate at 0/n
    assert wilson_interval(10, 10) == pytest.approx((0.7225, 1.0), abs=1e-4)
    lo, hi = wilson_interval(0, 0)
    assert math.isnan(lo) and math.isnan(hi)


def test_repeated_problem_counts_once():
    # one problem tried 10 times (9 solved) and 1 other problem solved once: 2 distinct problems
    recs = [record("rrt", seed=0, length_rad=1.0) for _ in range(9)]
    recs += [record("rrt", seed=0, status="timeout"), record("rrt", seed=1, length_rad=3.0)]
    (g,) = summarize(recs)
    assert (g.n, g.trials) == (2, 11)
    assert g.successes == pytest.approx(1.9)  # 0.9 of the repeated problem + 1
    assert g.metrics["path_length_rad"].n == 2  # one value per problem, not ten
    assert g.metrics["path_length_rad"].median == pytest.approx(2.0)
    assert "1.9/2" in summary_table(recs)


def test_duplicates_do_not_inflate_paired_n():
    recs = []
    for _ in range(12):  # the same problem twelve times, as in the old default compare
        recs += [record("ik", seed=0, length_rad=1.0), record("rrt", seed=0, length_rad=2.0)]
    (c,) = paired_comparisons(recs, rng=np.random.default_rng(0), metrics=["path_length_rad"])
    assert (c.n, c.scenes) == (1, 1) and c.few
    assert math.isnan(c.p_value) and math.isnan(c.ci_low)


def test_common_subset_removes_survivorship():
    # ik solves only the two easy (short) problems; rrt solves all four
    recs = [record("ik", seed=0, length_rad=1.0), record("ik", seed=1, length_rad=1.0),
            record("ik", seed=2, status="no_solution"), record("ik", seed=3, status="no_solution")]
    recs += [record("rrt", seed=i, length_rad=L) for i, L in enumerate([1.2, 1.2, 5.0, 6.0])]
    own = {g.planner: g.metrics["path_length_rad"].median for g in summarize(recs)}
    assert own == {"ik": pytest.approx(1.0), "rrt": pytest.approx(3.1)}  # rrt looks 3x worse on its own
    common = common_subset_stats(recs, metrics=["path_length_rad"])["path_length_rad"]
    assert common["ik"].n == common["rrt"].n == 2
    assert common["rrt"].median == pytest.approx(1.2)  # on the same problems it is 1.2x


def test_time_to_solve_counts_failures_at_the_budget():
    recs = [record("rrt", seed=0, length_rad=1.0, time_s=0.1), record("rrt", seed=1, length_rad=1.0, time_s=0.3),
            record("rrt", seed=2, status="timeout", time_s=7.0), record("rrt", seed=3, status="no_solution", time_s=0.2)]
    (g,) = summarize(recs)
    assert g.metrics["planning_time_s"].median == pytest.approx(0.2)  # successes only: flattering
    assert g.time_to_solve.n == 4
    assert g.time_to_solve.median == pytest.approx((0.3 + 5.0) / 2)  # 0.1, 0.3, 5 (budget), 5 (budget)
    (o,) = outcomes([recs[2]], metrics=["planning_time_s"]).values()
    assert o.time_to_solve_s == 5.0 and o.solved == 0


def test_cluster_bootstrap_resamples_scenes():
    rng = np.random.default_rng(0)
    # two scenes: one holds ten values of 1, the other ten of 3; the median jumps with the scene drawn
    values = np.array([1.0] * 10 + [3.0] * 10)
    scenes = ["a"] * 10 + ["b"] * 10
    lo, hi = cluster_bootstrap_median_ci(values, scenes, rng=rng, n_resamples=500)
    assert (lo, hi) == (1.0, 3.0)
    # an ordinary bootstrap over 20 "independent" values would claim a far narrower interval
    lo_i, hi_i = cluster_bootstrap_median_ci(values, list(range(20)), rng=rng, n_resamples=500)
    assert hi_i - lo_i <= hi - lo
    lo1, hi1 = cluster_bootstrap_median_ci(values, ["a"] * 20, rng=rng, n_resamples=50)
    assert math.isnan(lo1) and math.isnan(hi1)  # one scene: no between-scene variation to estimate


def test_summary_json_schema_and_few_problem_flag(tmp_path):
    recs = [record("ik", seed=i, length_rad=1.0 + i) for i in range(5)]
    recs += [record("rrt", seed=i, length_rad=2.0 + i) for i in range(4)] + [record("rrt", seed=4, status="timeout")]
    write_summary(tmp_path, recs, seed=0)
    data = json.loads((tmp_path / "summary.json").read_text())
    assert data["distinct_problems"] == 5 and data["few_problems"] is True
    rrt = data["planners"]["rrt"]
    assert rrt["success"]["k"] == 4 and rrt["success"]["n"] == 5 and rrt["success"]["rate"] == pytest.approx(0.8)
    assert rrt["success"]["ci95"] == pytest.approx(list(wilson_interval(4, 5)))
    assert set(rrt["metrics"]["path_length_rad"]) == {"median", "q1", "q3", "n"}
    assert rrt["common_subset"]["path_length_rad"] == {"median": pytest.approx(3.5), "n": 4}
    assert rrt["by_family"]["open"]["success"]["n"] == 5
    assert rrt["metrics"]["length_ratio"]["median"] is None  # NaN is written as null
    (pair,) = [p for p in data["paired"] if p["metric"] == "path_length_rad"]
    assert (pair["a"], pair["b"], pair["n"], pair["few"]) == ("ik", "rrt", 4, True)
    md = (tmp_path / "summary.md").read_text()
    assert "WARNING: fewer than 20 distinct problems" in md and "n < 20: too few" in md
    assert "## On the problems every planner solved" in md


def test_no_warning_with_enough_problems():
    recs = [record("rrt", seed=i, length_rad=1.0) for i in range(20)]
    assert "WARNING" not in composition(recs)
