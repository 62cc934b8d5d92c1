"""Reading a run's saved trial records (`trials.jsonl`) and typed access to their fields.

Every table, plot and export is rebuilt from these records alone. A record is the JSON object the
runner appended for one finished trial; the runner owns writing them, this module owns reading.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from planners.base import STATUS_CAUSE, FailureReason, PlanStatus
from scenes.errors import SuiteError
from suite.run.formats import (
    MANIFEST_FORMAT_VERSION,
    RECORD_FORMAT_VERSION,
    check_version,
)
from suite.run.json_record import JsonRecord

log = logging.getLogger(__name__)

TRIALS_FILE = "trials.jsonl"
MANIFEST_FILE = "manifest.json"

#: Every status a record may carry, in the order tables and plots list them. `no_result`: an
#: imported external planner sent nothing for the problem (`suite.exchange.results`).
NO_RESULT = "no_result"
STATUSES: tuple[str, ...] = (*(s.value for s in PlanStatus), NO_RESULT)
SUCCESS = PlanStatus.SUCCESS.value

#: The motions of the pick-and-place cycle in the order they happen.
PROBLEM_KINDS: tuple[str, ...] = ("approach", "descend", "lift", "transit", "return")

#: Fields a line must have to count as a trial record.
REQUIRED_FIELDS = ("planner", "status", "problem", "scene_seed", "variant", "can_id")


@dataclasses.dataclass(eq=False)
class TrialRecord(JsonRecord):
    """One trial's record: one line of `trials.jsonl`, as the runner (`suite.run.trial`) writes it.

    The fields are in the order the runner writes them. A field a line does not have keeps its
    default (None, or empty); a key this version does not name is kept in `extra`, so a record read
    and written back (`to_json`) is the line it was, key order included (`JsonRecord`).
    """

    ALWAYS_WRITTEN = REQUIRED_FIELDS


    planner: str
    status: str
    #: the motion's kind (`planners.base.PROBLEM_KINDS`, or `free` for a free transit)
    problem: str
    scene_seed: int
    variant: str
    #: the can the motion belongs to; None for a free transit (numbered by `task_index`)
    can_id: int | None
    format_version: int | None = None
    trial_id: str | None = None
    planner_config: dict[str, Any] = dataclasses.field(default_factory=dict)
    scene_key: str | None = None
    task_index: int | None = None
    held: bool | None = None
    seed: int | None = None
    time_limit_s: float | None = None
    budget_clock: str | None = None
    q_start: list[float] | None = None
    q_goal: list[float] | None = None
    # what the run knows of the problem (`TrialSpec.meta`)
    problem_id: str | None = None
    family: str | None = None
    kind: str | None = None
    trivial: bool | None = None
    difficulty: float | None = None
    straight_length_rad: float | None = None
    split: str | None = None
    reference_length_rad: float | None = None
    reference_ee_length_m: float | None = None
    budget_s: float | None = None
    # how it ran
    setup_time_s: float | None = None
    contention: dict[str, Any] | None = None
    checker: str | None = None
    fcl_collide_calls: int | None = None
    #: False: the worker's first trial of this planner (its imports and first solve paid here)
    warm: bool | None = None
    external: bool | None = None
    # the verdict
    planning_time_s: float | None = None
    planning_cpu_time_s: float | None = None
    path: list[list[float]] | None = None
    metrics: dict[str, Any] = dataclasses.field(default_factory=dict)
    certification: dict[str, Any] | None = None
    stats: dict[str, Any] = dataclasses.field(default_factory=dict)
    reason_code: str | None = None
    worlds: dict[str, Any] | None = None
    attribution: dict[str, Any] | None = None

    @property
    def succeeded(self) -> bool:
        """True if the trial produced a validated, timed path."""
        return self.status == SUCCESS


_RECORD_FIELDS = frozenset(f.name for f in TrialRecord.json_fields())

#: Metrics that are fields of the record itself rather than of its "metrics" dict.
TOP_LEVEL_METRICS = ("planning_time_s",)


def read_trials(path: str | Path) -> list[TrialRecord]:
    """Read every trial record of a `trials.jsonl` file.

    A final line that is not valid JSON is a record torn by an interrupted write: it is skipped
    with a warning. Any other bad line is an error.

    Args:
        path: the trials.jsonl file, or the run directory holding it.

    Returns:
        The records in file order.

    Raises:
        SuiteError: the file cannot be read, or a line other than the last is not a record.
    """
    path = Path(path)
    if path.is_dir():
        path = path / TRIALS_FILE
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise SuiteError(f"cannot read trial records {str(path)!r}: {exc.strerror}") from None
    lines = text.split("\n")
    last = max((i for i, line in enumerate(lines) if line.strip()), default=-1)
    records = []
    for i, line in enumerate(lines):
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
        except json.JSONDecodeError:
            if i == last:
                log.warning("%s: ignoring the torn last line %d (%d characters)", path, i + 1, len(line))
                continue
            raise SuiteError(f"{path} line {i + 1} is not valid JSON") from None
        if not isinstance(rec, dict):
            raise SuiteError(f"{path} line {i + 1} is not a JSON object")
        missing = [f for f in REQUIRED_FIELDS if f not in rec]
        if missing:
            raise SuiteError(f"{path} line {i + 1} lacks the field(s) {', '.join(missing)}")
        check_version(rec, supported=RECORD_FORMAT_VERSION, what="trial record", where=f"{path} line {i + 1}")
        records.append(TrialRecord.from_json(rec))
    return records


def read_manifest(run_dir: str | Path) -> dict[str, Any]:
    """The run's manifest.json as a dict, or an empty dict if there is none (or it is unreadable)."""
    path = Path(run_dir) / MANIFEST_FILE
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        log.debug("no usable manifest at %s: %s", path, exc)
        return {}
    if isinstance(manifest, dict):  # a newer manifest format is an error, an older one is read
        check_version(manifest, supported=MANIFEST_FORMAT_VERSION, what="run manifest", where=str(path))
    return manifest


