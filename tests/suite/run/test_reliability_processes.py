"""Reliability with real second processes: two runs into one directory, Ctrl-C and SIGTERM.

The runs use the `sleepy` fixture planner (0.3 s per trial, no solution) on generated `open`
scenes, so that they are slow enough to interrupt and fast to finish.

Every wait here is for an event (a record, a file, a line, a worker process, the process's exit),
under a deadline generous enough for a slow or busy machine; nothing is timed.
"""

from __future__ import annotations

import json
import os
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
FAULTY = ROOT / "tests" / "fixtures" / "faulty"
#: Longest wait for an event (a record, a file, a worker, an exit): only a hang reaches it.
DEADLINE_S = 300.0
SLEEPY = ["--planners", "sleepy", "--variant", "open", "--cans", "1", "--jobs", "1", "--no-plots", "--no-progress"]


def _env():
    return dict(os.environ, PYTHONPATH=os.pathsep.join([str(FAULTY), str(ROOT)]))


def _start(args, **kw):
    return subprocess.Popen([sys.executable, "-m", "suite", "compare", *args], cwd=ROOT, env=_env(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True, **kw)


def _lines(out: Path) -> list[dict]:
    path = out / "trials.jsonl"
    return [json.loads(line) for line in path.read_text().splitlines()] if path.exists() else []


def _wait_until(condition, proc, what: str, timeout_s: float = DEADLINE_S) -> None:
    """Poll `condition()` until it holds; fail if `proc` ends first or nothing happens for `timeout_s`."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert proc.poll() is None, (f"the process ended before {what}", proc.communicate())
        assert time.monotonic() < deadline, f"no {what} within {timeout_s:.0f} s"
        time.sleep(0.05)


def _wait_for_records(out: Path, n: int, proc) -> None:
    _wait_until(lambda: len(_lines(out)) >= n, proc, f"{n} record(s) written")


def _has_worker(pid: int) -> bool:
    """Whether process `pid` has a multiprocessing worker child (spawned: `spawn_main`)."""
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            ppid = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
            if ppid == pid and b"spawn_main" in (d / "cmdline").read_bytes():
                return True
        except (OSError, ValueError, IndexError):  # the process ended meanwhile
            continue
    return False


def _group_gone(pgid: int, timeout_s: float = 60.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.05)
    return False


def test_two_runs_started_at_once_into_one_directory(tmp_path):
    out = tmp_path / "same"
    procs = [_start([*SLEEPY, "--scenes", "1", "--out", str(out)]) for _ in range(2)]
    results = [(p.wait(timeout=DEADLINE_S), *p.communicate()) for p in procs]
    codes = sorted(r[0] for r in results)
    assert codes == [0, 2], results
    loser = next(r for r in results if r[0] == 2)
    errors = [line for line in loser[2].splitlines() if line.strip()]
    winner_pid = next(p.pid for p, r in zip(procs, results) if r[0] == 0)
    # The holder writes its PID just after taking the lock: a loser that reads in between says "unknown".
    assert errors in ([(f"error: '{out}' is in use by another run (PID {pid}); wait for it to end, "
                        "or use another directory")] for pid in (winner_pid, "unknown")), errors
    ids = [r["trial_id"] for r in _lines(out)]
    assert len(ids) == len(set(ids)) == 5  # every trial once: nothing doubled


def test_interrupt_terminate_and_resume_lose_and_double_nothing(tmp_path):
    out = tmp_path / "run"
    proc = _start([*SLEEPY, "--scenes", "2", "--out", str(out)])
    _wait_for_records(out, 1, proc)
    os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C in a terminal does: the whole process group
    _, err = proc.communicate(timeout=DEADLINE_S)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    kept = len(_lines(out))
    resume = f"python -m suite compare --resume --out {out}"
    assert err.strip().splitlines()[-1] == (f"interrupted by SIGINT: {kept} trial(s) recorded in {out} are kept; "
                                            f"resume with: {resume}")
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["status"] == "interrupted" and manifest["interrupted_by"] == "SIGINT"
    total = manifest["trials_total"]  # 2 scenes x 5 problems, identical ones planned once
    assert manifest["trials_recorded"] == kept and total >= kept + 2
    assert _group_gone(proc.pid), "worker processes outlived the run"

    # the printed command resumes; SIGTERM (e.g. from a batch scheduler) to the parent stops it again
    proc = _start(shlex.split(resume)[4:])
    _wait_for_records(out, kept + 1, proc)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=DEADLINE_S)
    assert proc.returncode == 143 and "Traceback" not in err, err
    assert "interrupted by SIGTERM" in err.strip().splitlines()[-1]
    assert json.loads((out / "manifest.json").read_text())["interrupted_by"] == "SIGTERM"
    assert _group_gone(proc.pid)

    proc = _start(shlex.split(resume)[4:])
    _, err = proc.communicate(timeout=DEADLINE_S)
    assert proc.returncode == 0, err
    assert _group_gone(proc.pid), "worker processes outlived a completed run"
    ids = [r["trial_id"] for r in _lines(out)]
    assert len(ids) == len(set(ids)) == total  # trials lost 0, doubled 0
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["status"] == "complete" and manifest["trials_recorded"] == total


def test_second_ctrl_c_ends_at_once(tmp_path):
    out = tmp_path / "twice"
    proc = _start([*SLEEPY, "--scenes", "2", "--out", str(out)])
    _wait_for_records(out, 1, proc)
    os.killpg(proc.pid, signal.SIGINT)
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=DEADLINE_S)
    assert proc.returncode == 130 and "Traceback" not in err, err
    # The second signal ends it without the clean-up (or, when the two arrive as one, the first
    # ends it cleanly); how soon is the machine's business, not this test's.
    last = err.strip().splitlines()[-1]
    assert last == "SIGINT again: stopping at once" or last.startswith("interrupted by SIGINT: "), err
    assert _group_gone(proc.pid)
    ids = [r["trial_id"] for r in _lines(out)]  # whatever was recorded is whole
    assert len(ids) == len(set(ids)) >= 1


def test_interrupted_dataset_build_writes_nothing(tmp_path):
    target = tmp_path / "ds"
    proc = subprocess.Popen([sys.executable, "-m", "suite", "dataset", "build", "--name", str(target), "--variants",
                             "wall", "--scenes", "2", "--cans", "2", "--reference-time-s", "1", "--jobs", "1",
                             "--no-progress"], cwd=ROOT, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)
    # the build has started (its directory is locked) and a worker is building
    _wait_until(lambda: (target / ".lock").exists() and _has_worker(proc.pid), proc, "build worker")
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=DEADLINE_S)
    assert proc.returncode == 130 and "Traceback" not in err, err
    assert err.strip().splitlines()[-1] == ("interrupted by SIGINT: nothing written (a dataset is written only when "
                                            "complete); run the same command again to build it")
    assert not (target / "manifest.json").exists()
    assert _group_gone(proc.pid)


def test_interrupted_execute_writes_nothing(tmp_path):
    out = tmp_path / "exec"
    err_path = tmp_path / "stderr.txt"
    with open(err_path, "w") as err_file:
        # the `stalling` fixture planner waits until it is killed: planning is under way when the
        # signal comes, however fast the machine (a real planner may finish first: that raced)
        proc = subprocess.Popen([sys.executable, "-m", "suite", "execute", "--planner", "stalling", "--variant",
                                 "open", "--cans", "1", "--seed", "1", "--no-replay", "--out", str(out)], cwd=ROOT,
                                env=dict(_env(), SUITE_TEST_MARKER_DIR=str(tmp_path)), stdout=subprocess.DEVNULL,
                                stderr=err_file, text=True, start_new_session=True)
    # arguments checked, the output directory made, the scene built: planning has started
    _wait_until(lambda: (tmp_path / "planning").exists(), proc, "the planner's first plan call")
    os.killpg(proc.pid, signal.SIGTERM)
    proc.wait(timeout=DEADLINE_S)
    err = err_path.read_text()
    assert proc.returncode == 143 and "Traceback" not in err, err
    assert err.strip().splitlines()[-1] == f"interrupted by SIGTERM: nothing written to {out}"
    assert not (out / "execution.json").exists()
    assert _group_gone(proc.pid)


def test_interrupted_regions_build_keeps_the_worlds_built(tmp_path):
    out = tmp_path / "regions"
    proc = subprocess.Popen([sys.executable, "-m", "suite", "regions", "build", "--dataset", "recycle-v1:quick",
                             "--out", str(out), "--iris", "zo", "--jobs", "1", "--limit", "40"], cwd=ROOT, env=_env(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    # two worlds built: interrupt the third or a later one
    _wait_until(lambda: len(list(out.glob("*.npz"))) >= 2, proc, "two worlds' regions files", timeout_s=900)
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=DEADLINE_S)
    assert proc.returncode == 130 and "Traceback" not in err, err
    # the build reports the worlds whose regions are on disk (a worker writes its world's file
    # before the build receives its result): the same count as the files there now
    kept = len(list(out.glob("*.npz")))
    assert kept >= 2 and err.strip().splitlines()[-1] == (
        f"interrupted by SIGINT: the {kept} world(s) finished are kept in {out}; run the same command again to "
        "build the rest")
    assert not (out / ".lock").exists() and not list(out.glob("build*.json"))
    assert _group_gone(proc.pid)


def test_no_process_outlives_a_finished_run(tmp_path):
    out = tmp_path / "run"
    proc = _start([*SLEEPY, "--scenes", "1", "--out", str(out)])
    _, err = proc.communicate(timeout=DEADLINE_S)
    assert proc.returncode == 0, err
    try:  # at the very moment the run has exited, nothing of its process group is left
        os.killpg(proc.pid, 0)
        left = True
    except ProcessLookupError:
        left = False
    assert not left, "a worker or the resource tracker outlived the run"
