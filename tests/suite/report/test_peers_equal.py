"""Peers at equal check density: per-problem medians over seeds (a failure at the budget), the
median ratio and its bootstrap interval on known numbers, a setting read from its runs, and the
docs block."""

from __future__ import annotations

import json
import math

import pytest

from scenes.errors import SuiteError
from suite.report import peers_equal as pe
from suite.run.formats import MANIFEST_FORMAT_VERSION, RECORD_FORMAT_VERSION
from suite.run.records import TrialRecord


def _rec(planner: str, pid: str, *, time_s: float, ok: bool = True, scene: str = "s0", budget_s: float = 5.0,
         **extra) -> TrialRecord:
    return TrialRecord.from_json({"format_version": RECORD_FORMAT_VERSION, "planner": planner, "problem": "transit", "scene_seed": 0,
            "variant": "window", "can_id": 0, "problem_id": pid, "scene_key": scene, "time_limit_s": budget_s,
            "status": "success" if ok else "timeout", "planning_time_s": time_s, "warm": True, **extra})


def test_a_failure_counts_at_the_budget_and_seeds_give_their_median():
    recs = [_rec("rrt", "p1", time_s=0.2), _rec("rrt", "p1", time_s=4.9, ok=False), _rec("rrt", "p1", time_s=0.4),
            _rec("rrt", "p2", time_s=0.1, ok=False), _rec("rrt", "p2", time_s=0.1, ok=False), _rec("rrt", "p2", time_s=0.3)]
    assert pe.time_to_valid_s(recs[1]) == 5.0  # its budget, not the 4.9 s it ran
    assert pe.per_problem_medians(recs) == {("p1",): 0.4, ("p2",): 5.0}


def test_median_ratio_and_its_interval_on_known_numbers():
    # ratios 0.5, 1.0, 1.5: a resample's median is 0.5 or 1.5 with probability 7/27 each, 1.0 with 13/27,
    # so the 2.5% and 97.5% points are the extremes
    a = {("p1",): 1.0, ("p2",): 2.0, ("p3",): 3.0}
    b = {("p1",): 2.0, ("p2",): 2.0, ("p3",): 2.0}
    r = pe.median_ratio(a, b, resamples=10_000, seed=0)
    assert (r.median, r.problems, r.ci_low, r.ci_high) == (1.0, 3, 0.5, 1.5)
    # two problems: resample medians 0.2 (1/4), 0.3 (1/2), 0.4 (1/4)
    r2 = pe.median_ratio({("p",): 0.2, ("q",): 0.4}, {("p",): 1.0, ("q",): 1.0}, seed=3)
    assert r2.median == pytest.approx(0.3) and (r2.ci_low, r2.ci_high) == (0.2, 0.4)
    # every problem at the same ratio: no spread
    same = pe.median_ratio({(f"p{i}",): 0.6 * (i + 1) for i in range(8)}, {(f"p{i}",): i + 1.0 for i in range(8)})
    assert same.median == pytest.approx(0.6) and same.ci_low == pytest.approx(0.6) and same.ci_high == pytest.approx(0.6)
    # the bootstrap is seeded: the same numbers every time
    ratios = {(f"p{i}",): 0.1 * i + 0.05 for i in range(30)}
    ones = {k: 1.0 for k in ratios}
    assert pe.median_ratio(ratios, ones, seed=7) == pe.median_ratio(ratios, ones, seed=7)


def test_scene_interval_resamples_scenes_whole():
    # two scenes, every problem of a scene at one ratio: resampling scenes gives 0.5, 0.75 or 1.0
    a = {("p1",): 0.5, ("p2",): 0.5, ("p3",): 1.0, ("p4",): 1.0}
    b = {k: 1.0 for k in a}
    r = pe.median_ratio(a, b, clusters={("p1",): "s1", ("p2",): "s1", ("p3",): "s2", ("p4",): "s2"})
    assert (r.ci_scene_low, r.ci_scene_high) == (0.5, 1.0)


def test_different_problems_are_refused():
    with pytest.raises(SuiteError, match="different problems"):
        pe.median_ratio({("p1",): 1.0}, {("p2",): 1.0})


