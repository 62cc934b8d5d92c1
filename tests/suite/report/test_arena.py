"""OMPL benchmark logs: the structure of OMPL's log format, and OMPL's own parser reading them."""

from __future__ import annotations

import math
import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest
from synthetic_runs import synthetic_records, write_run

from suite.report.arena import benchmark_log, property_name, write_arena_logs
from suite.run.records import STATUSES, read_trials

PROPERTY_TYPES = {"REAL", "INTEGER", "BOOLEAN", "ENUM"}


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    records = synthetic_records(seeds=(0,), variants=("open",), cans=1, planners=("ik", "rrt"), rng_seed=11)
    records[0].status = "crash"  # a record written by the runner for a dead worker
    records[0].path, records[0].metrics = None, {}
    ok = next(r for r in records[1:] if r.status == "success")
    ok.metrics["clearance_min_m"] = None  # a metric the trial could not compute
    return write_run(tmp_path_factory.mktemp("run"), records, planners=("ik", "rrt"), cans=1)


def parse_log(text: str) -> dict:
    """Read a log following OMPL's documented grammar (doc/markdown/benchmark.md), strictly."""
    lines = text.split("\n")
    assert lines[-1] == "", "the log ends with a newline"
    it = iter(lines[:-1])

    def take(suffix: str) -> str:
        line = next(it)
        assert line.endswith(suffix), f"expected '... {suffix}', got {line!r}"
        return line[: -len(suffix)].strip()

    def multiline() -> list[str]:
        assert next(it) == "<<<|"
        body = []
        for line in it:
            if line == "|>>>":
                return body
            body.append(line)
        raise AssertionError("unterminated multi-line value")

    out: dict = {}
    lib, word, version = next(it).split(" ")
    assert word == "version" and version
    kw, name = next(it).split(" ")
    assert kw == "Experiment"
    out["experiment"] = name
    n_exp = int(take(" experiment properties"))
    out["exp_props"] = {}
    for _ in range(n_exp):
        lhs, value = next(it).split(" = ")
        prop, typ = lhs.rsplit(" ", 1)
        out["exp_props"][prop] = (typ, value)
    host = next(it)
    assert host.startswith("Running on ") and len(host.split()) == 3
    assert next(it).startswith("Starting at ")
    out["setup"], out["cpuinfo"] = multiline(), multiline()
    int(take(" is the random seed"))
    out["time_limit_s"] = float(take(" seconds per run"))
    float(take(" MB per run"))
    line = next(it)
    if line.endswith(" runs per planner"):
        out["runs_per_planner"] = int(line.split()[0])
        line = next(it)
    assert line.endswith(" seconds spent to collect the data")
    assert next(it) == "1 enum type"
    enum = next(it).split("|")
    assert enum[0] == "status"
    out["status_enum"] = enum[1:]
    out["planners"] = {}
    for _ in range(int(take(" planners"))):
        pname = next(it)
        assert " " not in pname
        common = [next(it).split(" = ") for _ in range(int(take(" common properties")))]
        props = []
        for _ in range(int(take(" properties for each run"))):
            prop, typ = next(it).rsplit(" ", 1)
            assert typ in PROPERTY_TYPES
            props.append((prop, typ))
        assert [p for p, _ in props] == sorted(p for p, _ in props)
        runs = []
        for _ in range(int(take(" runs"))):
            line = next(it)
            assert line.endswith("; ")
            values = line.split("; ")[:-1]
            assert len(values) == len(props)
            runs.append(dict(zip([p for p, _ in props], values)))
        line = next(it)
        progress = []
        if line.endswith(" progress properties for each run"):
            names = [next(it) for _ in range(int(line.split()[0]))]
            assert all(n.rsplit(" ", 1)[1] in PROPERTY_TYPES for n in names) and "time REAL" in names
            assert int(take(" runs")) == len(runs)
            for _ in runs:
                points = next(it).split(";")[:-1]
                progress.append([dict(zip(names, p.split(",")[:-1])) for p in points])
            line = next(it)
        assert line == "."
        out["planners"][pname] = {"common": dict(common), "props": dict(props), "runs": runs, "progress": progress}
    assert next(it, None) is None, "nothing after the last planner"
    return out


def test_log_structure_and_values(run_dir):
    records = read_trials(run_dir)
    log = parse_log(benchmark_log(records, experiment="cans open all", manifest={}))
    assert log["experiment"] == "cans_open_all"
    assert log["exp_props"]["trials"] == ("INTEGER", str(len(records)))
    assert log["time_limit_s"] == 10.0
    assert log["runs_per_planner"] == 5
    assert log["status_enum"] == list(STATUSES)
    assert list(log["planners"]) == ["ik", "rrt"]
    props = log["planners"]["ik"]["props"]
    assert props["time"] == "REAL" and props["solved"] == "BOOLEAN" and props["status"] == "ENUM"
    assert props["path length rad"] == "REAL" and props["clearance min m"] == "REAL"
    assert log["planners"]["ik"]["common"] == {"name": "ik"}
    for p, data in log["planners"].items():
        mine = [r for r in records if r.planner == p]
        assert len(data["runs"]) == len(mine)
        for rec, run in zip(mine, data["runs"]):
            assert float(run["time"]) == rec.planning_time_s  # repr round-trips exactly
            assert run["solved"] == ("1" if rec.status == "success" else "0")
            assert log["status_enum"][int(run["status"])] == rec.status
            assert int(run["scene seed"]) == rec.scene_seed and int(run["can id"]) == rec.can_id
            for name in ("path_length_rad", "clearance_min_m", "duration_s"):
                v, text = (rec.metrics or {}).get(name), run[property_name(name)]
                assert text == "" if v is None else math.isclose(float(text), v)
    first = log["planners"]["ik"]["runs"][0]
    assert log["status_enum"][int(first["status"])] == "crash" and first["path length rad"] == ""
    # a success without a clearance value: that field alone is empty
    assert any(r["solved"] == "1" and r["clearance min m"] == "" and r["path length rad"]
               for p in log["planners"].values() for r in p["runs"])


