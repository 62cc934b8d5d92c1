"""The records of execution in physics: what `execution.json` and `moving_bin.json` hold, read and
written here, and where each can ended.

`ExecutionRecord` is one planner's plans executed on one scene (`suite.execution.jobs.run_execution`
writes it), with an `ExecutionCan` per can; the moving bin's episodes are
`suite.execution.moving_bin_records.MovingBinRecord`. Both files are read back into these types:
every table, plot and summary of them reads attributes, not keys.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from suite.execution.moving_bin_records import (
    FORMAT_VERSION as MOVING_BIN_FORMAT_VERSION,
)
from suite.execution.moving_bin_records import MovingBinRecord
from suite.run.atomic import write_text_atomically
from suite.run.formats import check_version
from suite.run.json_record import JsonRecord

EXECUTION_FILE = "execution.json"
#: A run's moving-bin episodes (`MovingBinRecord.to_json` each).
MOVING_BIN_FILE = "moving_bin.json"


@dataclasses.dataclass(eq=False)
class ExecutionCan(JsonRecord):
    """Where one can ended (`where`: "bin", "plate" or "elsewhere"), whether its cycle was attempted,
    its final position (m) and when it entered the bin (s of simulated time, or None)."""

    can_id: int
    attempted: bool
    where: str
    p_WC_m: list[float] = dataclasses.field(default_factory=list)
    in_bin_at_s: float | None = None


@dataclasses.dataclass(eq=False)
class ExecutionRecord(JsonRecord):
    """One planner's plans for one scene executed in physics (one entry of execution.json).

    The simulation's outcome (`suite.execution.simulate.ExecutionOutcome`), then how the job ran:
    its grasps, whether it re-perceived between cycles, its settings, the worlds its plans were
    made in and judged in, its perception-induced failures and planning time. A job that raised
    has `error` and the counts it knew (`cans_total`).
    """

    planner: str
    scene_seed: int
    variant: str
    cans_total: int
    cans_attempted: int = 0
    cans_in_bin: int = 0
    cans_on_plate: int = 0
    cans_elsewhere: int = 0
    collisions: int = 0
    peak_tracking_error_rad: float | None = None
    peak_slip_m: float | None = None
    sim_time_s: float | None = None
    clear_time_s: float | None = None
    clear_wall_time_s: float | None = None
    wall_time_s: float | None = None
    real_time_factor: float | None = None
    stopped: str = ""
    contact_events: list[dict[str, Any]] = dataclasses.field(default_factory=list)
    cans: list[ExecutionCan] = dataclasses.field(default_factory=list)
    between_cycles_wall_s: float | None = None
    error: str | None = None
    grasps: str | None = None
    reperceive: bool = False
    config: dict[str, Any] | None = None
    on_failure: str | None = None
    worlds: dict[str, Any] | None = None
    perceived_worlds: list[dict[str, Any]] | None = None
    perception_induced: list[dict[str, Any]] = dataclasses.field(default_factory=list)
    planning_time_s: float | None = None
    perception: dict[str, Any] | None = None
    replay: str | None = None

    ALWAYS_WRITTEN = ("planner", "scene_seed", "variant", "cans_total")

    @classmethod
    def from_json(cls, obj: dict[str, Any]) -> ExecutionRecord:
        rec = super().from_json(obj)
        rec.cans = [ExecutionCan.from_json(c) for c in rec.cans]
        return rec


def write_execution(out: str | Path, records: Sequence[ExecutionRecord]) -> Path:
    """Write the run's execution.json (atomically: a torn write never replaces a good file)."""
    path = Path(out) / EXECUTION_FILE
    write_text_atomically(path, json.dumps({"executions": [r.to_json() for r in records]}, indent=1))
    return path


def read_execution(run_dir: str | Path) -> list[ExecutionRecord]:
    """The execution records of a run ([] when it was not executed)."""
    path = Path(run_dir) / EXECUTION_FILE
    if not path.exists():
        return []
    return [ExecutionRecord.from_json(e) for e in json.loads(path.read_text(encoding="utf-8"))["executions"]]


def write_moving_bin(out: str | Path, records: Sequence[MovingBinRecord]) -> Path:
    """Write the run's moving_bin.json (atomically)."""
    path = Path(out) / MOVING_BIN_FILE
    write_text_atomically(path, json.dumps({"format_version": MOVING_BIN_FORMAT_VERSION,
                                            "moving_bin": [r.to_json() for r in records]}, indent=1))
    return path


def read_moving_bin(run_dir: str | Path) -> list[MovingBinRecord]:
    """The moving-bin records of a run ([] when it ran none); an older format's missing fields get
    their defaults.

    Raises:
        SuiteError: the file is of a newer format than this suite reads.
    """
    path = Path(run_dir) / MOVING_BIN_FILE
    if not path.exists():
        return []
    doc = json.loads(path.read_text(encoding="utf-8"))
    check_version(doc, supported=MOVING_BIN_FORMAT_VERSION, what="moving-bin records", where=str(path))
    return [MovingBinRecord.from_json(r) for r in doc["moving_bin"]]


#: Where a can ended after physics execution: every can of execution.json has exactly one fate.
BIN, BACK_ON_PLATE, ELSEWHERE, NOT_ATTEMPTED = "in the bin", "picked, back on the plate", "elsewhere", "not attempted"
CAN_FATES = (BIN, BACK_ON_PLATE, ELSEWHERE, NOT_ATTEMPTED)
#: An execution's `stopped` note when only the last can's return (after its drop) had no plan: every
#: can was still attempted, so the scene counts as fully planned.
FINAL_RETURN_NOT_EXECUTED = "final return not executed"


def can_fate(can: ExecutionCan) -> str:
    """The fate of one can of an execution (where it ended and whether it was attempted)."""
    if can.where in ("bin", "elsewhere"):
        return BIN if can.where == "bin" else ELSEWHERE
    return BACK_ON_PLATE if can.attempted else NOT_ATTEMPTED


def fate_counts(executions: Iterable[ExecutionRecord]) -> dict[str, int]:
    """How many cans of these executions met each fate."""
    counts = dict.fromkeys(CAN_FATES, 0)
    for e in executions:
        for c in e.cans:
            counts[can_fate(c)] += 1
    return counts
