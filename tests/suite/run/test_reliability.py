"""Reliability, in-process: the run lock, a full disk and a removed file at the record writer, the
memory cap, the worker cap, format versions, and bad values in every configuration file refused in
one line. (Real second processes and signals: test_reliability_processes.py; a lost Dask worker:
test_reliability_dask.py.)"""

from __future__ import annotations

import errno
import json
import logging
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

import suite.run.journal as journal
from scenes.errors import SuiteError
from scenes.spec import DEFAULT_SPEC_PATH, load_spec
from suite.cli import main
from suite.problems.dataset import DATASETS_DIR, load_dataset
from suite.run.executors import Job, LocalExecutor
from suite.run.journal import RecordWriteError, TrialsJournal
from suite.run.records import TrialRecord
from suite.run.lock import RunLock
from suite.run.records import read_manifest, read_trials
from suite.run.runner import (
    TRIALS_FILE,
    CompareConfig,
    make_executor,
    prepare_trials,
    recorded_trial_ids,
    run_trials,
)

FAULTY = Path(__file__).resolve().parents[2] / "fixtures" / "faulty"


def _ids(path: Path) -> list[str]:
    return [r.trial_id for r in read_trials(path)]


def _one_error_line(capsys) -> str:
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1, err
    return err[0]


@pytest.fixture(scope="module")
def ik_trials():
    """The 5 problems of one `open` scene with one can, planned by `ik` (fast, real trials)."""
    return prepare_trials(CompareConfig(planners=("ik",), variant="open", scenes=1, cans=1, dataset=None,
                                        time_limit_s=2.0))


# --- one writer per run directory ------------------------------------------------------------------


def test_second_lock_on_a_directory_fails_naming_the_holder(tmp_path):
    with RunLock(tmp_path / "run"):
        with pytest.raises(SuiteError, match=rf"in use by another run \(PID {os.getpid()}\)"):
            RunLock(tmp_path / "run").acquire()
    with RunLock(tmp_path / "run"):  # released: free again
        pass


def test_lock_of_a_killed_process_does_not_block(tmp_path):
    run = tmp_path / "run"
    code = ("import os, signal, sys; from suite.run.lock import RunLock; RunLock(sys.argv[1]).acquire(); "
            "os.kill(os.getpid(), signal.SIGKILL)")
    proc = subprocess.run([sys.executable, "-c", code, str(run)], check=False)
    assert proc.returncode == -9 and (run / ".lock").read_text().strip().isdigit()  # left behind
    with RunLock(run):
        assert (run / ".lock").read_text().strip() == str(os.getpid())


def test_compare_into_a_locked_directory_writes_nothing(tmp_path, capsys):
    run = tmp_path / "busy"
    with RunLock(run):
        for extra in ([], ["--resume"]):
            (run / TRIALS_FILE).write_text("") if extra else None
            before = sorted(p.name for p in run.iterdir())
            assert main(["compare", "--planners", "ik", "--variant", "open", "--scenes", "1", "--out", str(run),
                         *extra]) == 2
            line = _one_error_line(capsys)
            assert f"'{run}' is in use by another run (PID {os.getpid()})" in line
            assert sorted(p.name for p in run.iterdir()) == before


# --- disk faults at the record writer --------------------------------------------------------------


