"""The Dask executor: same records as the local pool, hard limits and crash isolation on a cluster."""

import importlib.util
import json
import os
import signal
import time

import pytest

distributed = pytest.importorskip("distributed")

from suite.run.dask_executor import DaskExecutor  # noqa: E402
from suite.run.executors import Job  # noqa: E402
from suite.run.runner import TRIALS_FILE, CompareConfig, prepare_trials, run_trials  # noqa: E402


# Executor-mechanics workloads (module level: the workers import them by reference).
def _sandbox_pid(payload):
    return {"pid": os.getpid(), "worker_pid": os.getppid(), "n": payload}


def _sleep(seconds):
    time.sleep(seconds)
    return {"slept_s": seconds}


def _segfault(_):
    os.kill(os.getpid(), signal.SIGSEGV)
    time.sleep(10)


def _kill_worker_first_time(marker):
    """Kills the Dask worker running it (the sandbox's parent) unless `marker` exists."""
    if os.path.exists(marker):
        return {"attempt": "retry"}
    open(marker, "w").close()
    os.kill(os.getppid(), signal.SIGKILL)
    os._exit(0)


def _kill_worker_always(_):
    os.kill(os.getppid(), signal.SIGKILL)
    os._exit(0)


@pytest.fixture(scope="module")
def cluster():
    import dask

    with dask.config.set({"distributed.scheduler.allowed-failures": 1}):
        c = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                     dashboard_address=None, silence_logs=40)
    yield c
    c.close()


#: The hard limit of jobs that should finish (they take well under a second): only a hang reaches
#: it, so it can be generous for a slow or busy machine (a job's limit counts its unpickling too).
ROOMY_S = 120.0


def _outcomes(ex, jobs):
    return {o.job.key: o for o in ex.run(jobs)}


def test_same_seed_same_records_as_local_pool(tmp_path):
    planners = ("ik", "rrt") if importlib.util.find_spec("planners.ompl_rrt") else ("ik",)
    # a budget with a wide margin (rrt solves these in well under a second and returns then): a
    # trial timing out on a busy machine in one run and not the other would make the records differ
    cfg = CompareConfig(planners=planners, variant="wall", seed=3, scenes=1, cans=1, grasps="truth",
                        time_limit_s=30.0, jobs=2, dataset=None)
    trials = prepare_trials(cfg)
    records = {}
    for executor in ("local", "dask"):
        out = tmp_path / executor
        out.mkdir()
        counts = run_trials(trials, out=out, jobs=2, executor=executor, progress_bar=False)
        assert counts == {"total": len(trials), "skipped": 0, "ran": len(trials)}
        lines = [json.loads(line) for line in (out / TRIALS_FILE).read_text().splitlines()]
        records[executor] = {r["trial_id"]: r for r in lines}
    assert len(records["dask"]) == len(trials) == len(records["local"])
    assert set(records["dask"]) == {t.trial_id for t in trials}
    for tid, local in records["local"].items():
        dask_rec = records["dask"][tid]
        assert dask_rec["status"] == local["status"], tid
        assert dask_rec["path"] == local["path"], tid
        assert dask_rec["q_goal"] == local["q_goal"], tid
    assert any(r["status"] == "success" for r in records["dask"].values())
    # resume: nothing left to run, nothing written twice
    counts = run_trials(trials, out=tmp_path / "dask", jobs=2, executor="dask", progress_bar=False)
    assert counts["ran"] == 0
    assert len((tmp_path / "dask" / TRIALS_FILE).read_text().splitlines()) == len(trials)


def test_hang_and_segfault_become_records_and_sandboxes_persist(cluster):
    ex = DaskExecutor(scheduler=cluster.scheduler_address)
    jobs = [Job(f"ok{i}", _sandbox_pid, i, ROOMY_S) for i in range(6)]
    jobs += [Job("hang", _sleep, 600.0, 1.5), Job("segv", _segfault, None, ROOMY_S)]
    jobs += [Job(f"after{i}", _sandbox_pid, i, ROOMY_S) for i in range(4)]
    got = _outcomes(ex, jobs)
    assert set(got) == {j.key for j in jobs}
    # killed at its hard limit, not before (it would have slept 600 s: how soon after is the machine's)
    assert got["hang"].failure == "killed_timeout" and got["hang"].wall_time_s >= 1.5
    assert got["segv"].failure == "crash" and str(-signal.SIGSEGV) in got["segv"].message
    ok = [o for k, o in got.items() if k not in ("hang", "segv")]
    assert all(o.failure is None for o in ok)
    # the Dask workers survived; each keeps one sandbox between jobs (so its scene caches live on):
    # 2 first sandboxes, plus at most one replacement for each of the hung and the crashed job
    assert len({o.result["worker_pid"] for o in ok}) <= 2
    assert len({o.result["pid"] for o in ok}) <= 4
    assert all(o.result["pid"] != o.result["worker_pid"] for o in ok)


def test_killed_worker_is_retried_or_recorded_as_crash(cluster, tmp_path):
    ex = DaskExecutor(scheduler=cluster.scheduler_address)
    # the worker running "once" dies once: its tasks are retried elsewhere (allowed-failures=1)
    jobs = [Job("once", _kill_worker_first_time, str(tmp_path / "marker"), ROOMY_S)]
    jobs += [Job(f"ok{i}", _sleep, 0.2, ROOMY_S) for i in range(4)]
    got = _outcomes(ex, jobs)
    assert set(got) == {j.key for j in jobs}
    assert (tmp_path / "marker").exists()
    assert got["once"].failure is None and got["once"].result == {"attempt": "retry"}
    assert all(got[f"ok{i}"].result == {"slept_s": 0.2} for i in range(4))
    # a task that kills every worker it lands on: KilledWorker -> a crash outcome; the run finishes
    jobs = [Job("always", _kill_worker_always, None, ROOMY_S)]
    got = _outcomes(ex, jobs)
    assert set(got) == {"always"}
    assert got["always"].failure == "crash" and "Dask worker died" in got["always"].message


def test_a_task_the_cluster_cannot_run_stops_the_run(cluster):
    from scenes.errors import SuiteError

    # a lambda crosses to the worker (cloudpickle) but not into the sandbox (pickle): an error outside
    # the sandbox is the cluster's, not the trial's, so no record is made for it
    ex = DaskExecutor(scheduler=cluster.scheduler_address)
    with pytest.raises(SuiteError, match="could not run trial lam"):
        _outcomes(ex, [Job("lam", lambda p: {"x": p}, 1, ROOMY_S)])
    assert _outcomes(ex, [Job("ok", _sleep, 0.1, ROOMY_S)])["ok"].result == {"slept_s": 0.1}


def test_parent_backstop_cancels_a_task_past_its_deadline(cluster, monkeypatch):
    import suite.run.dask_executor as dx

    # make the parent's deadline (2 x hard limit + grace) fall 1 s after the task is seen running,
    # well before the worker-side kill at the 10 s hard limit: the message says which one stopped it
    monkeypatch.setattr(dx, "BACKSTOP_GRACE_S", -19.0)
    ex = DaskExecutor(scheduler=cluster.scheduler_address)
    got = _outcomes(ex, [Job("stuck", _sleep, 60.0, 10.0)])
    assert got["stuck"].failure == "killed_timeout" and "cancelled by the parent" in got["stuck"].message
