"""The comparison end to end: records, resume, jobs-independence, isolation, bad input."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

FIXTURES = Path(__file__).resolve().parents[2] / "fixtures"
ROOT = Path(__file__).resolve().parents[3]
# 10 s: rrt solves these in well under a second (and returns then); the records of two runs must
# not differ by a trial that timed out on a busy machine.
TINY = ["--planners", "ik,rrt", "--scenes", "1", "--cans", "1", "--variant", "wall", "--time-limit-s", "10",
        "--no-plots", "--no-progress"]
#: Longest wait for a run (or for its records): only a hang reaches it.
DEADLINE_S = 600


def compare(*args, env=None, check=True, timeout=DEADLINE_S):
    return subprocess.run([sys.executable, "-m", "suite", "compare", *args], capture_output=True, text=True,
                          check=check, env=env, cwd=ROOT, timeout=timeout)


def records(out: Path) -> list[dict]:
    return [json.loads(line) for line in (out / "trials.jsonl").read_text().splitlines()]


def comparable(recs):
    """Everything but wall-clock and CPU-time figures and the machine's contention, keyed by trial id."""
    out = {}
    for r in recs:
        r = dict(r)
        r.pop("planning_time_s")
        r.pop("planning_cpu_time_s", None)
        r.pop("contention", None)
        r["metrics"] = {k: v for k, v in r["metrics"].items() if not k.endswith("time_s")}
        r["stats"] = {k: v for k, v in r["stats"].items() if not k.endswith("time_s") and k != "iterations"}
        out[r["trial_id"]] = r
    return out


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "jobs2"
    res = compare(*TINY, "--jobs", "2", "--out", str(out))
    return out, res


def test_tiny_run_end_to_end(tiny_run):
    out, res = tiny_run
    recs = records(out)
    assert len(recs) == 10  # 1 can x 5 problems x 2 planners
    assert {r["problem"] for r in recs} == {"approach", "descend", "lift", "transit", "return"}
    for r in recs:
        for key in ("trial_id", "planner", "scene_seed", "variant", "can_id", "problem", "status",
                    "planning_time_s", "q_start", "q_goal", "path", "metrics", "stats", "seed"):
            assert key in r
    rrt = [r for r in recs if r["planner"] == "rrt"]
    assert all(r["status"] == "success" for r in rrt)
    assert all(r["metrics"]["duration_s"] > 0 for r in rrt if r["problem"] == "transit")
    # the planners checked with the compiled kernels (the default), and each record says so
    assert {r["checker"] for r in recs} == {"compiled"}
    assert all(isinstance(r["fcl_collide_calls"], int) and r["fcl_collide_calls"] >= 0 for r in recs)
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["config"]["checker"] == "compiled" and manifest["identity_rule"] == "round9-unsigned-zero"
    assert manifest["versions"]["drake"].startswith("1.51")
    assert manifest["machine"]["cores"] >= 1
    assert (out / "summary.md").exists() and (out / "summary.csv").exists()
    assert "rrt" in res.stdout and "5/5" in res.stdout
    # the one-page report, by default, its path printed
    assert f"report: {out / 'report.html'}" in res.stdout
    page = (out / "report.html").read_text()
    assert page.count('<section class="drill" ') == len({r["problem_id"] for r in recs}) == 5


def test_jobs_do_not_change_the_records(tiny_run, tmp_path):
    out2, _ = tiny_run
    out1 = tmp_path / "jobs1"
    compare(*TINY, "--jobs", "1", "--out", str(out1))
    a, b = comparable(records(out1)), comparable(records(out2))
    assert a.keys() == b.keys()
    for k in a:
        assert a[k]["status"] == b[k]["status"]
        assert a[k]["path"] == b[k]["path"], (a[k]["planner"], a[k]["problem"])


