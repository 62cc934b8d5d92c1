"""Recompute the metrics of a finished run from its stored paths with the current scoring code.

Every record with a stored path gets its problem rebuilt (`recorded_problems`), its path timed
again with TOPP-RA, scored and given its exact verdict (`certification`) again exactly as
`suite.run.trial.run_trial` does for a new trial.
Records whose world cannot be rebuilt keep their stored metrics and are counted. Nothing else in
a record changes (not its status). `trials.jsonl` is replaced atomically.
"""

from __future__ import annotations

import dataclasses
import json
import logging
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from scenes.errors import SuiteError
from suite.run.atomic import write_text_atomically
from suite.run.recorded_problems import RecordedProblems, Unrebuildable
from suite.run.records import TrialRecord

log = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True)
class RescoreCounts:
    """What a rescore did.

    Attributes:
        records: records in the run.
        with_path: records with a stored path (the ones that have metrics).
        rescored: records whose metrics were recomputed.
        kept: reason -> number of records that kept their stored metrics (world not rebuilt).
        timing_changed: rescored records whose timing now fails where it succeeded, or the reverse
            (their status is left as recorded).
    """

    records: int
    with_path: int
    rescored: int
    kept: dict[str, int]
    timing_changed: int

    def line(self) -> str:
        """One line for the terminal."""
        text = f"rescored {self.rescored} of {self.with_path} records with a path ({self.records} records)"
        n_kept = sum(self.kept.values())
        if n_kept:
            why = "; ".join(f"{n} {reason}" for reason, n in sorted(self.kept.items(), key=lambda kv: -kv[1]))
            text += f"; {n_kept} kept their stored metrics, world not rebuilt: {why}"
        if self.timing_changed:
            text += f"; {self.timing_changed} now time differently (ok vs failed), status left as recorded"
        return text


def rescore_records(records: Sequence[TrialRecord], manifest: dict[str, Any]) -> tuple[list[TrialRecord], RescoreCounts]:
    """New copies of the records with every metric recomputed from their stored paths.

    Args:
        records: the run's trial records, in file order.
        manifest: the run's manifest (how its scenes or dataset problems were made).

    Returns:
        The records (same order; only "metrics" and "certification" differ) and the counts.
    """
    from planners.worlds import collision_world
    from suite.run.records import joint_path
    from suite.scoring.metrics import record_metrics, score
    from suite.scoring.timing import time_parameterize
    from suite.scoring.validate import certify_path, structure_reason

    problems = RecordedProblems(records, manifest)
    out, kept = [], Counter()
    with_path = rescored = timing_changed = 0
    for rec in records:
        path = joint_path(rec)
        if path is None:
            out.append(rec)
            continue
        with_path += 1
        try:
            problem = problems.problem(rec)
        except Unrebuildable as exc:
            kept[str(exc)] += 1
            out.append(rec)
            continue
        world = collision_world(problem)
        timed = time_parameterize(path, robot=world.robot)
        timing_changed += timed.ok != (rec.status != "timing_failed")
        scored = score(path=path, world=world, X_WG_goal=problem.X_WG_goal, timed=timed,
                       reference_length_rad=problems.reference(rec, "reference_length_rad"),
                       reference_ee_length_m=problems.reference(rec, "reference_ee_length_m"))
        certification = certify_path(path, world) if structure_reason(problem, path, world) is None else None
        out.append(rec.with_(metrics=record_metrics(scored), certification=certification))
        rescored += 1
    return out, RescoreCounts(len(records), with_path, rescored, dict(kept), timing_changed)


def write_trials_atomically(path: Path, records: Sequence[TrialRecord]) -> None:
    """Replace a trials.jsonl with these records (`write_text_atomically`: one rename)."""
    write_text_atomically(path, "".join(json.dumps(rec.to_json()) + "\n" for rec in records))


def rescore_run(run_dir: str | Path) -> RescoreCounts:
    """Rescore a run directory's trials.jsonl in place (the caller redraws its report).

    Args:
        run_dir: the run directory (trials.jsonl and manifest.json).

    Returns:
        The counts (rescored, kept with their reasons).

    Raises:
        SuiteError: no such run, or trials.jsonl changed while it was being rescored.
    """
    from suite.run.records import TRIALS_FILE, read_manifest, read_trials

    run_dir = Path(run_dir)
    trials = run_dir / TRIALS_FILE
    if not trials.is_file():
        raise SuiteError(f"run directory {str(run_dir)!r} holds no {TRIALS_FILE}")
    before = trials.stat()
    records = read_trials(trials)
    new, counts = rescore_records(records, read_manifest(run_dir))
    after = trials.stat()
    if (after.st_size, after.st_mtime_ns) != (before.st_size, before.st_mtime_ns):
        raise SuiteError(f"{trials} changed while it was being rescored (is the run still going?); nothing written")
    write_trials_atomically(trials, new)
    log.debug("rescored %s", trials)
    return counts
