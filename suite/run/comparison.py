"""One comparison run of a `CompareConfig` into its directory, for callers other than `compare`'s
command line (`python -m suite paper gcs-arm` runs its comparisons through it).

The directory is locked for the run, its manifest written (or, resuming, the run's settings checked
against it), every trial not yet recorded run and appended to trials.jsonl, and the run's status
and contention set in its manifest. A signal stops the run as it stops `compare`: the records kept,
the manifest `interrupted`. The report (summary, plots, report.html) is the caller's to write,
from the records (`suite.report.write.write_report`).
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import json
import logging
import multiprocessing
import os
from pathlib import Path
from typing import Any

from scenes.errors import SuiteError
from suite.run.manifest import MANIFEST_FILE
from suite.run.runner import TRIALS_FILE, CompareConfig

log = logging.getLogger(__name__)

#: Settings of how a run executes, which a resumed run may change (its records do not depend on them).
HOW_IT_RUNS = ("jobs", "executor", "scheduler", "memory_limit_mb")


def run_comparison(config: CompareConfig, *, out: Path, command: list[str], resume: bool = False,
                   progress_bar: bool = True) -> dict[str, int]:
    """Run every trial of `config` not yet recorded in `out` (the manifest and trials.jsonl of a run).

    Args:
        config: the run's settings (checked: `scenes.schema.load(CompareConfig, ...)`).
        out: the run directory, created if missing; without `resume` it must not hold a run.
        command: the arguments of the command that started this process (the manifest's `command`).
        resume: continue the run in `out`: its manifest's settings must be `config`'s, but for how
            the run executes (`HOW_IT_RUNS`).
        progress_bar: show the trials' progress bar (on stderr).

    Returns:
        Counts: {"total", "skipped", "ran"}.

    Raises:
        SuiteError: `out` is locked by another run, holds a run (without `resume`), holds none or
            one of other settings (with it), or a record could not be written.
        Interrupted: SIGINT or SIGTERM stopped the run (its records are kept, its manifest says so).
    """
    from suite.run.interrupt import Interrupted, SignalGuard, reap_children
    from suite.run.journal import RecordWriteError
    from suite.run.lock import RunLock
    from suite.run.manifest import update_manifest

    out = Path(out)
    before = frozenset(c.pid for c in multiprocessing.active_children())
    total: dict[str, int] = {}
    with SignalGuard():
        lock = RunLock(out).acquire()
        try:
            _check_out(out, config, resume=resume)
            return _run_locked(config, out=out, command=command, resume=resume, progress_bar=progress_bar,
                               total=total)
        except Interrupted as exc:
            update_manifest(out, status="interrupted", interrupted_by=exc.name, stopped_utc=_now(),
                            **_recorded_counts(out, total))
            raise
        except RecordWriteError as exc:
            counts = _recorded_counts(out, total)
            update_manifest(out, status="stopped", stop_reason=str(exc), stopped_utc=_now(), **counts)
            raise SuiteError(f"{exc}; the run stopped with {counts['trials_recorded']} trial(s) kept in {out}") from None
        finally:
            reap_children(keep=before)  # no worker outlives the run, however it ended
            lock.release()


def _check_out(out: Path, config: CompareConfig, *, resume: bool) -> None:
    """`out` (locked) holds a run of `config`'s settings when resuming, and no run otherwise."""
    from suite.run.manifest import read_run_manifest

    if not resume:
        if (out / TRIALS_FILE).exists():
            raise SuiteError(f"{str(out)!r} already holds a run; resume it or choose another directory")
        return
    if not (out / TRIALS_FILE).exists():
        raise SuiteError(f"{str(out)!r} holds no {TRIALS_FILE} to resume")
    manifest = read_run_manifest(out)
    stored = (manifest or {}).get("config")
    if not isinstance(stored, dict):
        raise SuiteError(f"{out / MANIFEST_FILE} holds no run settings to resume")
    given = json.loads(json.dumps(dataclasses.asdict(config)))  # tuples as the manifest's lists
    for key, value in given.items():
        if key in stored and key not in HOW_IT_RUNS and stored[key] != value:
            raise SuiteError(f"resuming {str(out)!r}: its {key} is {stored[key]!r}, not {value!r}; "
                             "start a new run in another directory")


def _run_locked(config: CompareConfig, *, out: Path, command: list[str], resume: bool, progress_bar: bool,
                total: dict[str, int]) -> dict[str, int]:
    from planners.worlds import CHECKER_ENV
    from suite.run.contention import machine_across, machine_sample, run_contention
    from suite.run.executors import cap_workers
    from suite.run.records import read_trials
    from suite.run.manifest import update_manifest, write_manifest
    from suite.run.runner import make_executor, prepare_trials, recorded_trial_ids, run_trials

    os.environ[CHECKER_ENV] = config.checker  # the workers (spawned from here) inherit it
    if resume:
        update_manifest(out, status="running", resumed_utc=_now())
    else:
        write_manifest(out, config, argv=command)
        (out / TRIALS_FILE).touch()  # the directory now holds a run, even before its first record
    trials = prepare_trials(config)
    total["trials"] = len(trials)
    done = recorded_trial_ids(out / TRIALS_FILE)
    executor = make_executor(config.executor, jobs=cap_workers(config.jobs, sum(t.trial_id not in done for t in trials)),
                             scheduler=config.scheduler, memory_limit_mb=config.memory_limit_mb)
    machine0 = machine_sample()
    counts = run_trials(trials, out=out, jobs=config.jobs, executor=executor, scheduler=config.scheduler,
                        progress_bar=progress_bar, hard_limit_grace_s=config.hard_limit_grace_s)
    contention = run_contention(read_trials(out / TRIALS_FILE), machine=machine_across(machine0))
    update_manifest(out, status="complete", finished_utc=_now(), trials_recorded=counts["skipped"] + counts["ran"],
                    trials_total=counts["total"], contention=contention)
    if contention["run_contended"]:
        log.warning("%s: the machine was contended: %s of %s trial(s) waited for a CPU (or lost it to steal); "
                    "summary.md names them", out, contention["contended"], contention["measured"])
    return counts


def _recorded_counts(out: Path, total: dict[str, int]) -> dict[str, Any]:
    from suite.run.runner import recorded_trial_ids

    try:
        recorded = len(recorded_trial_ids(out / TRIALS_FILE))
    except (OSError, SuiteError):
        recorded = None
    return {"trials_recorded": recorded, "trials_total": total.get("trials")}


def _now() -> str:
    return dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds")