def test_resume_after_kill_loses_and_duplicates_nothing(tiny_run, tmp_path):
    out = tmp_path / "killed"
    proc = subprocess.Popen([sys.executable, "-m", "suite", "compare", *TINY, "--jobs", "1", "--out", str(out)],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    trials = out / "trials.jsonl"
    deadline = time.monotonic() + DEADLINE_S
    # a fast machine may write all 10 records before the kill lands (or before the poll sees 3):
    # the resume below must then add nothing, which it checks the same way
    while not (trials.exists() and len(trials.read_text().splitlines()) >= 3) and proc.poll() is None:
        assert time.monotonic() < deadline, "no 3 records"
        time.sleep(0.1)
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    n_before = len(trials.read_text().splitlines())
    assert 3 <= n_before <= 10
    with open(trials, "a") as f:
        f.write('{"trial_id": "torn')  # a line cut short by the kill
    compare(*TINY, "--jobs", "2", "--out", str(out), "--resume")
    recs = records(out)
    ids = [r["trial_id"] for r in recs]
    assert len(ids) == len(set(ids)) == 10
    assert set(ids) == set(comparable(records(tiny_run[0])))


def test_crash_and_hang_are_isolated(tmp_path):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(FIXTURES / "crashy"), str(ROOT)]))
    cfg = tmp_path / "cfg.yaml"
    # The hang is killed at 3 x 2 s + 15 s: far beyond what a worker's first trial takes on a busy
    # machine (imports and all: a 4.5 s hard limit killed an rrt trial there), and a 2 s budget is
    # ten times what rrt needs on these problems.
    cfg.write_text("hard_limit_grace_s: 15\n")
    out = tmp_path / "crashy"
    compare("--planners", "crashy,rrt", "--scenes", "1", "--cans", "1", "--variant", "wall", "--time-limit-s", "2",
            "--jobs", "2", "--no-plots", "--no-progress", "--config", str(cfg), "--out", str(out), env=env)
    by = {(r["planner"], r["problem"]): r["status"] for r in records(out)}
    assert by[("crashy", "descend")] == "crash"
    assert by[("crashy", "lift")] == "killed_timeout"
    assert by[("crashy", "approach")] == "no_solution"
    assert all(by[("rrt", p)] == "success" for p in ("approach", "descend", "lift", "transit", "return"))


@pytest.mark.parametrize(
    "args, needle",
    [
        (["--planners", "ik,warp"], "unknown planner 'warp'"),
        (["--scenes", "0"], "--scenes"),
        (["--cans", "-1"], "--cans"),
        (["--time-limit-s", "nan"], "--time-limit-s"),
        (["--time-limit-s", "-3"], "--time-limit-s"),
        (["--variant", "moon"], "unknown variant 'moon'"),
        (["--out", "/proc/forbidden/run"], "not writable"),
        (["--resume"], "--resume needs --out"),
    ],
)
def test_bad_input_fails_before_any_trial(args, needle, tmp_path):
    res = compare(*args, check=False)
    assert res.returncode != 0
    lines = [l for l in res.stderr.splitlines() if l.strip()]
    assert len(lines) == 1, res.stderr
    assert needle in lines[0]


def test_existing_run_is_not_overwritten(tiny_run):
    out, _ = tiny_run
    before = (out / "trials.jsonl").read_bytes()
    res = compare(*TINY, "--out", str(out), check=False)
    assert res.returncode != 0 and "already holds a run" in res.stderr
    assert (out / "trials.jsonl").read_bytes() == before


def test_execute_runs_each_planners_plans_in_physics(tmp_path):
    out = tmp_path / "exec"
    res = compare("--planners", "rrt,trajopt", "--scenes", "1", "--cans", "1", "--variant", "open",
                  "--no-progress", "--execute", "--out", str(out))
    execs = json.loads((out / "execution.json").read_text())["executions"]
    assert [e["planner"] for e in execs] == ["rrt", "trajopt"]
    recs = records(out)
    for e in execs:
        # Executed only what the trials planned: a planner with a failed problem stops there.
        planned = all(r["status"] == "success" for r in recs if r["planner"] == e["planner"])
        assert e["cans_attempted"] == (1 if planned else 0)
        assert e["cans_in_bin"] + e["cans_on_plate"] + e["cans_elsewhere"] == e["cans_total"] == 1
        assert e["replay"] == f"replay_{e['planner']}.html" and (out / e["replay"]).stat().st_size > 100_000
    assert "Execution in physics" in (out / "summary.md").read_text()
    assert (out / "plots" / "execution.png").exists()
    assert "Execution in physics" in res.stdout


