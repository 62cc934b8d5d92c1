"""Tuning: the documented search, the choice rule, and tuned settings as every run's defaults."""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import pytest

from planners.registry import BUILTIN, planner_class
from planners.tuned import objective, search_space, tuned_settings
from scenes.errors import SuiteError
from suite.cli.tune import grid, search_exclude
from suite.problems.dataset import tuning_problems
from suite.report.tuning import (
    CandidateResult,
    choose,
    choose_explained,
    differs,
    evaluate,
    paired_ratio,
    weak_families,
)
from suite.run.records import TrialRecord
from suite.run.trial import make_config
from tests.suite.report.test_summary import record


@pytest.mark.parametrize("planner", sorted(BUILTIN))
def test_every_search_starts_at_the_class_defaults(planner):
    try:
        cls = planner_class(planner)
    except ImportError as exc:  # e.g. an optional dependency
        pytest.skip(str(exc))
    except SuiteError as exc:  # a search for a planner this installation does not register
        pytest.skip(str(exc))
    defaults = {f.name: f.default for f in dataclasses.fields(cls.Config)}
    space = search_space(planner)
    assert space, f"{planner}: every shipped planner declares its search next to its config"
    assert set(space) <= set(defaults), f"{planner}: unknown settings in its search"
    assert {k: v[0] for k, v in space.items()} == {k: defaults[k] for k in space}
    assert grid(planner)[0] == {k: v[0] for k, v in space.items()}
    assert math.prod(len(v) for v in space.values()) <= 8  # small, as documented
    excluded = [c for c in itertools.product(*space.values())
                if any(all(dict(zip(space, c))[k] == v for k, v in rule.items()) for rule, _ in search_exclude(planner))]
    assert len(grid(planner)) == math.prod(len(v) for v in space.values()) - len(excluded)
    assert all(why for _, why in search_exclude(planner))  # each exclusion says why
    assert objective(planner) in ("time", "length")


def _result(solved, time_s, ratio, by_family=None):
    return CandidateResult(settings={}, problems=10, solved=solved, by_family=by_family or {},
                           time_to_solve_median_s=time_s, planning_time_median_s=time_s,
                           length_ratio_common_median=ratio)


def test_choice_rule_success_first_then_the_objective_then_the_other_metric():
    results = [_result(8, 0.1, 1.5), _result(9, 0.9, 1.9), _result(9, 0.3, 1.2), _result(9, 0.3, 1.2)]
    assert choose(results, objective="time", weighting="pooled") == 2  # most solved, then fastest, then the earlier
    assert choose(results, objective="length", weighting="pooled") == 2
    assert choose([_result(9, 0.3, 1.4), _result(9, 0.9, 1.1)], objective="length", weighting="pooled") == 1
    assert choose([_result(9, math.nan, math.nan), _result(9, 0.5, 1.3)], objective="time", weighting="pooled") == 1
    # within the margin (1% in length, 10% in time) the objective ties, and the other metric decides
    assert choose([_result(9, 0.3, 1.005), _result(9, 0.2, 1.0)], objective="length", weighting="pooled") == 1
    assert choose([_result(9, 0.3, 1.005), _result(9, 0.3, 1.0)], objective="length", weighting="pooled") == 0
    assert choose([_result(9, 0.3, 1.02), _result(9, 0.1, 1.0)], objective="length", weighting="pooled") == 1
    assert choose([_result(9, 0.105, 1.0), _result(9, 0.1, 1.0)], objective="time", weighting="pooled") == 0
    assert choose([_result(9, 0.105, 1.0), _result(9, 0.1, 1.2)], objective="time", weighting="pooled") == 0
    # no absolute band: milliseconds differ like seconds do (the 5 ms band let list order choose)
    assert choose([_result(9, 0.003, 1.0), _result(9, 0.002, 1.0)], objective="time", weighting="pooled") == 1
    # tied on both metrics: list order (the defaults first)
    assert choose([_result(9, 0.1, 1.0), _result(9, 0.1, 1.0)], objective="time", weighting="pooled") == 0
    assert choose([_result(9, 0.105, 1.0), _result(9, 0.1, 1.005)], objective="time", weighting="pooled") == 0
    explained = choose_explained([_result(9, 0.105, 1.0), _result(9, 0.1, 1.005)], objective="time", weighting="pooled")
    assert explained.decided_by == "list order (tied on both metrics)"