def test_verdict_against_the_target():
    def ratio(m, lo, hi):
        return pe.RatioSummary(median=m, problems=10, ci_low=lo, ci_high=hi, ci_scene_low=lo, ci_scene_high=hi)

    assert pe.verdict(ratio(0.5, 0.4, 0.7)) == "met"
    assert pe.verdict(ratio(1.2, 0.9, 1.5)) == "not met"
    assert pe.verdict(ratio(0.7, 0.5, 0.9)) == "median met, interval crosses 0.8"
    assert pe.verdict(ratio(0.85, 0.5, 0.9)) == "median not met, interval crosses 0.8"


def _write_run(run, *, seed: int, times: dict[str, list[float]], commit: str = "abc123") -> None:
    run.mkdir(parents=True)
    manifest = {"format_version": MANIFEST_FORMAT_VERSION, "git_commit": commit,
                "config": {"seed": seed, "dataset": "recycle-v3.1:test:family=window,kind=transit+return"}}
    (run / "manifest.json").write_text(json.dumps(manifest))
    lines = []
    for planner, ts in times.items():
        config = ({"range_rad": 1.0, "collision_check_step_rad": 0.01, "shortcut": True, "shortcut_max_iters": 100}
                  if planner == "roboplan-rrt" else
                  {"range_rad": 1.0, "resolution_rad": 0.01, "resolution_norm": "l2", "validate_resolution_rad": None,
                   "simplifier": "rope", "simplify_time_s": 0.1})
        for i, t in enumerate(ts):
            ok = t < 5.0
            lines.append(_rec(planner, f"p{i}", time_s=t, ok=ok, scene=f"s{i // 2}", planner_config=config,
                              certification={"verdict": "certified"} if ok else None,
                              metrics={"length_ratio": 2.0} if ok else {},
                              stats={"samples_per_edge": 99.5, "samples_per_edge_from": "counted" if planner == "rrt"
                                     else "computed", "solve_time_s": t * 0.9, "simplify_time_s": t * 0.1}))
    (run / "trials.jsonl").write_text("\n".join(json.dumps(r.to_json()) for r in lines) + "\n")


def test_a_setting_is_read_from_its_seed_runs(tmp_path):
    setting = tmp_path / "step-0.01-range-1"
    # 4 problems; rrt's per-problem medians over 3 seeds: 0.1, 0.2, 5 (2 failures), 0.4
    _write_run(setting / "seed-0", seed=0, times={"rrt": [0.1, 0.2, 5.0, 0.4], "roboplan-rrt": [0.2, 0.4, 1.0, 0.8]})
    _write_run(setting / "seed-1", seed=1, times={"rrt": [0.1, 0.3, 5.0, 0.4], "roboplan-rrt": [0.2, 0.4, 1.0, 0.8]})
    _write_run(setting / "seed-2", seed=2, times={"rrt": [0.2, 0.2, 0.5, 0.3], "roboplan-rrt": [0.2, 0.4, 1.0, 0.8]})
    r = pe.analyse_setting(setting, resamples=2000)
    assert r.seeds == (0, 1, 2) and r.problems == 4 and r.range_rad == 1.0
    # ratios 0.5, 0.5, 5.0, 0.5: median 0.5
    assert r.ratio.median == pytest.approx(0.5)
    assert r.a.check == r.b.check == "0.01 rad, l2"
    assert (r.a.recheck, r.a.post_processing, r.b.post_processing) == ("none", "rope", "PathShortcutter(100)")
    assert (r.a.trials, r.a.successes, r.a.solved_every_seed, r.a.certified) == (12, 10, 3, 10)
    assert r.a.time_s == pytest.approx(0.3)  # median of 0.1, 0.2, 5, 0.4
    assert (r.a.samples_per_edge, r.a.samples_per_edge_from, r.b.samples_per_edge_from) == (99.5, "counted", "computed")
    data = pe.as_json([r], resamples=2000, seed=0)
    table = pe.markdown(data["settings"])
    assert "| both 0.01 rad, l2 | 1 | 4 x 3 | 0.3 | 0.6 | 0.50 [" in table
    assert "| step-0.01-range-1 | `rrt` | 0.01 rad, l2 | none | rope | 10/12 | 10/10 | 2 | 99.5 (counted) |" in table