def test_full_disk_stops_the_run_keeps_whole_records_and_resume_completes(ik_trials, tmp_path, monkeypatch, capsys):
    out = tmp_path / "full"
    real_write = journal._write
    calls = {"n": 0}

    def full_disk_on_third(fd, data):
        calls["n"] += 1
        if calls["n"] == 3:
            real_write(fd, data[: len(data) // 2])  # half a line reaches the disk, then it is full
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real_write(fd, data)

    args = ["compare", "--planners", "ik", "--variant", "open", "--scenes", "1", "--cans", "1", "--time-limit-s", "2",
            "--jobs", "1", "--no-plots", "--no-progress", "--out", str(out)]
    monkeypatch.setattr(journal, "_write", full_disk_on_third)
    assert main(args) == 2
    assert capsys.readouterr().err.strip().splitlines()[-1] == (
        f"error: cannot append to {out / TRIALS_FILE}: No space left on device (ENOSPC); the run stopped with 2 "
        f"trial(s) kept; once the cause is fixed, resume with: python -m suite compare --resume --out {out}")
    assert len(_ids(out / TRIALS_FILE)) == 2  # whole records only: the half line was cut back
    assert (out / TRIALS_FILE).read_bytes().endswith(b"}\n")
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["status"] == "stopped" and manifest["trials_recorded"] == 2 and manifest["trials_total"] == 5
    monkeypatch.setattr(journal, "_write", real_write)  # space freed
    assert main(["compare", "--resume", "--out", str(out), "--no-plots", "--no-progress"]) == 0
    assert sorted(_ids(out / TRIALS_FILE)) == sorted(t.trial_id for t in ik_trials)  # none lost, none doubled


def _record(trial_id: str) -> TrialRecord:
    return TrialRecord(planner="ik", status="success", problem="lift", scene_seed=0, variant="open", can_id=0,
                       trial_id=trial_id)


def test_removed_trials_file_is_reported_at_the_next_append(tmp_path):
    path = tmp_path / TRIALS_FILE
    with TrialsJournal(path) as j:
        j.append(_record("a"))
        path.unlink()
        with pytest.raises(RecordWriteError, match=rf"cannot append to {path}: the file was removed during the run"):
            j.append(_record("b"))


def test_unwritable_trials_file_is_one_error(tmp_path):
    (tmp_path / TRIALS_FILE).mkdir()  # a directory where the file should be
    with pytest.raises(RecordWriteError, match=r"cannot append to .*trials.jsonl: Is a directory"):
        TrialsJournal(tmp_path / TRIALS_FILE)


# --- bounded resources -----------------------------------------------------------------------------


def _pid(n):
    return {"pid": os.getpid(), "n": n}


def test_workers_are_capped_by_the_pending_jobs(caplog):
    ex = LocalExecutor(jobs=6)
    with caplog.at_level(logging.INFO, logger="suite.run.executors"):
        got = list(ex.run([Job(f"j{i}", _pid, i, 30.0) for i in range(2)]))
    assert len({o.result["pid"] for o in got}) <= 2 and len(got) == 2
    assert "starting 2 worker(s), not 6: only 2 trial(s) pending" in caplog.text


def test_runaway_memory_is_a_crash_record_and_the_run_goes_on(ik_trials, tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(FAULTY))  # the `hungry` planner's entry point (workers inherit sys.path)
    trials = prepare_trials(CompareConfig(planners=("hungry", "ik"), variant="open", scenes=1, cans=1, dataset=None,
                                          time_limit_s=2.0))
    out = tmp_path / "oom"
    out.mkdir()
    ex = make_executor("local", jobs=1, memory_limit_mb=2048)
    counts = run_trials(trials, out=out, jobs=1, executor=ex, progress_bar=False)
    assert counts["ran"] == 10
    recs = {(r.planner, r.problem): r for r in read_trials(out)}
    oom = recs[("hungry", "descend")]
    assert oom.status == "crash" and oom.stats["reason"] == "out_of_memory"
    assert oom.stats["memory_limit_mb"] == 2048
    assert all(recs[("ik", k)].status == "success" for k in ("approach", "descend", "lift"))
    assert recs[("hungry", "lift")].status == "no_solution"  # the next trial ran in a fresh worker


# --- format versions -------------------------------------------------------------------------------


def test_newer_record_version_is_one_line_naming_both(tmp_path):
    path = tmp_path / TRIALS_FILE
    rec = {"trial_id": "x", "planner": "ik", "status": "success", "problem": "lift", "scene_seed": 0,
           "variant": "open", "can_id": 0}
    path.write_text(json.dumps(rec) + "\n" + json.dumps({**rec, "trial_id": "y", "format_version": 7}) + "\n")
    for read in (read_trials, recorded_trial_ids):
        with pytest.raises(SuiteError, match=r"line 2: trial record format version 7 is newer than this suite "
                                             r"reads \(up to version 2\)"):
            read(path)
    path.write_text(json.dumps(rec) + "\n")  # no version: read as version 1
    assert _ids(path) == ["x"] and recorded_trial_ids(path) == {"x"}


def test_newer_manifest_version_is_refused_by_resume_and_reports(tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    (run / TRIALS_FILE).write_text("")
    (run / "manifest.json").write_text(json.dumps({"format_version": 3, "config": {}}))
    with pytest.raises(SuiteError, match=r"run manifest format version 3 is newer .* \(up to version 2\)"):
        read_manifest(run)
    assert main(["compare", "--resume", "--out", str(run)]) == 2
    assert "run manifest format version 3 is newer than this suite reads (up to version 2)" in _one_error_line(capsys)
    (run / "manifest.json").write_text(json.dumps({"config": {}}))  # an old manifest: read as version 1
    assert read_manifest(run) == {"config": {}}


def _dataset_copy(tmp_path: Path, edit) -> Path:
    d = tmp_path / "ds"
    shutil.copytree(DATASETS_DIR / "recycle-v1", d)
    manifest = json.loads((d / "manifest.json").read_text())
    edit(manifest)
    (d / "manifest.json").write_text(json.dumps(manifest))
    return d


def test_dataset_versions_newer_refused_missing_read_as_1(tmp_path):
    d = _dataset_copy(tmp_path, lambda m: m.update(format_version=3))
    with pytest.raises(SuiteError, match=r"dataset format version 3 is newer than this suite reads \(up to version 1\)"):
        load_dataset(f"{d}:quick")
    d = _dataset_copy(tmp_path / "old", lambda m: m.pop("format_version"))
    ds = load_dataset(f"{d}:quick")
    assert ds.hash == "ed5709ff475906ed0d29" and len(ds.problems) == 104


@pytest.mark.parametrize("edit, needle", [
    (lambda m: m.update(hash=5), "field 'hash' = 5: input should be a valid string"),
    (lambda m: m.update(tiers={"quick": "all"}), "field 'tiers.quick' = 'all': input should be a valid list"),
    (lambda m: m.pop("hash"), "field 'hash' is missing"),
    (lambda m: m.update(format_version="1"), "field 'format_version' = '1': input should be a valid integer"),
])
def test_bad_dataset_manifest_field_is_one_line(tmp_path, edit, needle):
    d = _dataset_copy(tmp_path, edit)
    with pytest.raises(SuiteError) as err:
        load_dataset(str(d))
    assert needle in str(err.value) and str(d / "manifest.json") in str(err.value) and "\n" not in str(err.value)


def test_bad_stored_problem_line_is_one_line(tmp_path):
    d = _dataset_copy(tmp_path, lambda m: None)
    lines = (d / "problems.jsonl").read_text().splitlines()
    first = next(i for i, line in enumerate(lines) if json.loads(line).get("benchmark", True))
    rec = json.loads(lines[first])
    del rec["q_goal"]
    lines[first] = json.dumps(rec)
    (d / "problems.jsonl").write_text("\n".join(lines) + "\n")
    with pytest.raises(SuiteError, match=rf"line {first + 1} \(problem {rec['problem_id']}\) is not a stored "
                                         r"problem: field 'q_goal' is missing"):
        load_dataset(str(d))


# --- one typed boundary: --config files and scene specs ---------------------------------------------


@pytest.mark.parametrize("text, needle", [
    ("jobs: two", "field 'jobs' = 'two': input should be a valid integer"),
    ("time_limit_s: '5'", "field 'time_limit_s' = '5': input should be a valid number"),
    ("seed: 1.5", "field 'seed' = 1.5: input should be a valid integer"),
    ("memory_limit_mb: 10", "field 'memory_limit_mb' = 10: input should be greater than or equal to 256"),
    ("executor: 3", "field 'executor' = 3: input should be 'local' or 'dask'"),
    ("planner_configs: {rrt: 5}", "field 'planner_configs.rrt' = 5: input should be a valid dictionary"),
    ("planner_configs: {rrt: {range_rad: fast}}", "field 'planner_configs.rrt.range_rad' = 'fast': input should be a valid number"),
    ("planner_configs: {rrt: {verbose: 1}}", "field 'planner_configs.rrt.verbose' = 1: input should be a valid boolean"),
    ("planner_configs: {rrt: {rnage_rad: 1}}", "field 'planner_configs.rrt.rnage_rad' is unknown; allowed: ["),
    ("planner_configs: {rtt: {}}", "planner_configs.rtt: unknown planner 'rtt'"),
    ("tme_limit_s: 3", "field 'tme_limit_s' is unknown; allowed: ["),
    ("[1, 2]", "must be a YAML mapping"),
    ("jobs: [", "is not valid YAML"),
])
def test_bad_config_file_value_is_one_line(tmp_path, capsys, text, needle):
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text(text + "\n")
    out = tmp_path / "never"
    assert main(["compare", "--config", str(cfg), "--out", str(out)]) == 2
    line = _one_error_line(capsys)
    assert needle in line and str(cfg) in line
    assert not out.exists()  # refused before anything was written


def test_bad_spec_file_for_generated_scenes_is_one_line(tmp_path, capsys):
    assert main(["compare", "--variant", "open", "--spec", str(tmp_path / "none.yaml"), "--out",
                 str(tmp_path / "r")]) == 2
    assert "cannot read scene spec" in _one_error_line(capsys)


@pytest.mark.parametrize("path, value, needle", [
    (("plate", "size_m"), [0.3, -0.3, 0.02], "field 'plate.size_m' = [0.3, -0.3, 0.02] (item 1): input should be greater than 0"),
    (("plate", "size_m"), [0.3, 0.3], "field 'plate.size_m' = [0.3, 0.3]: item 2 is missing"),
    (("cans", "count"), True, "field 'cans.count' = True: input should be a valid integer"),
    (("cans", "placement"), "grid", "field 'cans.placement' = 'grid': input should be 'random' or 'pickable'"),
    (("can", "color_rgba"), [1, 1, 1, 2], "(item 3): input should be less than or equal to 1"),
    (("cameras", "fov_y_deg"), float("nan"), "field 'cameras.fov_y_deg' = nan: input should be a finite number"),
    (("cameras", "clipping_m"), [3.0, 1.0], "field 'cameras.clipping_m' = [3.0, 1.0]: allowed: [near, far] with near < far"),
    (("bin", "wall_thickness_m"), 0.3, "field 'bin.wall_thickness_m' = 0.3: leaves no room inside the bin"),
    (("cameras", "poses", "top", "zoom"), 2, "field 'cameras.poses.top.zoom' is unknown; allowed: ['p_m', 'target_m']"),
])
def test_bad_scene_spec_value_is_one_line_naming_file_and_field(tmp_path, path, value, needle):
    raw = yaml.safe_load(DEFAULT_SPEC_PATH.read_text())
    node = raw
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    spec = tmp_path / "spec.yaml"
    spec.write_text(yaml.safe_dump(raw))
    with pytest.raises(SuiteError) as err:
        load_spec(spec, variant="open")
    msg = str(err.value)
    assert msg.startswith(f"scene spec {spec}: ") and needle in msg and "\n" not in msg


def test_valid_specs_parse_as_before():
    # the typed boundary changes no valid input: scene keys are pinned in test_families.py; here
    # the parsed values keep their types (floats stay floats, counts ints)
    spec = load_spec(variant="wall")
    assert spec.cans.count == 5 and isinstance(spec.cans.count, int)
    assert spec.table.size_m == (2.0, 2.0, 0.05) and all(isinstance(v, float) for v in spec.bin.center_xy_m)
    assert spec.wall is not None and spec.cameras.clipping_m == (0.05, 3.0)