def test_the_issue_rrt_table_chooses_the_shorter_of_the_tied_fastest():
    """rrt's tune table (issue 50): four candidates solve all; three within the old 5 ms band.
    {1.0, rope} and {0.5, rope} tie on time; {0.5, rope} is 1.6x shorter and must win."""
    def fam(time_s, ratio):
        return dataclasses.replace(_result(115, time_s, ratio), family_solved_mean=1.0,
                                   family_time_to_solve_median_s=time_s, family_length_ratio_common_median=ratio)

    rows = [fam(0.0022, 2.30), fam(0.0021, 1.46), fam(0.0052, 1.48), fam(0.0090, 1.13)]
    explained = choose_explained(rows, objective="time")
    assert explained.index == 1 and explained.decided_by == "other metric"
    assert explained.objective_tied == (0, 1)


def _paired(times, lengths, family="wall"):
    """A candidate with per-problem figures (one scene per problem)."""
    per = {(i,): (family if isinstance(family, str) else family[i], (f"s{i}",), t, l)
           for i, (t, l) in enumerate(zip(times, lengths))}
    fam_t = float(np.median(times))
    return dataclasses.replace(_result(len(times), fam_t, float(np.median(lengths))), per_problem=per,
                               family_solved_mean=1.0, family_time_to_solve_median_s=fam_t,
                               family_length_ratio_common_median=float(np.median(lengths)))


def test_a_difference_within_the_paired_noise_is_a_tie_and_a_consistent_one_is_not():
    rng = np.random.default_rng(5)
    base = rng.uniform(0.01, 0.1, 60)
    lengths = np.full(60, 1.5)
    # b is 30% slower on half the problems and 30% faster on the other half: medians differ, no real difference
    noisy = base * np.where(np.arange(60) % 2 == 0, 1.3, 1 / 1.3)
    a, b = _paired(base, lengths), _paired(noisy * 1.15, lengths * 0.8)
    pr = paired_ratio(a, b, metric="time")
    assert pr.problems == 60 and pr.lo < 1.0 < pr.hi
    assert not differs(a, b, metric="time")
    # consistently 20% slower on every problem: a real difference beyond the margin
    c = _paired(base * 1.2, lengths * 0.8)
    pr = paired_ratio(a, c, metric="time")
    assert pr.ratio == pytest.approx(1.2) and pr.lo > 1.0
    assert differs(a, c, metric="time")
    # consistently 5% slower: real, but inside the 10% margin
    assert not differs(a, _paired(base * 1.05, lengths), metric="time")
    # a time tie goes to the shorter paths
    assert choose([a, b], objective="time") == 1
    assert choose([a, c], objective="time") == 0


def test_the_bootstrap_keeps_family_weights_and_is_seeded():
    fams = ["wall"] * 30 + ["window"] * 6
    times = np.linspace(0.01, 0.05, 36)
    a = _paired(times, np.ones(36), family=fams)
    b = _paired(times * np.r_[np.ones(30), np.full(6, 2.0)], np.ones(36), family=fams)
    family = paired_ratio(a, b, metric="time", weighting="family")
    pooled = paired_ratio(a, b, metric="time", weighting="pooled")
    assert family.ratio == pytest.approx(math.sqrt(2.0))  # median of the two families' medians (log 1 and log 2)
    assert pooled.ratio == pytest.approx(1.0)  # 30 wall problems outvote 6 window ones
    assert paired_ratio(a, b, metric="time") == family  # same records, same interval


def test_weak_family_is_flagged_only_when_another_candidate_does_better():
    a = _result(5, 0.1, 1.0, {"window": (1, 4), "wall": (4, 6)})
    b = _result(4, 0.1, 1.0, {"window": (3, 4), "wall": (1, 6)})
    assert weak_families([a, b], chosen=0) == ["window"]
    assert weak_families([a, b], chosen=1) == ["wall"]
    assert weak_families([a], chosen=0) == []  # nothing documented does better