# --- typed access ---------------------------------------------------------------------------------


def is_success(rec: TrialRecord) -> bool:
    """True if the trial produced a validated, timed path."""
    return rec.succeeded


#: The free-text reasons the suite's planners wrote before they named a cause, and that cause.
_OLD_REASONS = (
    (("last knot", "step from the last knot"), FailureReason.GOAL_NOT_REACHED),
    (("knot ",), FailureReason.NO_IK_AT_KNOT),
    (("the regions do not connect",), FailureReason.REGIONS_DISCONNECTED),
    (("no regions",), FailureReason.REGIONS_MISSING),
    (("GCS failed", "the solution does not join", "solver failed"), FailureReason.SOLVER_FAILED),
    (("path still collides", "the path through the regions"), FailureReason.PATH_STILL_COLLIDES),
    (("in collision",), FailureReason.ENDPOINT_IN_COLLISION),
    (("outside joint limits",), FailureReason.ENDPOINT_OUT_OF_LIMITS),
)
#: The statuses only the orchestrator sets: their cause is the status's, whatever a planner said.
_JUDGED = (PlanStatus.INVALID_SOLUTION, PlanStatus.TIMING_FAILED, PlanStatus.CRASH, PlanStatus.KILLED_TIMEOUT)
_SAMPLERS = ("RRTConnect", "RRTstar", "BITstar", "AORRTC", "PRM", "roboplan RRT-Connect")


def reason_code(rec: TrialRecord) -> str | None:
    """A failed record's enumerated cause (`planners.base.FailureReason`'s value), None for a
    success. Read from the record (`reason_code`), else worked out as the judge works it out,
    so old records and imported ones get one too (`not_stated` where nothing says)."""
    if is_success(rec):
        return None
    if rec.reason_code:
        return str(rec.reason_code)
    try:
        status = PlanStatus(rec.status)
    except ValueError:
        status = None
    stats = rec.stats or {}
    if stats.get("reason") in (FailureReason.PATH_OVER_LIMIT.value, FailureReason.OUT_OF_MEMORY.value):
        return str(stats["reason"])
    if status is PlanStatus.TIMEOUT and "late_by_s" in stats:
        return FailureReason.LATE_PATH.value
    if status in _JUDGED:
        return STATUS_CAUSE[status].value
    if stats.get("reason_code"):
        return str(stats["reason_code"])
    text = str(stats.get("reason") or "")
    for prefixes, code in _OLD_REASONS:  # records written before planners named their cause
        if text.startswith(prefixes):
            return code.value
    if status is PlanStatus.NO_SOLUTION and not text and stats.get("solver") in _SAMPLERS:
        return FailureReason.SEARCH_FAILED.value
    return STATUS_CAUSE.get(status, FailureReason.NOT_STATED).value


