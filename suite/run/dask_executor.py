"""The Dask executor: run trial functions on a Dask cluster with the local executor's contract.

Each Dask task runs its job inside a *sandbox*: a spawned child process of the Dask worker that
lives across tasks (so `planners.worlds` keeps its per-process scene caches) and is killed and
replaced when a job overruns its hard limit (`killed_timeout`) or dies (`crash`). A segfault or a
hang inside a trial therefore never takes the Dask worker down. If the Dask worker itself dies,
the scheduler retries its task on another worker up to `distributed.scheduler.allowed-failures`
times, then fails it with KilledWorker, which becomes a `crash` outcome. As a backstop the parent
cancels a task still running well past its hard limit and records `killed_timeout`.

Outcomes are yielded in completion order; only the parent writes records.
"""

from __future__ import annotations

import logging
import multiprocessing as mp
import multiprocessing.connection
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from typing import Any

from scenes.errors import SuiteError
from suite.run.executors import Job, Outcome, _Worker

log = logging.getLogger(__name__)

#: The parent cancels a task this long past (twice) its hard limit, counted from when it was first
#: seen on a worker (a worker may hold one queued task behind the running one).
BACKSTOP_GRACE_S = 60.0
POLL_S = 1.0

# Worker side: one sandbox process per Dask worker thread (and init function).
_SANDBOXES: dict[tuple[int, Any], _Worker] = {}
_SANDBOX_LOCK = threading.Lock()


def _new_sandbox(init: Callable[[], None] | None) -> _Worker:
    proc = mp.current_process()
    daemonic = proc._config.get("daemon", False)
    if daemonic:
        # Dask's nanny starts workers as daemonic processes (distributed.worker.daemon, default
        # True) and multiprocessing refuses children of daemonic processes. The sandbox is itself
        # daemonic and exits on its pipe's EOF, so lifting the flag while starting it is safe.
        proc._config["daemon"] = False
    try:
        return _Worker(mp.get_context("spawn"), init)
    finally:
        if daemonic:
            proc._config["daemon"] = True


def run_in_sandbox(fn: Callable[[Any], dict], payload: Any, hard_limit_s: float,
                   init: Callable[[], None] | None) -> tuple[str | None, Any, float]:
    """Run `fn(payload)` in this worker's sandbox process (the body of every Dask task).

    Returns:
        (failure, result_or_message, wall_time_s): failure None with the result dict, or
        "crash" / "killed_timeout" with a message.
    """
    slot = (threading.get_ident(), init)
    with _SANDBOX_LOCK:
        w = _SANDBOXES.get(slot)
    if w is None or not w.proc.is_alive():
        if w is not None:
            w.kill()
        w = _new_sandbox(init)
        with _SANDBOX_LOCK:
            _SANDBOXES[slot] = w
    w.submit(Job("", fn, payload, hard_limit_s))
    deadline = w.started + hard_limit_s
    while True:
        ready = mp.connection.wait([w.conn, w.proc.sentinel], timeout=max(0.0, deadline - time.monotonic()))
        elapsed = time.monotonic() - w.started
        state, value = w.poll(ready)
        if state == "done":
            if w.retiring:  # the job asked for a fresh process (e.g. after a MemoryError)
                w.stop()
                _SANDBOXES.pop(slot, None)
            return None, value, elapsed
        if state == "crash":
            _SANDBOXES.pop(slot, None)
            return "crash", value, elapsed
        if elapsed >= hard_limit_s:
            w.kill()
            _SANDBOXES.pop(slot, None)
            return "killed_timeout", f"killed after {elapsed:.1f} s (hard limit {hard_limit_s:.1f} s)", elapsed


