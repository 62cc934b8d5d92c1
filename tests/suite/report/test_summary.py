"""Reading trial records and the run summary: k/n, medians, IQR, failures, paired statistics."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

from scenes.errors import SuiteError
from suite.report.outcomes import cluster_bootstrap_median_ci
from suite.report.summary import write_summary
from suite.report.summary_stats import paired_comparisons, summarize, wilcoxon_p
from suite.report.summary_tables import summary_table
from suite.run.records import TrialRecord, metric, planners_in, problem_key, read_trials

Q0 = np.array([-1.57, 0.1, 0.0, -1.2, 0.0, 1.6, 0.0])
U = np.array([1.0, 2.0, 0.0, -2.0, 0.0, 0.0, 4.0]) / 5.0  # a unit direction in joint space


def straight(length_rad: float) -> np.ndarray:
    """A real two-waypoint joint path of the given length (rad)."""
    return np.vstack([Q0, Q0 + length_rad * U])


def record(planner, *, seed=0, can=0, kind="transit", status="success", time_s=0.1, length_rad=None,
           clearance_m=0.05, variant="open"):
    rec = {
        "trial_id": f"{planner}-{seed}-{can}-{kind}-{variant}", "planner": planner, "planner_config": {},
        "scene_seed": seed, "variant": variant, "can_id": can, "problem": kind, "status": status,
        "planning_time_s": time_s, "q_start": Q0.tolist(), "q_goal": None, "path": None, "metrics": {},
        "stats": {}, "seed": 1, "held": False, "scene_key": f"k{seed}", "time_limit_s": 5.0,
    }
    if status == "success":
        path = straight(length_rad)
        seg = np.diff(path, axis=0)
        rec["path"] = path.tolist()
        rec["q_goal"] = path[-1].tolist()
        rec["metrics"] = {
            "path_length_rad": float(np.sum(np.linalg.norm(seg, axis=1))),  # = length_rad
            "smoothness": 0.0,  # a straight line does not turn
            "clearance_min_m": clearance_m,
            "duration_s": float(np.max(np.abs(seg)) / 1.5),  # slowest joint at 1.5 rad/s
        }
    return TrialRecord.from_json(rec)


def write_jsonl(path, records, tail=""):
    path.write_text("".join(json.dumps(r.to_json()) + "\n" for r in records) + tail)
    return path


# --- reading ---------------------------------------------------------------------------------------


def test_read_trials_ignores_a_torn_last_line(tmp_path):
    recs = [record("rrt", can=i, length_rad=1.0 + i) for i in range(3)]
    torn = json.dumps(record("rrt", can=9, length_rad=2.0).to_json())[:57]  # the write was cut off
    path = write_jsonl(tmp_path / "trials.jsonl", recs, tail=torn)
    got = read_trials(path)
    assert [r.can_id for r in got] == [0, 1, 2]
    assert read_trials(tmp_path) == got  # the run directory works too
    assert metric(got[2], "path_length_rad") == pytest.approx(3.0)


def test_read_trials_names_a_bad_line_that_is_not_last(tmp_path):
    recs = [json.dumps(record("ik", can=i, length_rad=1.0).to_json()) for i in range(3)]
    (tmp_path / "trials.jsonl").write_text(recs[0] + "\n" + recs[1][:30] + "\n" + recs[2] + "\n")
    with pytest.raises(SuiteError, match="line 2 is not valid JSON"):
        read_trials(tmp_path / "trials.jsonl")


def test_read_trials_rejects_objects_without_the_record_fields(tmp_path):
    (tmp_path / "trials.jsonl").write_text(json.dumps(record("ik", length_rad=1.0).to_json()) + "\n{\"planner\": \"ik\"}\n\n")
    with pytest.raises(SuiteError, match="line 2 lacks the field"):
        read_trials(tmp_path / "trials.jsonl")


def test_read_trials_missing_file_is_a_suite_error(tmp_path):
    with pytest.raises(SuiteError, match="cannot read trial records"):
        read_trials(tmp_path / "nope.jsonl")


def test_metric_and_planner_order():
    ok, failed = record("trajopt", length_rad=0.7), record("ik", status="no_solution")
    assert metric(ok, "path_length_rad") == pytest.approx(0.7)
    assert math.isnan(metric(failed, "path_length_rad"))
    assert metric(failed, "planning_time_s") == pytest.approx(0.1)
    assert planners_in([ok, failed]) == ["trajopt", "ik"]
    assert planners_in([ok, failed], {"config": {"planners": ["ik", "rrt", "trajopt"]}}) == ["ik", "trajopt"]
    assert problem_key(ok) == (0, "open", 0, "transit")


# --- summary ---------------------------------------------------------------------------------------


def five_rrt_trials():
    """4 successes (lengths 1, 2, 3, 4 rad) and one timeout, across two problem kinds."""
    return [
        record("rrt", can=0, kind="approach", length_rad=1.0, time_s=0.2),
        record("rrt", can=1, kind="approach", length_rad=2.0, time_s=0.4),
        record("rrt", can=0, kind="transit", length_rad=3.0, time_s=0.6),
        record("rrt", can=1, kind="transit", length_rad=4.0, time_s=0.8),
        record("rrt", can=2, kind="transit", status="timeout", time_s=5.0),
    ]


def test_summary_counts_medians_and_iqr():
    (g,) = summarize(five_rrt_trials())
    assert (g.successes, g.n) == (4, 5)
    assert g.success_rate == pytest.approx(0.8)
    assert g.status_counts == {"success": 4, "timeout": 1}
    s = g.metrics["path_length_rad"]
    # numpy's linear quartiles of 1, 2, 3, 4: 1.75, 2.5, 3.25
    assert (s.n, s.q1, s.median, s.q3) == (4, pytest.approx(1.75), pytest.approx(2.5), pytest.approx(3.25))
    # planning time over the successful trials only: 0.2, 0.4, 0.6, 0.8 (the timeout's 5 s excluded)
    t = g.metrics["planning_time_s"]
    assert (t.median, t.q1, t.q3) == (pytest.approx(0.5), pytest.approx(0.35), pytest.approx(0.65))
    assert g.metrics["duration_s"].median == pytest.approx(2.5 * 0.8 / 1.5)  # largest joint step 0.8 * L


def test_summary_by_problem_kind():
    groups = summarize(five_rrt_trials(), by="problem")
    assert [(g.problem, g.successes, g.n) for g in groups] == [("approach", 2, 2), ("transit", 2, 3)]
    assert groups[1].metrics["path_length_rad"].median == pytest.approx(3.5)
    assert groups[1].status_counts == {"success": 2, "timeout": 1}


def test_summary_table_shows_k_of_n_and_medians_in_80_columns():
    text = summary_table(five_rrt_trials() + [record("ik", status="ik_failed")])
    line = next(ln for ln in text.splitlines() if ln.startswith("rrt"))
    assert "4/5 (80% [38, 96])" in line
    ik_line = next(ln for ln in text.splitlines() if ln.startswith("ik"))
    assert "0/1 (0% [0, 79])" in ik_line and "n/a" in ik_line
    assert max(len(ln) for ln in text.splitlines()) <= 80  # it fits a terminal
    assert "summary.md" in text and "--wide" in text  # and says where the rest is


def test_wide_summary_table_has_every_metric_with_quartiles():
    from suite.report.summary_stats import SUMMARY_METRICS

    records = five_rrt_trials()
    narrow, wide = summary_table(records), summary_table(records, wide=True)
    header = "\n".join(wide.splitlines()[:4])
    for label in SUMMARY_METRICS.values():
        assert label.split("\n")[0] in header, label
    assert "[" in next(ln for ln in wide.splitlines() if ln.startswith("rrt")).split("80%")[1]  # quartiles
    assert max(len(ln) for ln in wide.splitlines()) > max(len(ln) for ln in narrow.splitlines())
    # the lines under the table are the narrow table's, every planner's verdicts included
    verdicts = next(ln for ln in narrow.split("\n\n")[0].splitlines() if ln.startswith("Exact verdict"))
    assert verdicts in wide and "rrt" in verdicts


# --- paired statistics -----------------------------------------------------------------------------


def paired_example():
    """rrt and ik on 7 problems of 7 scenes: rrt solves 7, ik 6; rrt is longer by 0.1 .. 0.6 rad on the shared 6."""
    recs = []
    for i in range(6):
        recs.append(record("ik", seed=i, length_rad=1.0 + i, time_s=0.05))
        recs.append(record("rrt", seed=i, length_rad=1.0 + i + 0.1 * (i + 1), time_s=0.5))
    recs.append(record("rrt", seed=6, length_rad=9.0))
    recs.append(record("ik", seed=6, status="ik_failed"))
    return recs


def test_paired_comparison_known_example():
    pairs = paired_comparisons(paired_example(), rng=np.random.default_rng(0), metrics=["path_length_rad"],
                               planners=["ik", "rrt"])
    (c,) = pairs
    assert (c.planner_a, c.planner_b, c.n) == ("ik", "rrt", 6)  # the problem ik failed does not pair
    assert c.median_diff == pytest.approx(-0.35)  # median of -0.1 .. -0.6
    # every difference has the same sign: the exact two-sided p is 2 / 2^6
    assert c.p_value == pytest.approx(2 / 64)
    assert -0.6 <= c.ci_low <= c.median_diff <= c.ci_high <= -0.1
    again = paired_comparisons(paired_example(), rng=np.random.default_rng(0), metrics=["path_length_rad"],
                               planners=["ik", "rrt"])
    assert again == pairs  # seeded: the same CI


def test_paired_small_and_degenerate_cases():
    assert math.isnan(wilcoxon_p(np.array([0.3])))
    assert wilcoxon_p(np.zeros(5)) == 1.0
    lo, hi = cluster_bootstrap_median_ci(np.array([0.3]), ["a"], rng=np.random.default_rng(1), n_resamples=100)
    assert math.isnan(lo) and math.isnan(hi)
    lo, hi = cluster_bootstrap_median_ci(np.full(4, 0.25), list("abcd"), rng=np.random.default_rng(1),
                                         n_resamples=100)
    assert lo == hi == pytest.approx(0.25)
    # no problem solved by both: n = 0, everything n/a
    recs = [record("ik", can=0, length_rad=1.0), record("rrt", can=0, status="timeout")]
    (c,) = paired_comparisons(recs, rng=np.random.default_rng(0), metrics=["path_length_rad"])
    assert c.n == 0 and math.isnan(c.median_diff) and math.isnan(c.p_value)


def test_write_summary_files(tmp_path):
    recs = paired_example()
    written = write_summary(tmp_path, recs, seed=3)
    assert [p.name for p in written] == ["summary.md", "summary.json", "summary.csv", "paired.csv"]
    md = (tmp_path / "summary.md").read_text()
    assert "6/7 (86% [49, 97])" in md and "7/7 (100% [65, 100])" in md
    assert "## Paired comparisons" in md and "ik - rrt" in md
    assert "ik_failed" in md  # the failure breakdown
    rows = list(csv.DictReader((tmp_path / "summary.csv").open()))
    ik_all = next(r for r in rows if r["planner"] == "ik" and r["problem"] == "all" and r["variant"] == "all")
    assert (ik_all["n"], ik_all["successes"], ik_all["status_ik_failed"]) == ("7", "6", "1")
    assert float(ik_all["path_length_rad_median"]) == pytest.approx(3.5)
    paired = list(csv.DictReader((tmp_path / "paired.csv").open()))
    length = next(r for r in paired if r["metric"] == "path_length_rad")
    assert length["n"] == "6" and float(length["median_diff"]) == pytest.approx(-0.35)
    assert float(length["wilcoxon_p"]) == pytest.approx(2 / 64)


def test_every_executed_can_has_exactly_one_fate():
    from suite.execution.execution_records import (
        BACK_ON_PLATE,
        BIN,
        ELSEWHERE,
        NOT_ATTEMPTED,
        ExecutionCan,
        ExecutionRecord,
        fate_counts,
    )

    cans = [ExecutionCan(0, True, "bin"), ExecutionCan(1, True, "plate"), ExecutionCan(2, True, "elsewhere"),
            ExecutionCan(3, False, "plate"),
            ExecutionCan(4, False, "elsewhere")]  # knocked off the plate before its turn
    counts = fate_counts([ExecutionRecord("rrt", 0, "open", cans_total=5, cans=cans)])
    assert counts == {BIN: 1, BACK_ON_PLATE: 1, ELSEWHERE: 2, NOT_ATTEMPTED: 1}
    assert sum(counts.values()) == len(cans)


def test_time_medians_leave_out_cold_trials():
    """A worker's first trial of a planner (warm: False) is out of every time median, in the
    per-problem collapse and in time to solve; its success and other metrics count."""
    from suite.report.outcomes import outcomes

    base = TrialRecord(planner="rrt", status="success", problem="transit", scene_seed=1, variant="wall", can_id=0,
                       time_limit_s=5.0, metrics={"path_length_rad": 1.0})
    recs = [base.with_(problem_id="a", planning_time_s=9.0, warm=False),
            base.with_(problem_id="a", planning_time_s=1.0, warm=True),
            base.with_(problem_id="b", planning_time_s=7.0, warm=False),
            base.with_(problem_id="c", planning_time_s=2.0)]  # a record from before the flag: warm
    by_id = {o.key: o for o in outcomes(recs, metrics=("planning_time_s", "path_length_rad")).values()}
    times = sorted(t for o in by_id.values() if (t := o.metrics["planning_time_s"]) == t)  # NaN != NaN
    assert times == [1.0, 2.0]  # problem b's only trial was cold: no time
    assert all(o.successes >= 1 and o.metrics["path_length_rad"] == 1.0 for o in by_id.values())
    assert sorted(o.time_to_solve_s for o in by_id.values() if o.time_to_solve_s == o.time_to_solve_s) == [1.0, 2.0]


def test_the_time_attribution_plot_is_drawn_only_when_a_record_attributes(tmp_path):
    from suite.report.plots_attribution import plot_time_attribution

    base = TrialRecord(planner="rrt", status="success", problem="transit", scene_seed=1, variant="wall", can_id=0,
                       time_limit_s=5.0, warm=True, planning_time_s=1.0)
    counted = base.with_(planner="rrt", problem_id="a", attribution={"queries": 100, "query_s": 0.8, "other_s": 0.2,
                                                                     "query_share": 0.8, "s_per_query": 0.008})
    other = base.with_(planner="trajopt", problem_id="a")
    assert plot_time_attribution([other], planners=["trajopt"], path=tmp_path / "none.png") is None
    p = plot_time_attribution([counted, other], planners=["rrt", "trajopt"], path=tmp_path / "att.png")
    assert p is not None and p.stat().st_size > 5_000


def test_best_known_agreement_counts_equal_paths_and_lists_certified_shorter_ones(tmp_path):
    from suite.report.summary_tables import best_known_agreement

    def with_best(rec, best, verdict="certified", pid="p"):
        return rec.with_(reference_length_rad=best, problem_id=pid, certification={"verdict": verdict})

    recs = [with_best(record("a", seed=0, length_rad=1.0), 1.0005, pid="equal"),  # within 0.1%
            with_best(record("a", seed=1, length_rad=0.5), 1.0, pid="shorter"),  # certified, half as long
            with_best(record("a", seed=2, length_rad=0.5), 1.0, verdict="collision", pid="hugging"),  # not certified
            with_best(record("a", seed=3, length_rad=1.2), 1.0, pid="longer"),
            with_best(record("a", seed=4, status="timeout"), 1.0, pid="failed"),
            record("a", seed=5, length_rad=1.0)]  # no best known
    a = best_known_agreement(recs, "a")
    assert a["successes"] == 4 and a["equal"] == 1
    assert a["beaten"] == [{"problem_id": "shorter", "length_rad": pytest.approx(0.5), "best_known_rad": 1.0,
                            "ratio": 0.5}]
    write_summary(tmp_path, recs)
    assert json.loads((tmp_path / "summary.json").read_text())["planners"]["a"]["best_known"]["equal"] == 1
    assert "shorter (0.500)" in (tmp_path / "summary.md").read_text()


def test_search_and_simplification_are_reported_apart_for_ompl_planners():
    """OMPL's Benchmark reports solve and simplify time and length before and after apart: so does
    the summary, with each planner's post-processing named from its config."""
    from suite.report.summary_search import post_processing, search_rows, search_summary

    recs = []
    for i, (solve, simp, before, after) in enumerate([(0.01, 0.002, 4.0, 2.0), (0.03, 0.004, 6.0, 3.0),
                                                      (0.02, 0.003, 5.0, 4.0)]):
        r = record("rrt", seed=i, length_rad=after, time_s=solve + simp)
        r.planner_config = {"simplifier": "rope", "simplify_time_s": 0.1}
        r.stats = {"solve_time_s": solve, "simplify_time_s": simp, "length_before_rad": before,
                      "length_after_rad": after}
        recs.append(r)
    recs.append(record("trajopt", seed=0, length_rad=1.0, time_s=0.3))
    s = search_summary(recs, "rrt")
    assert s["trials"] == 3 and s["solve_time_s"] == pytest.approx(0.02) and s["simplify_time_s"] == pytest.approx(0.003)
    assert (s["length_before_rad"], s["length_after_rad"]) == (5.0, 3.0)
    assert s["length_kept"] == pytest.approx(0.5)  # the median of 0.5, 0.5, 0.8
    assert search_summary(recs, "trajopt") is None
    headers, rows = search_rows(recs, ["rrt", "trajopt"])
    assert [r[0] for r in rows] == ["rrt"] and "ropeShortcutPath" in rows[0][1]
    assert post_processing({"simplifier": "rope+full", "simplify_time_s": 0.1}).startswith("rope shortcut, then")
    assert post_processing({"simplifier": "rope", "simplify_time_s": 0.0}) == "none"
    assert post_processing({"shortcut": True, "shortcut_max_iters": 100}) == "roboplan PathShortcutter (100 random shortcuts)"
    assert post_processing({"num_control_points": 10}) == "none"
    from suite.report.summary import summary_markdown

    md = summary_markdown(recs, pairs=[], planners=["rrt", "trajopt"])
    assert "## Search and simplification (OMPL planners)" in md