def problem_number(rec: TrialRecord) -> int:
    """What a record's problem is numbered by in its scene: its can's id, or a free transit's
    task index (`task_index`; its `can_id` is None)."""
    return int(rec.can_id) if rec.can_id is not None else int(rec.task_index or 0)


def problem_subject(rec: TrialRecord) -> str:
    """`can N` for a cycle's motion, `task N` for a free transit."""
    return f"can {rec.can_id}" if rec.can_id is not None else f"task {rec.task_index}"


def problem_key(rec: TrialRecord) -> tuple:
    """The identity of the planning problem: its content hash (`problem_id`) where the record has
    one, else (scene_seed, variant, can_id, problem kind) as in runs made before problems had one.

    Every planner of a comparison solves the same problems, so records pair on this key.
    """
    if rec.problem_id:
        return (str(rec.problem_id),)
    return (int(rec.scene_seed), str(rec.variant), problem_number(rec), str(rec.problem))


def problem_counts(records: Sequence[TrialRecord]) -> dict[str, int]:
    """How many distinct problems the records hold, how many of them are trivial (their straight
    segment passes the validator) and how many scenes they come from."""
    problems: dict[tuple, bool | None] = {}
    for r in records:
        problems[problem_key(r)] = r.trivial
    return {"distinct": len(problems), "trivial": sum(1 for v in problems.values() if v),
            "known_trivial": sum(1 for v in problems.values() if v is not None),
            "scenes": len({(r.scene_key or r.scene_seed, r.variant) for r in records})}


def metric(rec: TrialRecord, name: str) -> float:
    """A metric of a trial as a float; NaN when the record does not have it (e.g. failures).

    `planning_time_s` is read from the record itself, `time_to_trajectory_s` is planning time plus
    TOPP-RA's timing time, every other name is read from its "metrics".
    """
    if name == "time_to_trajectory_s":
        return metric(rec, "planning_time_s") + metric(rec, "timing_time_s")
    if name == "offline_s":  # a planner's offline preparation of the problem's world (gcs regions)
        value = (rec.stats or {}).get("offline_s")
        return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else math.nan
    if name in TOP_LEVEL_METRICS:
        value = getattr(rec, name)
    else:
        value = (rec.metrics or {}).get(name)
    if value is None or isinstance(value, bool):
        return math.nan
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def metric_values(records: Iterable[TrialRecord], name: str, *, successful_only: bool = True) -> np.ndarray:
    """The finite values of one metric over records (by default only successful ones)."""
    vals = [metric(r, name) for r in records if is_success(r) or not successful_only]
    arr = np.asarray(vals, dtype=float)
    return arr[np.isfinite(arr)]


def joint_path(rec: TrialRecord) -> np.ndarray | None:
    """The validated joint path (N, 7) in rad, or None if the record has none."""
    path = rec.path
    if not path:
        return None
    arr = np.asarray(path, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 7 or len(arr) < 2:
        return None
    return arr


def planners_in(records: Sequence[TrialRecord], manifest: dict[str, Any] | None = None) -> list[str]:
    """The planners of a run, in the manifest's order if it lists them, else in order of appearance."""
    seen = list(dict.fromkeys(str(r.planner) for r in records))
    listed = _manifest_planners(manifest or {})
    ordered = [p for p in listed if p in seen]
    return ordered + [p for p in seen if p not in ordered]


def _manifest_planners(manifest: dict[str, Any]) -> list[str]:
    for holder in (manifest, manifest.get("config") or {}):
        value = holder.get("planners") if isinstance(holder, dict) else None
        if isinstance(value, str):
            return [p.strip() for p in value.split(",") if p.strip()]
        if isinstance(value, list):
            return [p if isinstance(p, str) else str(p.get("name", "")) for p in value]
        if isinstance(value, dict):
            return list(value)
    return []


def problem_kinds_in(records: Iterable[TrialRecord]) -> list[str]:
    """The problem kinds present, in cycle order (unknown kinds last, sorted)."""
    present = {str(r.problem) for r in records}
    return [k for k in PROBLEM_KINDS if k in present] + sorted(present - set(PROBLEM_KINDS))


def statuses_in(records: Iterable[TrialRecord]) -> list[str]:
    """The statuses present, in the order of `STATUSES` (unknown ones last, sorted)."""
    present = {str(r.status) for r in records}
    return [s for s in STATUSES if s in present] + sorted(present - set(STATUSES))