def test_a_candidate_weak_where_another_does_better_is_out_of_the_choice():
    # ik on recycle-v2's tune split: a tie in problems solved, the faster one weaker on window
    slow = _result(67, 0.196, 1.43, {"window": (8, 31), "clutter": (14, 24)})
    fast = _result(67, 0.149, 1.46, {"window": (6, 31), "clutter": (15, 24)})
    assert choose([slow, fast], objective="time", weighting="pooled") == 0
    # when every candidate is weak somewhere, the plain rule decides
    a = _result(5, 0.2, 1.0, {"window": (1, 4), "wall": (4, 6)})
    b = _result(4, 0.1, 1.0, {"window": (3, 4), "wall": (1, 6)})
    assert choose([a, b], objective="time", weighting="pooled") == 0


def test_evaluate_counts_distinct_problems_and_the_common_subset():
    fast = [record("rrt", seed=i, length_rad=1.0, time_s=0.1) for i in range(3)] + [
        record("rrt", seed=3, status="timeout", time_s=5.0)]
    slow = [record("rrt", seed=i, length_rad=2.0, time_s=0.4) for i in range(4)]
    for recs in (fast, slow):
        for r in recs:
            if r.status == "success":
                r.metrics["length_ratio"] = r.metrics["path_length_rad"]
    a, b = evaluate([({"range_rad": None}, fast), ({"range_rad": 1.0}, slow)])
    assert (a.solved, a.problems, b.solved) == (3, 4, 4)
    assert (a.time_to_solve_median_s, b.time_to_solve_median_s) == (pytest.approx(0.1), pytest.approx(0.4))
    assert (a.length_ratio_common_median, b.length_ratio_common_median) == (1.0, 2.0)  # seeds 0-2 only
    assert choose([a, b], objective="time", weighting="pooled") == 1  # solving more wins before speed


def test_tuned_settings_are_the_defaults_and_overrides_win(tmp_path, monkeypatch):
    import planners.tuned as tuned

    monkeypatch.setattr(tuned, "CONFIGS_DIR", tmp_path)
    (tmp_path / "rrt.yaml").write_text("planner: rrt\nsettings: {range_rad: 0.75, simplifier: rope+full}\n")
    cls = planner_class("rrt")
    assert tuned_settings("rrt") == {"range_rad": 0.75, "simplifier": "rope+full"}
    assert make_config(cls, None).range_rad == 0.75
    assert make_config(cls, {"range_rad": 0.3}).range_rad == 0.3
    assert make_config(cls, None, tuned=False).range_rad is None
    (tmp_path / "rrt.yaml").write_text("planner: rrt\nsettings: [1, 2]\n")
    from scenes.errors import SuiteError

    with pytest.raises(SuiteError, match="needs a 'settings' mapping"):
        make_config(cls, None)


def test_tuning_sample_is_non_trivial_tune_split_problems_per_family():
    ds, problems = tuning_problems("recycle-v1", per_family=2, time_limit_s=1.0)
    metas = [m for _, m in problems]
    assert all(m["split"] == "tune" and not m["trivial"] for m in metas)
    families = [m["family"] for m in metas]
    assert all(families.count(f) <= 2 for f in set(families)) and len(set(families)) >= 5
    from suite.problems.dataset import load_dataset

    test_ids = set(load_dataset("recycle-v1:quick").ids)
    assert not test_ids & {m["problem_id"] for m in metas}  # the quick tier (test split) is never tuned on
    _, everything = tuning_problems("recycle-v1", per_family=None, time_limit_s=1.0)  # the default: all
    tune = load_dataset("recycle-v1:tune")
    assert len(everything) == sum(not tune.meta[pid]["trivial"] for pid in tune.ids) > len(problems)


def test_a_tuning_directory_in_use_is_refused_in_one_line(tmp_path, capsys):
    from suite.cli import main
    from suite.run.lock import RunLock

    held = RunLock(tmp_path / "tune-rrt", what="tuning").acquire()
    try:
        assert main(["tune", "--planner", "rrt", "--out", str(tmp_path / "tune-rrt"), "--no-progress"]) == 2
    finally:
        held.release()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "is in use by another tuning" in err[0]
    assert main(["tune", "--planner", "nope", "--out", str(tmp_path / "never")]) == 2
    assert not (tmp_path / "never").exists()  # a bad planner fails before anything is written


