"""Clean interruption: SIGINT and SIGTERM become one exception in the parent, workers ignore them.

`SignalGuard` turns the first SIGINT or SIGTERM into `Interrupted` (raised in the main thread)
after killing the worker processes, so the run stops at once, keeps every finished record and
says how to continue. A signal that
arrives while a record is being written (`critical()`) is held until the write is complete, so no
record is torn by it. A second signal ends the process at once: the worker processes this process
started are killed and it exits with 128 + the signal's number.

Worker processes never see the terminal's Ctrl-C: they are started with SIGINT and SIGTERM ignored
(`signals_blocked()`: a spawned child inherits ignored signals across exec, though not the parent's
blocked mask) and keep ignoring both, and the parent kills them.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import signal
import threading
from collections.abc import Iterator

SIGNALS = (signal.SIGINT, signal.SIGTERM)

_ACTIVE: "SignalGuard | None" = None


class Interrupted(BaseException):
    """The run was stopped by a signal (a BaseException: no `except Exception` swallows it)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = int(signum)

    @property
    def name(self) -> str:
        return signal.Signals(self.signum).name

    @property
    def exit_code(self) -> int:
        """130 for SIGINT, 143 for SIGTERM (the shell's convention: 128 + the signal's number)."""
        return 128 + self.signum


class SignalGuard:
    """While active (a context manager, main thread only): SIGINT/SIGTERM raise `Interrupted`."""

    def __init__(self) -> None:
        self.signals_seen = 0
        self._critical = 0
        self._pending: int | None = None
        self._previous: dict[int, object] = {}

    def __enter__(self) -> "SignalGuard":
        global _ACTIVE
        if threading.current_thread() is threading.main_thread():
            for s in SIGNALS:
                self._previous[s] = signal.signal(s, self._handle)
            _ACTIVE = self
        return self

    def __exit__(self, *exc) -> None:
        global _ACTIVE
        for s, handler in self._previous.items():
            signal.signal(s, handler)
        self._previous = {}
        if _ACTIVE is self:
            _ACTIVE = None

    def _handle(self, signum: int, frame) -> None:
        self.signals_seen += 1
        if self.signals_seen > 1:
            _exit_now(signum)
        # Stop the workers now: their trials are dropped (rerun on resume), and a pool that would
        # wait for its running jobs on the way out (concurrent.futures) has none left to wait for.
        kill_children()
        if self._critical:
            self._pending = signum
            return
        raise Interrupted(signum)

    @contextlib.contextmanager
    def critical(self) -> Iterator[None]:
        """Hold a signal until the block is done (e.g. one record's write and flush)."""
        self._critical += 1
        try:
            yield
        finally:
            self._critical -= 1
            if not self._critical and self._pending is not None:
                signum, self._pending = self._pending, None
                raise Interrupted(signum)


def critical() -> contextlib.AbstractContextManager:
    """The active guard's `critical()`, or a no-op when no guard is active."""
    return _ACTIVE.critical() if _ACTIVE is not None else contextlib.nullcontext()


def _exit_now(signum: int) -> None:
    """The second signal: kill our worker processes and leave without any clean-up."""
    try:
        os.write(2, f"\n{signal.Signals(signum).name} again: stopping at once\n".encode())
    except OSError:
        pass
    kill_children()
    os._exit(128 + signum)


def kill_children() -> None:
    """SIGKILL every live child process started by multiprocessing (workers ignore SIGTERM)."""
    for child in mp.active_children():
        try:
            os.kill(child.pid, signal.SIGKILL)
        except (OSError, TypeError):
            pass


def reap_children(*, keep: frozenset[int] = frozenset(), timeout_s: float = 5.0) -> None:
    """Join this process's multiprocessing children (except the pids in `keep`, e.g. those alive
    before a run started); kill those still alive after `timeout_s`."""
    children = [c for c in mp.active_children() if c.pid not in keep]
    for child in children:
        child.join(timeout=timeout_s)
    for child in children:
        if child.is_alive():
            child.kill()
            child.join(timeout=2.0)
    _stop_resource_tracker()


def _stop_resource_tracker() -> None:
    """Stop (and wait for) the resource tracker that spawning workers started: left to exit after
    this process, it would be an orphan, a zombie where the container's init does not reap."""
    from multiprocessing import resource_tracker

    stop = getattr(resource_tracker._resource_tracker, "_stop", None)  # CPython 3.8+ (private)
    if stop is not None:
        try:
            stop()
        except Exception:  # nothing to stop, or already stopping: the tracker exits with us anyway
            pass


@contextlib.contextmanager
def signals_blocked() -> Iterator[None]:
    """Start processes inside this: SIGINT and SIGTERM are blocked in this thread and, in the main
    thread, ignored meanwhile, so that a spawned child starts with both ignored and not even its
    start-up imports can be interrupted by the terminal's Ctrl-C. (A spawned child does not inherit
    the blocked mask: Python's fork-exec clears it; it does inherit ignored signals, and Python keeps
    an ignored SIGINT ignored.) A signal that arrives meanwhile stays pending, blocked, and is
    delivered to this process's own handler when the block ends."""
    old = signal.pthread_sigmask(signal.SIG_BLOCK, SIGNALS)
    handlers = {}
    try:
        if threading.current_thread() is threading.main_thread():
            handlers = {s: signal.signal(s, signal.SIG_IGN) for s in SIGNALS}
        yield
    finally:
        for s, handler in handlers.items():
            signal.signal(s, handler)  # before unblocking: a pending signal goes to the handler
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def ignore_signals() -> None:
    """In a worker process: SIGINT and SIGTERM do nothing (the parent stops workers)."""
    for s in SIGNALS:
        signal.signal(s, signal.SIG_IGN)
