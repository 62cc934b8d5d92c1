"""Executors: run trial functions in worker processes with a hard time limit per trial.

The local executor keeps J spawned worker processes. The parent hands each a trial, waits for its
answer up to the trial's hard limit, and kills a worker that overruns (the trial gets a
`killed_timeout` record) or dies (a `crash` record); a fresh worker takes its place and the run
goes on. Results come back in completion order; only the parent writes records.
"""

from __future__ import annotations

import dataclasses
import logging
import multiprocessing as mp
import multiprocessing.connection
import os
import time
from collections import deque
from collections.abc import Callable, Iterator
from typing import Any

log = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True)
class Job:
    """A unit of work: `fn(payload)` must return a JSON-able dict, within `hard_limit_s`."""

    key: str
    fn: Callable[[Any], dict]
    payload: Any
    hard_limit_s: float
    group: str = ""  # jobs of one group share cached state (e.g. a scene's worlds) in a worker


@dataclasses.dataclass(frozen=True)
class Outcome:
    """A job's result, or how it failed ("crash" / "killed_timeout") with a message."""

    job: Job
    result: dict | None
    failure: str | None = None
    message: str = ""
    wall_time_s: float = 0.0


_RETIRE = False


def retire_worker() -> None:
    """Called by a job in a worker process: end this worker after its answer (e.g. after a
    MemoryError, whose process may be left in a bad state); the pool starts a fresh one."""
    global _RETIRE
    _RETIRE = True


def cap_workers(requested: int, pending: int) -> int:
    """The worker count for `pending` jobs: never more workers than jobs (said in a log line)."""
    n = max(1, min(requested, pending))
    if n < requested:
        log.info("starting %d worker(s), not %d: only %d trial(s) pending", n, requested, pending)
    return n


def _worker_main(conn, init: Callable[[], None] | None) -> None:
    from suite.run.interrupt import ignore_signals

    ignore_signals()  # the parent stops workers; the terminal's Ctrl-C is for the parent alone
    if init is not None:
        init()
    while True:
        try:
            item = conn.recv()
        except (EOFError, OSError):  # the parent has gone
            return
        if item is None:
            return
        fn, payload = item
        result = fn(payload)
        try:
            conn.send((result, _RETIRE))
        except OSError:  # the parent has gone while the job ran: nothing to report to
            return
        if _RETIRE:
            return


class _Worker:
    def __init__(self, ctx, init):
        from suite.run.interrupt import signals_blocked

        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_worker_main, args=(child, init), daemon=True)
        with signals_blocked():  # the child starts with SIGINT/SIGTERM ignored
            self.proc.start()
        child.close()
        self.job: Job | None = None
        self.group: str | None = None
        self.started = 0.0
        #: the worker asked to be replaced after its last answer (see `retire_worker`)
        self.retiring = False

    def submit(self, job: Job) -> None:
        self.job, self.group, self.started = job, job.group, time.monotonic()
        self.conn.send((job.fn, job.payload))

    def poll(self, ready) -> tuple[str | None, Any]:
        """The state of the running job after `multiprocessing.connection.wait` returned `ready`.

        Returns:
            ("done", result), ("crash", message) after killing the process, or (None, None) while
            the job still runs. The caller handles the hard limit.
        """
        if self.conn in ready:
            try:
                result, self.retiring = self.conn.recv()
            except (EOFError, OSError):
                result = None
            if result is not None:
                self.job = None
                return "done", result
        if self.proc.sentinel in ready or not self.proc.is_alive() or self.conn in ready:
            self.proc.join(timeout=2.0)  # the pipe's EOF can arrive before the exit code is set
            code = self.proc.exitcode
            self.kill()
            return "crash", f"worker exited with code {code}"
        return None, None

    def kill(self) -> None:
        try:
            self.proc.kill()
        except Exception:  # already gone
            pass
        self.proc.join(timeout=5)
        self.conn.close()

    def stop(self) -> None:
        try:
            self.conn.send(None)
        except (BrokenPipeError, OSError):
            pass
        self.proc.join(timeout=5)
        if self.proc.is_alive():
            self.kill()


