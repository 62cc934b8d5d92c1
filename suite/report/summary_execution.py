"""The execution table: where each planner's cans ended in physics, contacts, tracking and time."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from tabulate import tabulate

from suite.execution.execution_records import (
    BACK_ON_PLATE,
    ELSEWHERE,
    FINAL_RETURN_NOT_EXECUTED,
    NOT_ATTEMPTED,
    ExecutionRecord,
    fate_counts,
)
from suite.report.summary_tables import format_number

EXECUTION_INTRO = """## Execution in physics

Each planner's timed plans for every can of a scene, chained (approach, descend, close, lift,
transit, open, return) and run in a Drake simulation with contact (see suite/execution/).
Cans in bin / picked but back on the plate / elsewhere: where the cans ended. Execution stops at
the first can whose cycle was not fully planned; the cans from there on are "not attempted". Collisions: unintended contact episodes (robot with the scene or
with a can it was not picking, the carried can with the scene). Peak tracking: largest joint
error. Peak slip: largest motion of a carried can in the gripper. Clear time: median simulated
time until the last can was in the bin. Real-time factor: simulated / wall time (median).
"""


def execution_table(executions: Sequence[ExecutionRecord], *, planners: Sequence[str] | None = None,
                    tablefmt: str = "github") -> str:
    """Per planner: where the cans ended after physics execution, contacts, tracking and time
    (`execution_rows` as a table)."""
    return tabulate(*reversed(execution_rows(executions, planners=planners)), tablefmt=tablefmt)


def execution_rows(executions: Sequence[ExecutionRecord], *, planners: Sequence[str] | None = None
                   ) -> tuple[list[str], list[list[Any]]]:
    """Per planner: where the cans ended after physics execution, contacts, tracking and time.

    "fully planned" counts the scenes whose every problem was planned, and the cans recycled in
    those scenes: the figure that judges execution apart from planning failures.
    """
    planners = list(planners) if planners is not None else list(dict.fromkeys(e.planner for e in executions))
    headers = ["planner", "scenes", "cans in bin", "not attempted", "picked, on plate", "elsewhere",
               "fully planned: in bin",
               "collisions", "peak tracking (mrad)", "peak slip (mm)", "clear time (s)", "real-time factor", "errors"]
    rows = []
    for p in planners:
        runs = [e for e in executions if e.planner == p]
        ok = [e for e in runs if e.error is None]
        if not runs:
            continue
        total = sum(e.cans_total for e in runs)
        in_bin = sum(e.cans_in_bin for e in ok)
        full = [e for e in ok if (not e.stopped or FINAL_RETURN_NOT_EXECUTED in e.stopped)
                and e.cans_attempted == e.cans_total]
        full_total = sum(e.cans_total for e in full)
        full_bin = sum(e.cans_in_bin for e in full)
        clear = [e.clear_time_s for e in ok if e.clear_time_s is not None]
        fates = fate_counts(ok)
        rows.append([
            p, len(runs), f"{in_bin}/{total} ({100 * in_bin / max(total, 1):.0f}%)",
            fates[NOT_ATTEMPTED], fates[BACK_ON_PLATE], fates[ELSEWHERE],
            f"{full_bin}/{full_total} in {len(full)} scenes" if full else "-",
            sum(e.collisions for e in ok),
            format_number(1e3 * max((e.peak_tracking_error_rad for e in ok), default=float("nan"))),
            format_number(1e3 * max(((e.peak_slip_m if e.peak_slip_m is not None else float("nan")) for e in ok), default=float("nan"))),
            format_number(float(np.median(clear))) if clear else "-",
            format_number(float(np.median([e.real_time_factor for e in ok]))) if ok else "-",
            len(runs) - len(ok),
        ])
    return headers, rows