def test_family_weighting_lets_no_family_outvote_another():
    """Pooled, a fast easy family with many problems decides; weighed by family, the hard one
    counts as much: 'a' is faster on 30 wall problems, 'b' on 10 window ones and as fast on wall."""
    def fam(solved_mean, time_s, pooled_time_s):
        return dataclasses.replace(_result(40, pooled_time_s, 1.0), family_solved_mean=solved_mean,
                                   family_time_to_solve_median_s=time_s, family_length_ratio_common_median=1.0)

    a, b = fam(1.0, 1.0, 0.10), fam(1.0, 0.6, 0.12)
    assert choose([a, b], objective="time", weighting="pooled") == 0
    assert choose([a, b], objective="time", weighting="family") == 1
    # solving more of every family still comes first
    c = dataclasses.replace(b, family_solved_mean=0.95)
    assert choose([a, c], objective="time", weighting="family") == 0
    with pytest.raises(ValueError, match="weighting"):
        choose([a], objective="time", weighting="median")


def test_evaluate_gives_each_family_one_vote():
    recs = [record("rrt", seed=i, length_rad=1.0, time_s=0.1) for i in range(3)]
    hard = record("rrt", seed=9, status="timeout", time_s=5.0, variant="window")
    for r in recs:
        r.metrics["length_ratio"] = 1.0
    (a,) = evaluate([({}, recs + [hard])])
    assert sorted(a.by_family) == ["open", "window"]
    assert a.family_solved_mean == pytest.approx(0.5)  # 3/3 on one family, 0/1 on the other
    assert a.family_time_to_solve_median_s == pytest.approx((0.1 + 5.0) / 2)


def test_a_planner_from_anywhere_is_tuned_by_the_search_it_declares(monkeypatch):
    """`suite tune` reads a planner's search from its class, so a planner from an entry point
    is tuned like a built-in one."""
    from planners import registry
    from planners.base import PlannerBase

    @dataclasses.dataclass(frozen=True)
    class StepConfig:
        step: float = 0.1
        greedy: bool = False

    class StepPlanner(PlannerBase):
        name = "step"
        Config = StepConfig
        search_space = {"step": (0.1, 0.2), "greedy": (False, True)}
        tuning_objective = "length"

    real = registry.planner_class
    monkeypatch.setattr(registry, "planner_class", lambda name: StepPlanner if name == "step" else real(name))
    assert grid("step") == [{"step": 0.1, "greedy": False}, {"step": 0.1, "greedy": True},
                            {"step": 0.2, "greedy": False}, {"step": 0.2, "greedy": True}]
    assert objective("step") == "length"


def test_a_candidate_over_the_offline_bound_is_out_unless_none_is_within():
    """Step -1: gcs's regions are built by the user, so a default whose worlds take longer than the bound
    at p90 is out, even when it solves more; with no candidate within the bound the rule goes on."""
    def off(solved, ratio, p90_s):
        return dataclasses.replace(_result(solved, 0.3, ratio), offline_p90_s=p90_s, offline_worlds=20)

    rows = [off(9, 1.1, 40.0), off(10, 1.0, 300.0), off(9, 1.05, 110.0)]
    assert choose(rows, objective="length", weighting="pooled") == 1  # no bound: the most solved
    explained = choose_explained(rows, objective="length", weighting="pooled", offline_bound_s=120.0)
    assert explained.index == 2 and explained.over_offline_bound == (1,)
    assert choose([off(9, 1.0, 300.0), off(10, 1.0, 200.0)], objective="length", weighting="pooled",
                  offline_bound_s=120.0) == 1  # none within: nothing is left out
    assert choose([_result(9, 0.3, 1.0)], objective="time", weighting="pooled", offline_bound_s=120.0) == 0  # NaN: none


def test_offline_seconds_count_each_world_once():
    from suite.report.tuning import offline_per_world

    stats = [{"world_hash": "a", "offline_s": 30.0}, {"world_hash": "a", "offline_s": 30.0},
             {"world_hash": "b", "offline_s": 90.0}, {}, None,
             {"world_hash": "c", "offline_s": 200.0, "offline_cpu_s": 80.0}]  # CPU time where recorded
    recs = [TrialRecord(planner="gcs", status="success", problem="transit", scene_seed=0, variant="open", can_id=0,
                        stats=s) for s in stats]
    assert offline_per_world(recs) == {"a": 30.0, "b": 90.0, "c": 80.0}
