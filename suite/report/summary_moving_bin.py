"""The moving-bin table: per planner and bin speed, cans in the bin and why the others were lost.

Every figure comes from moving_bin.json alone (`suite.execution.moving_bin.MovingBinRecord`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from tabulate import tabulate

from suite.report.outcomes import wilson_interval
from suite.report.summary_tables import format_number

MOVING_BIN_INTRO = """## Moving bin

The bin moves in the floor plane along a seeded path (trapezoidal speed profiles between random
points of its region), held by a person standing beside it (an obstacle too); the robot sees it
through a delayed, sampled, noisy estimate and predicts it at constant velocity
(docs/moving-bin.md). Approach, descend and lift are the planner's plans; the transit is planned
online at lift start toward the predicted bin and replanned under a deadline whenever the
predicted drop position drifts; the can is released only over the bin's opening; the return is
planned from where the arm is. Every planner runs the same loop; speed 0 is the static bin
through it. Cans in bin: with its 95% Wilson interval. Replans: deadline-bound replans per can
attempted. Latency: their wall time (median / p95; measured on the machine of the run).
Missed: over the deadline (the current plan went on); failed: no valid plan within it. Contacts:
episodes of the robot or the carried can touching the bin or the person. Jump: the largest
joint jump of the command at a splice (position rad / velocity rad/s). Grasp-release: median
time from the closed grasp to the release.
"""


@dataclasses.dataclass(frozen=True)
class SpeedCell:
    """One planner at one bin speed, over its episodes."""

    planner: str
    speed_m_s: float
    episodes: int
    cans_in_bin: int
    cans_total: int
    ci95: tuple[float, float]
    replans: int
    cans_attempted: int
    deadline_misses: int
    replan_failures: int
    latencies_s: tuple[float, ...]
    contacts_bin: int
    contacts_person: int
    jump_q_rad: float
    jump_v_rad_s: float
    grasp_to_release_s: tuple[float, ...]
    given_up: int
    not_applicable: str
    errors: int

    @property
    def rate(self) -> float:
        return self.cans_in_bin / self.cans_total if self.cans_total else math.nan

    @property
    def replans_per_can(self) -> float:
        return self.replans / self.cans_attempted if self.cans_attempted else math.nan


def speed_cells(records: Sequence[dict[str, Any]], *, planners: Sequence[str] | None = None) -> list[SpeedCell]:
    """Per planner (in the given order, then any other in the records) and speed (ascending), the
    episodes' totals."""
    present = list(dict.fromkeys(r["planner"] for r in records))
    order = [p for p in (planners or ()) if p in present]
    planners = order + [p for p in present if p not in order]  # the records' own planners too
    out = []
    for p in planners:
        mine = [r for r in records if r["planner"] == p]
        for v in sorted({float(r["speed_m_s"]) for r in mine if r.get("speed_m_s") is not None}):
            rs = [r for r in mine if r.get("speed_m_s") is not None and float(r["speed_m_s"]) == v]
            ok = [r for r in rs if r.get("status") == "ok"]
            na = next((r["reason"] for r in rs if r.get("status") == "not_applicable"), "")
            k, n = sum(r["cans_in_bin"] for r in ok), sum(r["cans_total"] for r in ok)
            events = [e for r in ok for e in r.get("events", ()) if e["trigger"] in ("drift", "arrival")]
            spliced = [e for e in events if e["outcome"] == "spliced"]
            out.append(SpeedCell(
                planner=p, speed_m_s=v, episodes=len(rs), cans_in_bin=k, cans_total=n, ci95=wilson_interval(k, n),
                replans=sum(r["replans"] for r in ok), cans_attempted=sum(r["cans_attempted"] for r in ok),
                deadline_misses=sum(r["deadline_misses"] for r in ok),
                replan_failures=sum(r["replan_failures"] for r in ok),
                latencies_s=tuple(e["latency_s"] for e in events),
                contacts_bin=sum(r["contacts_bin"] for r in ok), contacts_person=sum(r["contacts_person"] for r in ok),
                jump_q_rad=max((e["jump_q_rad"] for e in spliced), default=math.nan),
                jump_v_rad_s=max((e["jump_v_rad_s"] for e in spliced), default=math.nan),
                grasp_to_release_s=tuple(c["grasp_to_release_s"] for r in ok for c in r.get("cans", ())
                                         if c["released"]),
                given_up=sum(r["cans_given_up"] for r in ok), not_applicable=na,
                errors=sum(r.get("status") == "error" for r in rs)))
    return out


def _q(values: Sequence[float], q: float) -> float:
    return float(np.quantile(values, q)) if len(values) else math.nan


def moving_bin_rows(records: Sequence[dict[str, Any]], *, planners: Sequence[str] | None = None
                    ) -> tuple[list[str], list[list[Any]]]:
    """The table's headers and rows (one per planner and speed)."""
    headers = ["planner", "speed (m/s)", "episodes", "cans in bin", "replans / can", "latency median / p95 (s)",
               "missed", "failed", "gave up", "contacts bin / person", "jump (rad, rad/s)", "grasp-release (s)",
               "errors"]
    rows = []
    for c in speed_cells(records, planners=planners):
        if c.not_applicable and not c.cans_total:
            rows.append([c.planner, format_number(c.speed_m_s), c.episodes, f"not applicable: {c.not_applicable}",
                         *["-"] * 8, c.errors])
            continue
        lo, hi = c.ci95
        rows.append([
            c.planner, format_number(c.speed_m_s), c.episodes,
            f"{c.cans_in_bin}/{c.cans_total} ({100 * c.rate:.0f}% [{100 * lo:.0f}, {100 * hi:.0f}])"
            if c.cans_total else "-",
            format_number(c.replans_per_can),
            f"{format_number(_q(c.latencies_s, 0.5))} / {format_number(_q(c.latencies_s, 0.95))}"
            if c.latencies_s else "-",
            c.deadline_misses, c.replan_failures, c.given_up, f"{c.contacts_bin} / {c.contacts_person}",
            f"{format_number(c.jump_q_rad)}, {format_number(c.jump_v_rad_s)}" if math.isfinite(c.jump_q_rad) else "-",
            format_number(_q(c.grasp_to_release_s, 0.5)) if c.grasp_to_release_s else "-",
            c.errors,
        ])
    return headers, rows


def moving_bin_table(records: Sequence[dict[str, Any]], *, planners: Sequence[str] | None = None,
                     tablefmt: str = "github") -> str:
    return tabulate(*reversed(moving_bin_rows(records, planners=planners)), tablefmt=tablefmt)