class DaskExecutor:
    """Run jobs on a Dask cluster: an existing scheduler, or a LocalCluster started for the run.

    Args:
        scheduler: address of a running scheduler (tcp://HOST:8786); None starts a LocalCluster
            of `n_workers` single-threaded worker processes and closes it after the run.
        n_workers: workers of the LocalCluster (ignored with a scheduler).
        init: called once in each sandbox process before its first job (as in LocalExecutor).
        host: interface the LocalCluster listens on.
    """

    def __init__(self, *, scheduler: str | None, n_workers: int = 2,
                 init: Callable[[], None] | None = None, host: str = "127.0.0.1") -> None:
        self.scheduler = scheduler
        self.n_workers = n_workers
        self.init = init
        self.host = host

    def _connect(self, n_jobs: int):
        try:
            from distributed import Client, LocalCluster
        except ImportError:
            raise SuiteError("--executor dask needs the 'distributed' package; "
                             "install it with: pip install '.[cluster]'") from None
        if self.scheduler is None:
            from suite.run.executors import cap_workers
            from suite.run.interrupt import signals_blocked

            # The cluster's processes start with SIGINT/SIGTERM ignored (and the loop thread that
            # starts them with both blocked): the terminal's Ctrl-C reaches this process alone,
            # which closes the cluster.
            with signals_blocked():
                cluster = LocalCluster(n_workers=cap_workers(self.n_workers, n_jobs), threads_per_worker=1,
                                       processes=True, host=self.host, dashboard_address=None,
                                       silence_logs=logging.WARNING)
            return Client(cluster), cluster
        try:
            return Client(self.scheduler, timeout=30), None
        except (OSError, TimeoutError) as exc:
            raise SuiteError(f"cannot reach the Dask scheduler {self.scheduler!r}: {exc}") from None

    def run(self, jobs: list[Job]) -> Iterator[Outcome]:
        """Submit all jobs; yield each outcome as it completes (any order)."""
        if not jobs:
            return
        from distributed import wait
        from distributed.client import FutureCancelledError

        client, cluster = self._connect(len(jobs))
        run_id = uuid.uuid4().hex[:8]
        pending = {}
        try:
            for job in jobs:
                fut = client.submit(run_in_sandbox, job.fn, job.payload, job.hard_limit_s, self.init,
                                    key=f"trial-{job.key}-{run_id}", pure=False)
                pending[fut] = job
            first_seen: dict[str, float] = {}
            while pending:
                try:
                    done, _ = wait(list(pending), timeout=POLL_S, return_when="FIRST_COMPLETED")
                except TimeoutError:
                    done = set()
                for fut in done:
                    job = pending.pop(fut)
                    yield self._outcome(fut, job, first_seen.get(fut.key), FutureCancelledError)
                if not pending:
                    break
                now = time.monotonic()
                try:
                    processing = client.processing()
                except Exception:  # the scheduler is busy or reconnecting: check again next round
                    processing = {}
                for keys in processing.values():
                    for key in keys:
                        first_seen.setdefault(key, now)
                for fut, job in list(pending.items()):
                    seen = first_seen.get(fut.key)
                    if seen is not None and now - seen > 2 * job.hard_limit_s + BACKSTOP_GRACE_S:
                        log.warning("trial %s still running %.0f s after it started; cancelling it",
                                    job.key, now - seen)
                        del pending[fut]
                        fut.cancel()
                        yield Outcome(job, None, "killed_timeout",
                                      f"cancelled by the parent after {now - seen:.1f} s "
                                      f"(hard limit {job.hard_limit_s:.1f} s)", now - seen)
        finally:
            if pending:
                client.cancel(list(pending))
            client.close()
            if cluster is not None:
                cluster.close()

    @staticmethod
    def _outcome(fut, job: Job, seen: float | None, cancelled_error) -> Outcome:
        from distributed import KilledWorker

        elapsed = 0.0 if seen is None else time.monotonic() - seen
        try:
            failure, value, wall_time_s = fut.result()
        except KilledWorker as exc:
            return Outcome(job, None, "crash", f"Dask worker died running it: {exc}", elapsed)
        except cancelled_error:
            return Outcome(job, None, "crash", "task cancelled on the cluster", elapsed)
        except Exception as exc:
            # Outside the sandbox: the cluster cannot run tasks at all (the package or a dependency
            # missing on the scheduler or a worker). Not the trial's fault: stop, record nothing.
            first_line = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
            raise SuiteError(f"the Dask cluster could not run trial {job.key}: {type(exc).__name__}: {first_line} "
                             "(the scheduler and every worker need this package installed)") from exc
        if failure is None:
            return Outcome(job, value, None, "", wall_time_s)
        return Outcome(job, None, failure, value, wall_time_s)