def test_execute_on_a_dataset_runs_its_stored_scenes_cycle_by_cycle(tmp_path):
    # the stored scenes are posed again with the dataset's own build settings to find the steps
    # stored once under another scene; every scene whose problems were all solved is executed
    out = tmp_path / "exec"
    compare("--dataset", "recycle-v2:quick:family=open", "--planners", "rrt", "--jobs", "1", "--no-plots",
            "--no-progress", "--execute", "--time-limit-s", "30", "--out", str(out))  # every trial must solve
    execs = json.loads((out / "execution.json").read_text())["executions"]
    recs = records(out)
    assert len(execs) == len({r["scene_key"] for r in recs}) >= 1
    assert all(r["status"] == "success" for r in recs)
    # one worker: its first rrt trial is cold, every later one warm; the summary says so
    assert [r["warm"] for r in recs].count(False) == 1 and len(recs) > 1
    cold = json.loads((out / "summary.json").read_text())["planners"]["rrt"]["cold_start"]
    assert cold["cold_trials"] == 1 and cold["warm_trials"] == len(recs) - 1
    assert "## Cold starts" in (out / "summary.md").read_text()
    # rrt counts and times its python-fcl queries: the record splits its planning time
    for r in recs:
        a = r["attribution"]
        # the trial counts every query of plan(): rrt's own, and the two endpoint checks before them
        assert a["queries"] == r["stats"]["collision_checks"] + 2 and r["stats"]["collision_checks"] > 0
        assert 0 < a["query_s"] <= r["planning_time_s"] and a["query_s"] + a["other_s"] == pytest.approx(r["planning_time_s"])
    att = json.loads((out / "summary.json").read_text())["planners"]["rrt"]["attribution"]
    assert att["engine"] == "python-fcl" and 0 < att["query_share"] <= 1
    for e in execs:
        assert e["cans_attempted"] == e["cans_total"] >= 1, e  # no step missing from the dataset


def test_resume_refuses_a_contradicting_setting_and_appends_nothing(tiny_run, tmp_path):
    import shutil

    out = tmp_path / "resumed"
    shutil.copytree(tiny_run[0], out)
    before = (out / "trials.jsonl").read_bytes()
    r = compare("--out", str(out), "--resume", "--variant", "open", "--planners", "rrt,trajopt", check=False)
    assert r.returncode == 2 and r.stderr.count("\n") == 1
    assert "--variant 'open' contradicts the run's variant = 'wall'" in r.stderr
    assert (out / "trials.jsonl").read_bytes() == before
    # the same settings, or none, resume; how it runs (--jobs) may change
    r = compare("--out", str(out), "--resume", "--jobs", "1", "--no-plots", "--no-progress")
    assert r.returncode == 0, r.stderr
    assert (out / "trials.jsonl").read_bytes() == before  # everything was already recorded


def test_each_setting_is_listed_once_and_every_flag_setting_has_its_flag():
    # CompareConfig is the one list of settings: the flags that set a field of the same name are
    # derived from it, so a new setting without its flag fails here, not in a user's run
    import argparse
    import dataclasses

    from suite.cli.compare import FLAG_SETTINGS, add_arguments, resolve_config
    from suite.run.runner import CompareConfig

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args([])
    assert set(FLAG_SETTINGS) <= set(vars(args))
    assert set(FLAG_SETTINGS) <= {f.name for f in dataclasses.fields(CompareConfig)}
    assert resolve_config(args) == CompareConfig()
    args = parser.parse_args(["--jobs", "1", "--time-limit-s", "2.5"])
    assert resolve_config(args) == dataclasses.replace(CompareConfig(), jobs=1, time_limit_s=2.5)