def test_property_names_are_plain_words():
    assert property_name("path_length_rad") == "path length rad"
    assert property_name("goal_error_deg") == "goal error deg"
    assert property_name("Jerk-Max (rad/s^3)") == "jerk max rad s 3"


def test_write_arena_logs_one_experiment_per_kind(run_dir):
    written = write_arena_logs(run_dir)
    assert [p.name for p in written] == ["ompl_benchmark.log"] + [
        f"ompl_benchmark_{k}.log" for k in ("approach", "descend", "lift", "transit", "return")]
    logs = [parse_log(p.read_text()) for p in written]
    assert logs[0]["experiment"] == "cans_open_all_motions"
    assert sum(len(p["runs"]) for p in logs[0]["planners"].values()) == 10
    for log in logs[1:]:
        assert all(len(p["runs"]) == 1 for p in log["planners"].values())


def _check_database(db: Path, n_runs: int) -> None:
    con = sqlite3.connect(db)
    names = [r[0] for r in con.execute("SELECT name FROM experiments ORDER BY id")]
    assert names[0] == "cans_open_all_motions" and len(names) == 6
    assert [r[0] for r in con.execute("SELECT name FROM plannerConfigs ORDER BY id")] == ["ik", "rrt"]
    cols = {r[1] for r in con.execute("PRAGMA table_info(runs)")}
    assert {"time", "solved", "status", "path_length_rad", "clearance_min_m", "smoothness"} <= cols
    assert con.execute("SELECT COUNT(*) FROM runs").fetchone()[0] == n_runs
    (crashed,) = con.execute(
        "SELECT e.description FROM runs r JOIN enums e ON e.name = 'status' AND e.value = r.status "
        "WHERE r.experimentid = 1 AND r.path_length_rad IS NULL AND r.solved = 0 LIMIT 1").fetchone()
    assert crashed in STATUSES and crashed != "success"
    # the views Planner Arena's "best planner" pages use
    assert len(con.execute("SELECT * FROM bestPlannerConfigs").fetchall()) == 2


def test_ompl_parser_reads_the_logs(run_dir, tmp_path):
    """OMPL's own reader (what ompl_benchmark_statistics.py calls) builds the database."""
    tools = pytest.importorskip("ompl.tools")
    if not hasattr(tools, "readBenchmarkLog"):
        pytest.skip("this OMPL build has no readBenchmarkLog")
    logs = write_arena_logs(run_dir)
    db = tmp_path / "benchmark.db"
    tools.readBenchmarkLog(str(db), [str(p) for p in logs], False)
    tools.computeViews(str(db), False)
    _check_database(db, n_runs=20)


@pytest.mark.skipif(not os.environ.get("OMPL_BENCHMARK_STATISTICS"),
                    reason="set OMPL_BENCHMARK_STATISTICS to OMPL's scripts/ompl_benchmark_statistics.py")
def test_ompl_benchmark_statistics_script(run_dir, tmp_path):
    logs = write_arena_logs(run_dir)
    db = tmp_path / "benchmark.db"
    subprocess.run([sys.executable, os.environ["OMPL_BENCHMARK_STATISTICS"], "-d", str(db), *map(str, logs)],
                   check=True, capture_output=True, cwd=tmp_path)
    _check_database(db, n_runs=20)


def test_optimizing_planners_progress_goes_to_the_progress_block(tmp_path):
    records = synthetic_records(seeds=(0,), variants=("open",), cans=1, planners=("rrtstar", "rrt"), rng_seed=3)
    for r in records:
        if r.planner == "rrtstar":
            r.stats["progress"] = [[0.05, None], [0.1, 2.5], [0.15, 2.25]]
    log = parse_log(benchmark_log(records, experiment="progress"))
    star, rrt = log["planners"]["rrtstar"], log["planners"]["rrt"]
    assert rrt["progress"] == []  # a feasibility planner reports none
    assert len(star["progress"]) == len(star["runs"])
    assert star["progress"][0] == [{"best cost REAL": "nan", "time REAL": "0.05"},
                                   {"best cost REAL": "2.5", "time REAL": "0.1"},
                                   {"best cost REAL": "2.25", "time REAL": "0.15"}]
    tools = pytest.importorskip("ompl.tools")
    if not hasattr(tools, "readBenchmarkLog"):
        pytest.skip("this OMPL build has no readBenchmarkLog")
    path = tmp_path / "progress.log"
    path.write_text(benchmark_log(records, experiment="progress"))
    db = tmp_path / "benchmark.db"
    tools.readBenchmarkLog(str(db), [str(path)], False)
    rows = sqlite3.connect(db).execute("SELECT time, best_cost FROM progress ORDER BY runid, time").fetchall()
    assert len(rows) == 3 * len(star["runs"]) and rows[1] == (0.1, 2.5)