def test_a_seed_run_twice_or_an_incomplete_run_is_refused(tmp_path):
    twice = tmp_path / "twice"
    _write_run(twice / "a", seed=0, times={"rrt": [0.1], "roboplan-rrt": [0.2]})
    _write_run(twice / "b", seed=0, times={"rrt": [0.1], "roboplan-rrt": [0.2]})
    with pytest.raises(SuiteError, match="a run seed appears twice"):
        pe.analyse_setting(twice)
    partial = tmp_path / "partial"
    _write_run(partial / "seed-0", seed=0, times={"rrt": [0.1, 0.2], "roboplan-rrt": [0.2]})
    with pytest.raises(SuiteError, match="ran different problems .1 in one only.: an incomplete run"):
        pe.analyse_setting(partial)
    with pytest.raises(SuiteError, match="holds no runs"):
        pe.analyse_setting(tmp_path / "nothing")


def test_cli_prints_the_tables_and_writes_json(tmp_path, capsys):
    _write_run(tmp_path / "s" / "seed-0", seed=0, times={"rrt": [0.1, 0.2], "roboplan-rrt": [0.2, 0.4]})
    out = tmp_path / "analysis.json"
    assert pe.main([str(tmp_path / "s"), "--json", str(out), "--resamples", "500"]) == 0
    assert "| both 0.01 rad, l2 |" in capsys.readouterr().out
    data = json.loads(out.read_text())
    assert data["bootstrap"] == {"resamples": 500, "seed": 0, "level": 0.95}
    assert data["settings"][0]["ratio"]["median"] == pytest.approx(0.5)
    assert pe.main([str(tmp_path / "missing")]) == 2
    assert capsys.readouterr().err.startswith("error: ")


def test_docs_block_placeholder_table_and_dirty_refusal(tmp_path):
    assert "Not measured yet" in pe.docs_block(tmp_path)
    _write_run(tmp_path / "s" / "seed-0", seed=0, times={"rrt": [0.1, 0.2], "roboplan-rrt": [0.2, 0.4]})
    path = tmp_path / pe.ANALYSIS_JSON
    path.parent.mkdir(parents=True)
    data = pe.as_json([pe.analyse_setting(tmp_path / "s", resamples=200)], resamples=200, seed=0)
    path.write_text(json.dumps(data))
    assert pe.docs_block(tmp_path).startswith("| setting | range (rad) |")
    data["settings"][0]["commits"] = ["abc123+dirty"]
    path.write_text(json.dumps(data))
    with pytest.raises(SuiteError, match="uncommitted changes"):
        pe.docs_block(tmp_path)
    assert not math.isnan(data["settings"][0]["ratio"]["median"])


def test_suite_docs_writes_the_table_from_clean_runs_and_refuses_a_dirty_one(tmp_path):
    import shutil
    from pathlib import Path

    from suite.report import docs_blocks

    root = tmp_path
    (root / "docs").mkdir()
    shutil.copy(Path(__file__).resolve().parents[3] / "docs" / "peers.md", root / "docs" / "peers.md")
    # without an analysis the block is the placeholder (the committed page holds the measured table)
    docs_blocks.render(root, write=True, only=["peers-equal-table"])
    assert "_Not measured yet:" in (root / "docs" / "peers.md").read_text(encoding="utf-8")
    assert docs_blocks.render(root, write=False, only=["peers-equal-table"]) == []
    setting = root / "results" / "peers-equal" / "step-0.01-range-1"
    _write_run(setting / "seed-0", seed=0, times={"rrt": [0.1, 0.2], "roboplan-rrt": [0.2, 0.4]})
    rel = "results/peers-equal/step-0.01-range-1"
    data = pe.as_json([pe.analyse_setting(root / rel, resamples=200)], resamples=200, seed=0)
    data["settings"][0]["runs"] = [f"{rel}/seed-0"]  # as the driver names them, from the repository's root
    (root / pe.ANALYSIS_JSON).write_text(json.dumps(data))
    assert docs_blocks.render(root, write=True, only=["peers-equal-table"]) == ["docs/peers.md: peers-equal-table"]
    assert "| both 0.01 rad, l2 | 1 | 2 x 1 |" in (root / "docs" / "peers.md").read_text(encoding="utf-8")
    manifest = setting / "seed-0" / "manifest.json"
    manifest.write_text(json.dumps({**json.loads(manifest.read_text()), "git_commit": "abc123+dirty"}))
    with pytest.raises(docs_blocks.UnpublishableRun, match=f"{rel}/seed-0/manifest.json, which records a dirty tree"):
        docs_blocks.render(root, write=False, only=["peers-equal-table"])
