"""Reliability on a Dask cluster: a worker killed in the middle of a trial loses and doubles nothing.

A 2-worker local cluster that allows one failure per task: the trial that kills its worker once is
retried on the other worker and recorded once; the one that kills every worker it lands on is
recorded as `crash`; every other trial (some were queued on the killed workers) is recorded once.
"""

from __future__ import annotations

from pathlib import Path

import pytest

distributed = pytest.importorskip("distributed")

from suite.run.dask_executor import DaskExecutor  # noqa: E402
from suite.run.records import read_trials  # noqa: E402
from suite.run.runner import CompareConfig, WorkerInit, prepare_trials, run_trials  # noqa: E402

FAULTY = Path(__file__).resolve().parents[2] / "fixtures" / "faulty"


@pytest.mark.slow  # 15 s each (a cluster, Drake in its sandboxes, workers restarted); the executor-level
# versions of both cases run by default in test_dask_executor.py
@pytest.mark.parametrize("kill_always", [
    "",  # a worker dies once, in the middle of a trial: the trial is retried elsewhere
    "lift",  # and a trial that kills every worker it runs on: a crash record
])
def test_lost_worker_trial_retried_once_or_crash_nothing_lost_or_doubled(tmp_path, monkeypatch, kill_always):
    import dask

    monkeypatch.setenv("SUITE_TEST_KILL_ALWAYS", kill_always)
    monkeypatch.syspath_prepend(str(FAULTY))
    monkeypatch.setenv("PYTHONPATH", f"{FAULTY}:{Path(__file__).resolve().parents[3]}")  # the cluster's workers
    monkeypatch.setenv("SUITE_TEST_MARKER_DIR", str(tmp_path))
    trials = prepare_trials(CompareConfig(planners=("workerkiller", "ik"), variant="open", scenes=1, cans=1,
                                          dataset=None, time_limit_s=2.0))
    out = tmp_path / "run"
    out.mkdir()
    with dask.config.set({"distributed.scheduler.allowed-failures": 1}):
        cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                           dashboard_address=None, silence_logs=40)
    try:
        ex = DaskExecutor(scheduler=cluster.scheduler_address, init=WorkerInit())
        counts = run_trials(trials, out=out, jobs=2, executor=ex, progress_bar=False)
    finally:
        cluster.close()
    recs = read_trials(out)
    ids = [r.trial_id for r in recs]
    assert counts == {"total": 10, "skipped": 0, "ran": 10}
    assert sorted(ids) == sorted(t.trial_id for t in trials)  # lost 0, doubled 0
    by = {(r.planner, r.problem): r for r in recs}
    assert (tmp_path / "killed-transit").exists()
    assert by[("workerkiller", "transit")].status == "no_solution"  # retried once, elsewhere
    lift = by[("workerkiller", "lift")]
    if kill_always:
        assert lift.status == "crash" and "Dask worker died" in lift.stats["error"]
    else:
        assert lift.status == "no_solution"
    assert all(by[("ik", k)].status == "success" for k in ("approach", "descend", "lift"))
