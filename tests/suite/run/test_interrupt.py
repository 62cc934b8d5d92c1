"""Starting worker processes: a spawned child starts with SIGINT/SIGTERM ignored, and a signal that
reaches the parent meanwhile is not lost."""

from __future__ import annotations

import multiprocessing as mp
import signal
import threading

import pytest

from suite.run.interrupt import signals_blocked


def _report_handlers(queue) -> None:
    queue.put([signal.getsignal(s) == signal.SIG_IGN for s in (signal.SIGINT, signal.SIGTERM)])


def test_a_child_started_inside_starts_with_the_signals_ignored():
    # a spawned child does not inherit a blocked mask (Python's fork-exec clears it), so blocking
    # alone left its start-up imports open to the terminal's Ctrl-C: a KeyboardInterrupt traceback
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    proc = ctx.Process(target=_report_handlers, args=(queue,))
    before = signal.getsignal(signal.SIGINT)  # SIG_IGN when the tests run in the background (nohup, &)
    with signals_blocked():
        proc.start()
    try:
        assert queue.get(timeout=300) == [True, True]  # a deadline only a hang reaches
    finally:
        proc.join(timeout=300)
    assert signal.getsignal(signal.SIGINT) is before  # the parent's own is back


def test_a_signal_arriving_meanwhile_reaches_the_parent_afterwards():
    # Python's own handler, also when the tests run in the background, where SIGINT starts ignored
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        _expect_the_interrupt()
    finally:
        signal.signal(signal.SIGINT, previous)


def _expect_the_interrupt() -> None:
    with pytest.raises(KeyboardInterrupt):
        with signals_blocked():
            # to this thread, which blocks it (a signal to the process could go to another thread)
            signal.pthread_kill(threading.get_ident(), signal.SIGINT)
        pytest.fail("the SIGINT sent while starting processes was lost")