class LocalExecutor:
    """A pool of `jobs` spawned worker processes.

    Args:
        jobs: number of worker processes.
        init: called once in each worker before its first job (e.g. to quiet logging or seed
            process-global RNGs).
    """

    def __init__(self, *, jobs: int, init: Callable[[], None] | None = None) -> None:
        self.jobs = jobs
        self.init = init
        self._ctx = mp.get_context("spawn")
        self._workers: list[_Worker] = []

    def start(self, n: int | None = None) -> None:
        """Spawn the workers now (they import and initialise while the caller prepares work);
        `run` stops those beyond the number of jobs it is given."""
        # One thread per worker: the pool is the parallelism; BLAS/OpenMP thread pools in every
        # worker would only contend for the same cores. Children inherit this environment.
        for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
            os.environ.setdefault(var, "1")
        while len(self._workers) < (self.jobs if n is None else n):
            self._workers.append(_Worker(self._ctx, self.init))

    def close(self) -> None:
        for w in self._workers:
            w.stop()
        self._workers = []

    def abort(self) -> None:
        """Kill every worker now (an interrupted or failed run: the jobs in flight are dropped)."""
        for w in self._workers:
            w.kill()
        self._workers = []

    @staticmethod
    def _pick(queue: deque, w: _Worker, workers: list[_Worker]) -> Job:
        """The next job for a free worker: one of its last group (its caches are warm), else one
        of a group no other worker is on, else the oldest."""
        taken = {o.group for o in workers if o is not w and o.job is not None}
        fallback = None
        for i, job in enumerate(queue):
            if job.group == w.group:
                del queue[i]
                return job
            if fallback is None and job.group not in taken:
                fallback = i
        if fallback is not None:
            job = queue[fallback]
            del queue[fallback]
            return job
        return queue.popleft()

    def run(self, jobs: list[Job]) -> Iterator[Outcome]:
        """Run the jobs; yield each outcome as it completes. The workers stop at the end."""
        queue = deque(jobs)
        if not jobs:
            self.close()
            return
        n = cap_workers(self.jobs, len(jobs))
        for extra in self._workers[n:]:  # started early, before the jobs were known; never used
            extra.kill()
        del self._workers[n:]
        self.start(n)
        workers = self._workers
        try:
            while queue or any(w.job is not None for w in workers):
                for i, w in enumerate(workers):
                    if w.job is None and queue:
                        if not w.proc.is_alive():  # died between jobs: replace it, blame no job
                            w.kill()
                            w = workers[i] = _Worker(self._ctx, self.init)
                        w.submit(self._pick(queue, w, workers))
                busy = [w for w in workers if w.job is not None]
                now = time.monotonic()
                timeout = max(0.0, min(w.started + w.job.hard_limit_s - now for w in busy))
                ready = mp.connection.wait([w.conn for w in busy] + [w.proc.sentinel for w in busy],
                                           timeout=min(timeout, 1.0))
                for i, w in enumerate(workers):
                    if w.job is None:
                        continue
                    job, elapsed = w.job, time.monotonic() - w.started
                    state, value = w.poll(ready)
                    if state == "done":
                        if w.retiring:
                            w.stop()
                            workers[i] = _Worker(self._ctx, self.init)
                        yield Outcome(job, value, None, "", elapsed)
                        continue
                    if state == "crash":
                        workers[i] = _Worker(self._ctx, self.init)
                        yield Outcome(job, None, "crash", value, elapsed)
                    elif elapsed > job.hard_limit_s:
                        w.kill()
                        workers[i] = _Worker(self._ctx, self.init)
                        yield Outcome(job, None, "killed_timeout",
                                      f"killed after {elapsed:.1f} s (hard limit {job.hard_limit_s:.1f} s)", elapsed)
        except BaseException:  # interrupted, or the caller stopped (GeneratorExit): no waiting
            self.abort()
            raise
        finally:
            self.close()


def cpu_description() -> dict[str, Any]:
    """CPU model and core count of this machine (for manifests)."""
    model = ""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return {"cpu": model or os.uname().machine, "cores": os.cpu_count()}
