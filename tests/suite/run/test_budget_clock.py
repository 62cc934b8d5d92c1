"""Budgets on a clock (wall or CPU), each trial's CPU time and contention, and the run's warning.

No test here races a clock: the fake clocks are stepped by hand, and the real planning call sleeps
well past its budget in wall time while its CPU time stays far below it.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import time

import pytest

from planners import base
from planners.base import Budget, PlanStatus
from scenes.errors import SuiteError
from suite.problems import DEFAULT_TIER
from suite.run.contention import ContentionProbe, is_contended, run_contention
from suite.run.records import TrialRecord
from suite.run.trial import late_after_s, make_trial, run_trial


class FakeClock:
    """A clock that moves only when told."""

    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


@pytest.fixture()
def fake_clocks(monkeypatch):
    clocks = {"wall": FakeClock(), "cpu": FakeClock()}
    monkeypatch.setitem(base.CLOCKS, "wall", clocks["wall"])
    monkeypatch.setitem(base.CLOCKS, "cpu", clocks["cpu"])
    return clocks


def test_a_cpu_budget_is_spent_by_cpu_time_only(fake_clocks):
    wall, cpu = fake_clocks["wall"], fake_clocks["cpu"]
    b = Budget.starting_now(1.0, clock="cpu")
    assert (b.clock, b.start, b.deadline) == ("cpu", 100.0, 101.0)
    wall.t += 50.0  # the process sleeps, or waits for a CPU: no CPU time passes
    assert not b.expired() and b.left_s() == pytest.approx(1.0) and b.spent_s() == 0.0
    cpu.t += 0.4
    assert not b.expired() and b.left_s() == pytest.approx(0.6)
    cpu.t += 0.6
    assert b.expired() and b.spent_s() == pytest.approx(1.0)


def test_a_wall_budget_is_spent_by_wall_time(fake_clocks):
    b = Budget.starting_now(1.0, clock="wall")
    fake_clocks["cpu"].t += 5.0
    assert not b.expired()
    fake_clocks["wall"].t += 1.0
    assert b.expired() and b.left_s() == pytest.approx(0.0)


def test_an_unknown_clock_is_one_line():
    with pytest.raises(SuiteError, match=r"^budget clock 'gpu'; allowed: wall, cpu$"):
        Budget.starting_now(1.0, clock="gpu")


def test_ompl_cpu_termination_does_not_fire_while_the_process_sleeps():
    from planners.ompl_budget import termination

    ptc = termination("cpu", 0.05)
    time.sleep(0.2)  # four times the budget in wall time, no CPU
    assert not ptc()
    t_end = time.perf_counter() + 30.0  # only a broken clock reaches it
    while not ptc() and time.perf_counter() < t_end:
        pass  # spend CPU time
    assert ptc()


# --- a real planning call: sleeping spends a wall budget, not a CPU budget ------------------------

SLEEP_S = 1.5
BUDGET_S = 1.0


@pytest.fixture(scope="module")
def problem():
    from suite.problems.dataset import load_dataset

    ds = load_dataset(f"{DEFAULT_TIER}:family=wall,kind=transit", time_limit_s=BUDGET_S)
    return ds.problems[0], ds.meta[ds.ids[0]]


@pytest.fixture()
def sleepy_rrt(monkeypatch):
    """`rrt` that first sleeps SLEEP_S seconds inside its budget (no CPU), as a process waits for a
    CPU another process holds."""
    from planners import registry
    from planners.ompl_rrt import RRTConnectPlanner

    class SleepyRRT(RRTConnectPlanner):
        name = "sleepy-rrt"

        def solve(self, problem, world, budget):
            time.sleep(SLEEP_S)
            return super().solve(problem, world, budget)

    real = registry.planner_class
    monkeypatch.setattr(registry, "planner_class", lambda name: SleepyRRT if name == "sleepy-rrt" else real(name))
    return "sleepy-rrt"


def _trial(problem, meta, planner, clock):
    p = problem.with_(budget_clock=clock)
    return run_trial(make_trial(p, planner=planner, planner_config={}, run_seed=0, meta=meta))


def test_a_cpu_budget_survives_a_sleep_a_wall_budget_does_not(problem, sleepy_rrt):
    p, meta = problem
    cpu = _trial(p, meta, sleepy_rrt, "cpu")
    assert cpu.status == "success", cpu.stats.get("reason")
    assert cpu.budget_clock == "cpu" and cpu.format_version == 2
    # judged on its CPU time: its wall time alone would have made it late
    assert cpu.planning_time_s > late_after_s(BUDGET_S) >= SLEEP_S - 0.5
    assert cpu.planning_cpu_time_s < late_after_s(BUDGET_S)
    assert cpu.contention["cpu_wait_s"] is not None  # measured (Linux)
    wall = _trial(p, meta, sleepy_rrt, "wall")
    assert wall.status == "timeout" and wall.budget_clock == "wall" and wall.format_version == 1
    assert wall.trial_id != cpu.trial_id  # the clock is part of a cpu trial's identity


def test_a_record_has_its_cpu_time_beside_its_wall_time(problem):
    p, meta = problem
    r = _trial(p.with_(time_limit_s=30.0), meta, "rrt", "wall")
    assert r.status == "success"
    assert 0 < r.planning_cpu_time_s <= r.planning_time_s * 1.5 + 0.05  # one thread, at most a little more
    c = r.contention
    assert set(c) == {"cpu_wait_s", "steal_s", "machine_cpu_s", "others_cpu_s", "load1", "runnable", "cores",
                      "contended"}
    assert c["cores"] >= 1 and isinstance(c["contended"], bool)
    # a wall trial keeps the id it had before budgets had clocks (the same hash of the same fields)
    q = make_trial(p.with_(time_limit_s=30.0), planner="rrt", planner_config={}, run_seed=0).problem
    blob = json.dumps({"scene": q.scene.key(), "scene_seed": q.scene.seed, "can": q.can_id, "problem": q.kind,
                       "seed": q.seed, "time_limit_s": q.time_limit_s, "planner": "rrt", "config": {}},
                      sort_keys=True)
    assert r.trial_id == hashlib.sha256(blob.encode()).hexdigest()[:20]


# --- the contention rule ------------------------------------------------------------------------


def test_the_contention_rule():
    quiet = {"cpu_wait_s": 0.002, "steal_s": 0.0, "machine_cpu_s": 2.0}
    assert is_contended(quiet, wall_s=1.0) is False
    assert is_contended({**quiet, "cpu_wait_s": 0.2}, wall_s=1.0) is True  # waited 20% of its time
    assert is_contended({**quiet, "cpu_wait_s": 0.009}, wall_s=0.02) is False  # under 10 ms: one preemption
    assert is_contended({**quiet, "steal_s": 0.2}, wall_s=1.0) is True  # 10% of the machine's CPU stolen
    assert is_contended({**quiet, "steal_s": 0.04, "machine_cpu_s": 0.1}, wall_s=0.05) is False  # under 50 ms
    assert is_contended({"cpu_wait_s": None, "steal_s": None, "machine_cpu_s": None}, wall_s=1.0) is None
    assert is_contended(None, wall_s=1.0) is None


def test_a_probe_measures_a_quiet_stretch():
    probe = ContentionProbe.start()
    c = probe.stop(wall_s=0.0, cpu_s=0.0)
    assert c["cpu_wait_s"] is not None and c["cpu_wait_s"] >= 0 and c["cores"] >= 1


# --- the run: manifest, summary, flag -----------------------------------------------------------


def _records(n: int, contended: set[int], *, clock: str = "wall") -> list[TrialRecord]:
    out = []
    for i in range(n):
        wait = 0.5 if i in contended else 0.001
        out.append(TrialRecord.from_json({"trial_id": f"t{i}", "planner": "rrt" if i % 2 else "ik", "status": "success",
                    "problem": "transit", "scene_seed": i, "variant": "open", "can_id": 0, "budget_clock": clock,
                    "planning_time_s": 1.0, "planning_cpu_time_s": 1.0 - wait,
                    "contention": {"cpu_wait_s": wait, "steal_s": 0.0, "machine_cpu_s": 2.0, "others_cpu_s": 1.0,
                                   "load1": 3.5 if i in contended else 1.0, "runnable": 3, "cores": 2}}))
    return out


def test_run_contention_counts_and_names_the_contended_trials():
    s = run_contention(_records(6, {1, 4}, clock="cpu"))
    assert (s["trials"], s["measured"], s["contended"], s["contended_ids"]) == (6, 6, 2, ["t1", "t4"])
    assert {p: (c["measured"], c["contended"]) for p, c in s["by_planner"].items()} == {"ik": (3, 1), "rrt": (3, 1)}
    assert s["run_contended"] and s["by_planner"]["ik"]["contended_together"]
    assert s["budget_clock"] == "cpu" and s["load1"]["max"] == 3.5
    assert s["cpu_wait_share"] == pytest.approx((2 * 0.5 + 4 * 0.001) / 6, abs=1e-4)


def test_a_planner_of_short_trials_that_waited_together_makes_the_run_contended():
    recs = [r.with_(planning_time_s=0.005, contention={**r.contention, "cpu_wait_s": 0.004})
            for r in _records(6, set())]
    s = run_contention(recs)
    assert s["contended"] == 0  # each under the 10 ms floor
    assert s["run_contended"] and s["by_planner"]["rrt"]["cpu_wait_share"] == pytest.approx(0.8)
    from suite.report.summary_contention import contention_warning

    assert "rrt (80%)" in contention_warning(recs)
    assert not run_contention(_records(6, set()))["run_contended"]


def test_the_summary_warns_of_a_contended_run_and_names_its_trials(tmp_path):
    from suite.report.summary_contention import contention_warning
    from suite.run.records import read_trials
    from synthetic_runs import synthetic_records, write_run

    run = write_run(tmp_path / "run", synthetic_records(variants=("open",), cans=1))
    path = run / "trials.jsonl"
    recs = read_trials(path)
    quiet = [r.with_(contention={"cpu_wait_s": 0.0, "steal_s": 0.0, "machine_cpu_s": 2.0}) for r in recs]
    assert contention_warning(quiet) is None
    loaded = [r.with_(contention={"cpu_wait_s": r.planning_time_s * 0.5 + 0.02, "steal_s": 0.0,
                                  "machine_cpu_s": 2.0}) if i < 3 else r for i, r in enumerate(quiet)]
    path.write_text("".join(json.dumps(r.to_json()) + "\n" for r in loaded))
    from suite.report.write import write_report

    write_report(run, plots=False, html=True)
    md = (run / "summary.md").read_text()
    ids = [r.trial_id for r in loaded[:3]]
    head = md.split("\n## ")[0]
    assert "Warning: the machine was contended" in head and all(i in head for i in ids)
    assert f"3 of {len(loaded)} measured trials" in head
    assert "## Budget clock and machine contention" in md
    summary = json.loads((run / "summary.json").read_text())
    assert summary["contention"]["contended"] == 3 and summary["contention"]["contended_ids"] == ids
    assert "the machine was contended" in (run / "report.html").read_text()


def test_the_manifest_records_the_cpu_budget_clock(tmp_path):
    from suite.run.manifest import read_run_manifest, write_manifest
    from suite.run.runner import CompareConfig, prepare_trials

    config = CompareConfig(planners=("rrt",), budget_clock="cpu",
                           dataset=f"{DEFAULT_TIER}:family=wall,kind=transit")
    write_manifest(tmp_path, config, argv=["compare", "--budget-clock", "cpu"])
    manifest = read_run_manifest(tmp_path)
    assert manifest["config"]["budget_clock"] == "cpu" and manifest["format_version"] == 2
    trials = prepare_trials(config)
    assert trials and {t.problem.budget_clock for t in trials} == {"cpu"}
    wall = prepare_trials(dataclasses.replace(config, budget_clock="wall"))
    assert {t.problem.budget_clock for t in wall} == {"wall"}
    assert not {t.trial_id for t in wall} & {t.trial_id for t in trials}


@pytest.mark.parametrize("value", ["gpu", "CPU", ""])
def test_the_flag_refuses_a_bad_clock_in_one_line(value, capsys):
    from suite.cli import main

    assert main(["compare", "--budget-clock", value, "--planners", "rrt"]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert err == [f"error: --budget-clock {value!r}: allowed: wall, cpu"]


def test_a_config_file_refuses_a_bad_clock(tmp_path, capsys):
    from suite.cli import main

    cfg = tmp_path / "c.yaml"
    cfg.write_text("budget_clock: gpu\n")
    assert main(["compare", "--config", str(cfg)]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1 and "budget_clock" in err[0] and "'gpu'" in err[0] and "'wall' or 'cpu'" in err[0]


def test_bench_load_refuses_a_bad_clock():
    from suite.bench.load import clocks

    assert clocks("wall,cpu") == ["wall", "cpu"] and clocks("cpu") == ["cpu"]
    for bad in ("gpu", "cpu,cpu", ""):
        with pytest.raises(SuiteError, match="--budget-clock .*: allowed: wall, cpu"):
            clocks(bad)
