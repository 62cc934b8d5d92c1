"""One comparison run of a `CompareConfig` into its directory: the run's life from lock to manifest.

`compare` (`suite.cli.compare`) and `paper gcs-arm` (`suite.paper.gcs_arm_protocol`) run their
comparisons through `run_comparison`. The directory is locked for the whole run, its manifest
written (or, resuming, the run's settings checked against it), every trial not yet recorded run
and appended to trials.jsonl, and the run's status and contention set in its manifest; then the
caller's own step (`then`: physics execution, the report) runs with the directory still locked. A
signal stops the run with its records kept and its manifest `interrupted` (`Interrupted` is raised
on to the caller); a record that cannot be written stops it with its manifest `stopped`.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import json
import logging
import multiprocessing
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

from scenes.errors import SuiteError
from suite.run.manifest import MANIFEST_FILE
from suite.run.runner import TRIALS_FILE, CompareConfig
from suite.run.trial import TrialSpec

log = logging.getLogger(__name__)

#: Settings of how a run executes, which a resumed run may change (its records do not depend on them).
HOW_IT_RUNS = ("jobs", "executor", "scheduler", "memory_limit_mb")

T = TypeVar("T")


@dataclasses.dataclass(frozen=True)
class ComparisonRun:
    """A comparison whose trials are all recorded: its directory, trials, counts and contention."""

    out: Path
    config: CompareConfig
    trials: list[TrialSpec]
    #: {"total", "skipped", "ran"} (`suite.run.runner.run_trials`)
    counts: dict[str, int]
    #: the run's contention summary, as in its manifest (`suite.run.contention.run_contention`)
    contention: dict[str, Any]


def run_comparison(config: CompareConfig, *, out: Path, command: list[str], resume: bool = False,
                   progress_bar: bool = True, resume_hint: str | None = None,
                   check_trials: Callable[[list[TrialSpec]], None] | None = None,
                   then: Callable[[ComparisonRun], T] | None = None) -> ComparisonRun | T:
    """Run every trial of `config` not yet recorded in `out` (the manifest and trials.jsonl of a run).

    Args:
        config: the run's settings (checked: `scenes.schema.load(CompareConfig, ...)`).
        out: the run directory, created if missing; without `resume` it must not hold a run.
        command: the arguments of the command that started this process (the manifest's `command`).
        resume: continue the run in `out`: its manifest's settings must be `config`'s, but for how
            the run executes (`HOW_IT_RUNS`).
        progress_bar: show the trials' progress bar (on stderr).
        resume_hint: the command that resumes this run, named in the error of a stopped run.
        check_trials: called with the prepared trials before any runs (raise SuiteError to refuse them).
        then: the caller's step after the trials, run with `out` still locked; its value is returned.

    Returns:
        `then`'s value, or without it the `ComparisonRun`.

    Raises:
        SuiteError: `out` is locked by another run or not writable, holds a run (without `resume`),
            holds none or one of other settings (with it), or a record could not be written.
        Interrupted: SIGINT or SIGTERM stopped the run (its records are kept, its manifest says so).
    """
    from suite.run.interrupt import Interrupted, SignalGuard, reap_children
    from suite.run.journal import RecordWriteError
    from suite.run.lock import RunLock
    from suite.run.manifest import update_manifest
    from suite.run.runner import recorded_counts

    out = Path(out)
    before = frozenset(c.pid for c in multiprocessing.active_children())
    total: dict[str, int] = {}
    with SignalGuard():
        lock = RunLock(out).acquire()  # before the contents are checked: of two runs started at once, one fails
        try:
            _check_out(out, config, resume=resume)
            print(f"run directory: {out}", file=sys.stderr)
            run = _run_locked(config, out=out, command=command, resume=resume, progress_bar=progress_bar,
                              total=total, check_trials=check_trials)
            return run if then is None else then(run)
        except Interrupted as exc:
            update_manifest(out, status="interrupted", interrupted_by=exc.name, stopped_utc=_now(),
                            **recorded_counts(out, total=total.get("trials")))
            raise
        except RecordWriteError as exc:
            counts = recorded_counts(out, total=total.get("trials"))
            update_manifest(out, status="stopped", stop_reason=str(exc), stopped_utc=_now(), **counts)
            hint = f"; once the cause is fixed, resume with: {resume_hint}" if resume_hint else f" in {out}"
            raise SuiteError(f"{exc}; the run stopped with {counts['trials_recorded']} trial(s) kept{hint}") from None
        finally:
            reap_children(keep=before)  # no worker outlives the run, however it ended
            lock.release()


def _check_out(out: Path, config: CompareConfig, *, resume: bool) -> None:
    """`out` (locked) is writable and holds a run of `config`'s settings when resuming, no run otherwise."""
    from suite.run.manifest import read_run_manifest

    if not resume:
        if (out / TRIALS_FILE).exists():
            raise SuiteError(f"--out {str(out)!r} already holds a run; use --resume to continue it or another --out")
    elif not (out / TRIALS_FILE).exists():
        raise SuiteError(f"--resume: {str(out)!r} holds no {TRIALS_FILE} to resume")
    try:
        probe = out / ".write-test"
        probe.write_text("")
        probe.unlink()
    except OSError as exc:
        raise SuiteError(f"--out {str(out)!r} is not writable: {exc.strerror}") from None
    if not resume:
        return
    manifest = read_run_manifest(out)
    if manifest is None:
        return  # an old run without a manifest: its records' ids decide what is left to run
    stored = manifest.get("config")
    if not isinstance(stored, dict):
        raise SuiteError(f"{out / MANIFEST_FILE} holds no run settings to resume")
    given = json.loads(json.dumps(dataclasses.asdict(config)))  # tuples as the manifest's lists
    for key, value in given.items():
        if key in stored and key not in HOW_IT_RUNS and stored[key] != value:
            raise SuiteError(f"resuming {str(out)!r}: its {key} is {stored[key]!r}, not {value!r}; "
                             "start a new run in another directory")


def _run_locked(config: CompareConfig, *, out: Path, command: list[str], resume: bool, progress_bar: bool,
                total: dict[str, int], check_trials) -> ComparisonRun:
    from planners.worlds import CHECKER_ENV
    from suite.run.contention import machine_across, machine_sample, run_contention
    from suite.run.manifest import update_manifest, write_manifest
    from suite.run.records import read_trials
    from suite.run.runner import run_trials

    os.environ[CHECKER_ENV] = config.checker  # the workers (spawned from here) inherit it
    if resume:
        update_manifest(out, status="running", resumed_utc=_now())
    else:
        write_manifest(out, config, argv=command)
        (out / TRIALS_FILE).touch()  # the directory now holds a run, even before its first record
    trials, executor = _trials_and_executor(config, out, progress_bar=progress_bar)
    total["trials"] = len(trials)
    if check_trials is not None:
        check_trials(trials)
    machine0 = machine_sample()
    counts = run_trials(trials, out=out, jobs=config.jobs, executor=executor, scheduler=config.scheduler,
                        progress_bar=progress_bar, hard_limit_grace_s=config.hard_limit_grace_s)
    contention = run_contention(read_trials(out / TRIALS_FILE), machine=machine_across(machine0))
    update_manifest(out, status="complete", finished_utc=_now(), trials_recorded=counts["skipped"] + counts["ran"],
                    trials_total=counts["total"], contention=contention)
    if contention["run_contended"]:
        print(f"warning: the machine was contended: {contention['contended']} of {contention['measured']} trial(s) "
              f"waited for a CPU (or lost it to steal), {100 * (contention['cpu_wait_share'] or 0):.0f}% of the "
              "planning wall time in all; summary.md names them", file=sys.stderr)
    return ComparisonRun(out, config, trials, counts, contention)


def _trials_and_executor(config: CompareConfig, out: Path, *, progress_bar: bool):
    """The run's trials and the executor that runs them. A dataset's trials are prepared first (no
    IK: fast), so that the pending count caps the workers; generated scenes start the workers first,
    which import Drake and OMPL while the scenes are prepared (at most 5 problems per can and planner)."""
    from suite.run.executors import cap_workers
    from suite.run.runner import make_executor, prepare_trials, recorded_trial_ids

    if config.dataset:
        print(f"loading dataset {config.dataset}...", file=sys.stderr)
        trials = prepare_trials(config)
        done = recorded_trial_ids(out / TRIALS_FILE)
        jobs = cap_workers(config.jobs, sum(t.trial_id not in done for t in trials))
        return trials, make_executor(config.executor, jobs=jobs, scheduler=config.scheduler,
                                     memory_limit_mb=config.memory_limit_mb)
    print(f"preparing {config.scenes} {config.variant} scene(s) of {config.cans} cans ({config.grasps} grasps)...",
          file=sys.stderr)
    bound = config.scenes * config.cans * 5 * len(config.planners)
    executor = make_executor(config.executor, jobs=min(config.jobs, bound), scheduler=config.scheduler,
                             memory_limit_mb=config.memory_limit_mb)
    if hasattr(executor, "start"):
        executor.start()
    try:
        return prepare_trials(config), executor
    except BaseException:
        if hasattr(executor, "abort"):
            executor.abort()
        raise


def _now() -> str:
    return dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds")
