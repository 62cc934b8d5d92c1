"""The moving-bin tables: per planner and bin speed, cans in the bin and why the others were lost;
planners compared episode by episode on the same bin paths (`summary_moving_bin_paired`); where a
replan's time goes.

Every figure comes from moving_bin.json alone, read as `suite.execution.moving_bin_records.MovingBinRecord`.
Records written before the loop joined replans on the move lack its newer fields (bin_seed,
path_index, latency_mode, release_mode, cans_put_down, failures_by_stage, splices_at_rest, ...):
every one of them is read with a default (a count as None: not recorded), and a column whose field
no record carries is not shown.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from tabulate import tabulate

from suite.execution.moving_bin_records import MovingBinRecord, ReplanEvent
from suite.report.outcomes import wilson_interval
from suite.report.summary_moving_bin_paired import (
    PAIRED_CAPTION,
    latency_mode,
    paired_rows,
    planner_order,
    release_mode,
)
from suite.report.summary_tables import format_number

MOVING_BIN_INTRO = """## Moving bin

The bin moves in the floor plane along a seeded path, held by a person beside it (an obstacle
too); the robot sees it through a delayed, sampled, noisy estimate and predicts it at constant
velocity (docs/moving-bin.md). Approach, descend and lift are the planner's plans; the transit is
planned online toward the predicted bin and replanned under a deadline when the predicted drop
drifts. A replan joins the current motion without stopping it (a C1/C2 blend onto the new path;
"at rest" counts the joins that stopped the arm). The can is released on the move, the gripper
tracking the bin's estimate while it opens (release mode "rest": from rest). Every can is
attempted: one not released within its time limit is put down on the plate and the episode goes
on. Each episode's bin path has its own seed and every planner meets the same paths, so planners
are compared episode by episode. Latency is measured (wall time on the run's machine) or modelled
(a declared constant per planner: the records are reproducible on any machine). Speed 0 is the
static bin through the same loop.

Cans in bin / offered: every can of the episodes that ran or crashed (a can never reached, or of
a crashed episode, is not delivered), with its 95% Wilson interval (not attempted: cans an
episode never reached: it stopped). Given up (put down): cans given up (of them put down on the plate).
Released moving / released: releases on the move, of all releases. Replans: deadline-bound replans
per can attempted; latency: their median / p95. Missed: over the deadline (the current motion went
on); failed: no valid plan within it; by stage: the step that failed them ("start": the arm's place
collided in the world of the moment). Drift splice speed: the largest joint speed at the splice of
a drift replan (made while moving), median. Release updates: re-aims of a release at a new
estimate. Escapes: the arm backing away from a person or bin that came into it. Contacts: episodes of the robot or the
carried can touching the bin or the person; near misses and SSM holds (protective stops for the
person) beside them. Jump: the largest jump of the command at a splice (position rad, velocity
rad/s). Grasp-release: median time from the closed grasp to the release.
"""

#: The failure stages in the order of a replan, and their short names in a table cell.
STAGES = ("start", "goal_ik", "join", "planner", "validator", "person", "timing", "budget")
STAGE_SHORT = {"goal_ik": "ik"}
#: A replan's steps in order (old records have "blend", new ones "join" and "person").
STEPS = ("world", "blend", "ik", "plan", "join", "validate", "person", "timing")


def _deadline_bound(e: ReplanEvent) -> bool:
    """A replan under a deadline: one with a deadline, or a drift or arrival replan (in modelled
    mode these carry none); not the first transit, a return or a put-down, which the arm waits for."""
    return e.deadline_s is not None or e.trigger in ("drift", "arrival", "resume")


def _total(rs: Sequence[MovingBinRecord], key: str) -> int | None:
    """The sum of an integer field over the records carrying it; None if none does (an older record)."""
    values = [getattr(r, key) for r in rs if getattr(r, key) is not None]
    return int(sum(values)) if values else None


@dataclasses.dataclass(frozen=True)
class SpeedCell:
    """One planner at one bin speed (and latency and release mode), over its episodes.

    Counts of fields an older record lacks are None when no record of the cell carries them."""

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
    latency_mode: str = "measured"
    release_mode: str = "rest"
    splices: int = 0
    cans_released: int = 0
    not_attempted: int = 0
    put_down: int | None = None
    failures_by_stage: dict[str, int] | None = None
    splices_at_rest: int | None = None
    splice_speeds_rad_s: tuple[float, ...] = ()
    releases_moving: int | None = None
    release_speeds_m_s: tuple[float, ...] = ()
    near_misses_person: int | None = None
    ssm_holds: int | None = None
    person_min_distance_m: float | None = None
    escapes: int | None = None
    release_updates: int | None = None
    cans_offered: int = 0

    @property
    def rate(self) -> float:
        """Cans in the bin per can offered (every can of the episodes that ran or failed: a can
        an episode never reached, or one that ended in an error, counts as not delivered)."""
        return self.cans_in_bin / self.cans_offered if self.cans_offered else math.nan

    @property
    def replans_per_can(self) -> float:
        return self.replans / self.cans_attempted if self.cans_attempted else math.nan


def _stages(rs: Sequence[MovingBinRecord]) -> dict[str, int] | None:
    tables = [r.failures_by_stage for r in rs if isinstance(r.failures_by_stage, dict)]
    if not tables:
        return None
    out: dict[str, int] = {}
    for t in tables:
        for k, v in t.items():
            out[k] = out.get(k, 0) + int(v)
    return out


def _splice_speeds(rs: Sequence[MovingBinRecord]) -> tuple[float, ...]:
    """The joint speed at every drift replan's splice (the events': the replans made while the arm
    moves; those after an arrival or a protective stop start from rest); for a record whose events
    lack it, its median over every splice."""
    out: list[float] = []
    for r in rs:
        per_event = [e.splice_speed_rad_s for e in r.events
                     if e.outcome == "spliced" and e.trigger == "drift"
                     and e.splice_speed_rad_s is not None]
        if per_event:
            out += per_event
        elif r.splice_speed_median_rad_s is not None:
            out.append(r.splice_speed_median_rad_s)
    return tuple(out)


def speed_cells(records: Sequence[MovingBinRecord], *, planners: Sequence[str] | None = None) -> list[SpeedCell]:
    """Per planner (in the given order, then any other in the records), speed (ascending), latency
    mode and release mode, the episodes' totals (over the episodes with status ok)."""
    out = []
    for p in planner_order(records, planners):
        mine = [r for r in records if r.planner == p and r.speed_m_s is not None]
        groups = sorted({(float(r.speed_m_s), latency_mode(r), release_mode(r)) for r in mine})
        for v, lat, rel in groups:
            rs = [r for r in mine if (float(r.speed_m_s), latency_mode(r), release_mode(r)) == (v, lat, rel)]
            ok = [r for r in rs if r.status == "ok"]
            na = next((r.reason for r in rs if r.status == "not_applicable"), "")
            k, attempted = sum(r.cans_in_bin for r in ok), sum(r.cans_attempted for r in ok)
            offered = sum(r.cans_total for r in rs if r.status in ("ok", "error"))
            events = [e for r in ok for e in r.events if _deadline_bound(e)]
            spliced = [e for e in events if e.outcome == "spliced"]
            out.append(SpeedCell(
                planner=p, speed_m_s=v, episodes=len(rs), cans_in_bin=k, cans_total=sum(r.cans_total for r in ok),
                ci95=wilson_interval(k, offered), cans_offered=offered,
                replans=sum(r.replans for r in ok), cans_attempted=attempted,
                deadline_misses=sum(r.deadline_misses for r in ok),
                replan_failures=sum(r.replan_failures for r in ok),
                latencies_s=tuple(e.latency_s for e in events),
                contacts_bin=sum(r.contacts_bin for r in ok), contacts_person=sum(r.contacts_person for r in ok),
                jump_q_rad=max((e.jump_q_rad for e in spliced if e.jump_q_rad is not None),
                               default=math.nan),
                jump_v_rad_s=max((e.jump_v_rad_s for e in spliced if e.jump_v_rad_s is not None),
                                 default=math.nan),
                grasp_to_release_s=tuple(c.grasp_to_release_s for r in ok for c in r.cans
                                         if c.released and c.grasp_to_release_s is not None),
                given_up=sum(r.cans_given_up for r in ok), not_applicable=na,
                errors=sum(r.status == "error" for r in rs),
                latency_mode=lat, release_mode=rel,
                splices=sum(r.splices for r in ok),
                cans_released=sum(r.cans_released for r in ok),
                not_attempted=sum(r.cans_not_attempted if r.cans_not_attempted is not None
                                  else max(0, r.cans_total - r.cans_attempted) for r in ok),
                put_down=_total(ok, "cans_put_down"),
                failures_by_stage=_stages(ok),
                splices_at_rest=_total(ok, "splices_at_rest"),
                splice_speeds_rad_s=_splice_speeds(ok),
                releases_moving=_total(ok, "releases_moving"),
                release_speeds_m_s=tuple(r.release_speed_median_m_s for r in ok
                                         if r.release_speed_median_m_s is not None),
                near_misses_person=_total(ok, "near_misses_person"),
                ssm_holds=_total(ok, "ssm_holds"),
                person_min_distance_m=min((r.person_min_distance_m for r in ok
                                           if r.person_min_distance_m is not None), default=None),
                escapes=_total(ok, "escapes"), release_updates=_total(ok, "release_updates")))
    return out


def _q(values: Sequence[float], q: float) -> float:
    return float(np.quantile(values, q)) if len(values) else math.nan


def stages_cell(stages: dict[str, int] | None) -> str:
    """{"goal_ik": 3, "join": 1, "planner": 2} -> "ik 3, join 1, planner 2" (the replan's order; zeros left out)."""
    if stages is None:
        return "-"
    names = [s for s in STAGES if s in stages] + sorted(s for s in stages if s not in STAGES)
    parts = [f"{STAGE_SHORT.get(s, s)} {stages[s]}" for s in names if stages[s]]
    return ", ".join(parts) if parts else "0"


def _or_dash(v: Any) -> str:
    return "-" if v is None else str(v)


def _fraction_cell(c: SpeedCell) -> str:
    """"9/10 (90% [60, 98])": cans in the bin of those attempted, the rate and its Wilson interval."""
    if not c.cans_offered:
        return "-"
    lo, hi = c.ci95
    return f"{c.cans_in_bin}/{c.cans_offered} ({100 * c.rate:.0f}% [{100 * lo:.0f}, {100 * hi:.0f}])"


def moving_bin_rows(records: Sequence[MovingBinRecord], *, planners: Sequence[str] | None = None
                    ) -> tuple[list[str], list[list[Any]]]:
    """The main table's headers and rows: one per planner and speed (and latency and release mode
    when the run has more than one of either; their columns only then).

    A column for a field that no record carries (an older moving_bin.json) is left out."""
    cells = speed_cells(records, planners=planners)
    modes_lat = len({c.latency_mode for c in cells}) > 1
    modes_rel = len({c.release_mode for c in cells}) > 1
    ran = [c for c in cells if c.cans_total or not c.not_applicable]

    def shown(attr: str) -> bool:
        return any(getattr(c, attr) is not None for c in ran)

    show_not_attempted = any(c.not_attempted for c in ran)
    show_put_down, show_stages, show_rest = shown("put_down"), shown("failures_by_stage"), shown("splices_at_rest")
    show_splice_speed = any(c.splice_speeds_rad_s for c in ran)
    show_moving = shown("releases_moving")
    show_person = shown("near_misses_person") or shown("ssm_holds")
    show_escapes, show_updates = shown("escapes"), shown("release_updates")
    columns: list[tuple[str, Any]] = [
        ("planner", lambda c: c.planner),
        ("speed (m/s)", lambda c: format_number(c.speed_m_s)),
    ]
    if modes_lat:
        columns.append(("latency", lambda c: c.latency_mode))
    if modes_rel:
        columns.append(("release", lambda c: c.release_mode))
    columns += [
        ("episodes", lambda c: f"{c.episodes} ({c.errors} error{'s' * (c.errors != 1)})" if c.errors else c.episodes),
        ("cans in bin / offered", _fraction_cell),
    ]
    if show_not_attempted:
        columns.append(("not attempted", lambda c: c.not_attempted))
    if show_put_down:
        columns.append(("given up (put down)", lambda c: f"{c.given_up} ({_or_dash(c.put_down)})"))
    else:
        columns.append(("given up", lambda c: c.given_up))
    columns += [
        ("replans / can", lambda c: format_number(c.replans_per_can)),
        ("latency median / p95 (s)", lambda c: f"{format_number(_q(c.latencies_s, 0.5))} / "
                                               f"{format_number(_q(c.latencies_s, 0.95))}" if c.latencies_s else "-"),
        ("missed / failed", lambda c: f"{c.deadline_misses} / {c.replan_failures}"),
    ]
    if show_stages:
        columns.append(("failed by stage", lambda c: stages_cell(c.failures_by_stage)))
    if show_rest:
        columns.append(("splices (at rest)", lambda c: f"{c.splices} ({_or_dash(c.splices_at_rest)})"))
    else:
        columns.append(("splices", lambda c: c.splices))
    if show_splice_speed:
        columns.append(("drift splice speed (rad/s)", lambda c: format_number(_q(c.splice_speeds_rad_s, 0.5))
                        if c.splice_speeds_rad_s else "-"))
    if show_moving:
        columns.append(("released moving / released", lambda c: f"{_or_dash(c.releases_moving)} / {c.cans_released}"))
    if show_updates:
        columns.append(("release updates", lambda c: _or_dash(c.release_updates)))
    columns.append(("contacts bin / person", lambda c: f"{c.contacts_bin} / {c.contacts_person}"))
    if show_person:
        columns.append(("person near misses / SSM holds",
                        lambda c: f"{_or_dash(c.near_misses_person)} / {_or_dash(c.ssm_holds)}"))
    if show_escapes:
        columns.append(("escapes", lambda c: _or_dash(c.escapes)))
    columns += [
        ("jump (rad, rad/s)", lambda c: f"{format_number(c.jump_q_rad)}, {format_number(c.jump_v_rad_s)}"
         if math.isfinite(c.jump_q_rad) else "-"),
        ("grasp-release (s)", lambda c: format_number(_q(c.grasp_to_release_s, 0.5)) if c.grasp_to_release_s else "-"),
    ]
    headers = [h for h, _ in columns]
    lead = 3 + modes_lat + modes_rel  # planner, speed, the modes, episodes
    rows = []
    for c in cells:
        if c.not_applicable and not c.cans_total:
            row = [f(c) for _, f in columns[:lead]]
            rows.append([*row, f"not applicable: {c.not_applicable}", *["-"] * (len(columns) - lead - 1)])
            continue
        rows.append([f(c) for _, f in columns])
    return headers, rows


# --- latency per step ---------------------------------------------------------------------------

def latency_caption(source: set[str]) -> str:
    how = {
        "events": "from every deadline-bound replan's own step times (its event's parts_s), pooled over the episodes",
        "episodes": "from the episodes' own summaries (latency_parts_s), as the median of their medians / the "
                    "largest of their p95s (the events carried no step times)",
    }
    return ("Replan latency per step (ms, median / p95), per planner pooled over speeds, over the episodes with "
            "measured latency; " + "; or ".join(how[s] for s in ("events", "episodes") if s in source)
            + ". Total: the replan's whole wall time. Not shown for modelled latency (a declared constant).")


def _steps_in(tables: Sequence[dict[str, Any]]) -> list[str]:
    seen = list(dict.fromkeys(k for t in tables for k in t))
    return [s for s in STEPS if s in seen] + [s for s in seen if s not in STEPS]


def latency_table(records: Sequence[MovingBinRecord], planners: Sequence[str] | None = None
                  ) -> tuple[list[str], list[list[Any]], set[str]]:
    """The per-step latency table (headers, rows) and where its numbers come from ("events",
    "episodes"); no rows when no measured-latency record has step times."""
    measured = [r for r in records if r.status == "ok" and latency_mode(r) == "measured"]
    per_planner: dict[str, tuple[str, dict[str, list[float]], list[float], int]] = {}
    for p in planner_order(measured, planners):
        rs = [r for r in measured if r.planner == p]
        events = [e for r in rs for e in r.events if _deadline_bound(e) and e.parts_s]
        if events:
            steps = {s: [e.parts_s[s] for e in events if e.parts_s.get(s) is not None]
                     for s in _steps_in([e.parts_s for e in events])}
            per_planner[p] = ("events", steps, [e.latency_s for e in events], len(events))
            continue
        summaries = [r for r in rs if r.latency_parts_s]
        if summaries:
            tables = [r.latency_parts_s for r in summaries]
            steps = {s: [t[s] for t in tables if t.get(s) is not None] for s in _steps_in(tables)}
            total = [(r.replan_latency_median_s, r.replan_latency_p95_s) for r in summaries
                     if r.replan_latency_median_s is not None]
            per_planner[p] = ("episodes", steps, total, len(summaries))
    if not per_planner:
        return [], [], set()
    all_steps = _steps_in([dict.fromkeys(s) for _, s, _, _ in per_planner.values()])

    def ms(v: float) -> str:
        return format_number(1000 * v)

    def cell(source: str, values: list) -> str:
        if not values:
            return "-"
        if source == "events":
            return f"{ms(_q(values, 0.5))} / {ms(_q(values, 0.95))}"
        med = [v[0] for v in values]
        p95 = [v[1] for v in values if v[1] is not None]
        return f"{ms(_q(med, 0.5))} / {ms(max(p95)) if p95 else 'n/a'}"

    headers = ["planner", "over", *all_steps, "total"]
    rows = []
    for p, (source, steps, total, n) in per_planner.items():
        over = f"{n} replans" if source == "events" else f"{n} episodes"
        rows.append([p, over, *(cell(source, steps.get(s, [])) for s in all_steps), cell(source, total)])
    return headers, rows, {s for s, _, _, _ in per_planner.values()}


def latency_rows(records: Sequence[MovingBinRecord], planners: Sequence[str] | None = None
                 ) -> tuple[list[str], list[list[Any]]]:
    """Per planner, the median / p95 of each step of the deadline-bound replans (ms); see `latency_table`."""
    headers, rows, _ = latency_table(records, planners)
    return headers, rows


# --- the section --------------------------------------------------------------------------------

def moving_bin_tables(records: Sequence[MovingBinRecord], *, planners: Sequence[str] | None = None
                      ) -> list[tuple[str, list[str], list[list[Any]]]]:
    """The section's tables in order, each as (caption, headers, rows): the main one (no caption:
    the section's text is its caption), the paired differences and the latency per step (each
    only when it has rows)."""
    out = [("", *moving_bin_rows(records, planners=planners))]
    headers, rows = paired_rows(records, planners)
    if rows:
        out.append((PAIRED_CAPTION, headers, rows))
    headers, rows, source = latency_table(records, planners)
    if rows:
        out.append((latency_caption(source), headers, rows))
    return out


def moving_bin_table(records: Sequence[MovingBinRecord], *, planners: Sequence[str] | None = None,
                     tablefmt: str = "github") -> str:
    """The main table, then (each after its caption) the paired differences and the latency per step."""
    parts = []
    for i, (caption, headers, rows) in enumerate(moving_bin_tables(records, planners=planners)):
        if caption:
            parts.append(caption)
        # the main table's numbers align as numbers; the others' cells are text ("+12.5" keeps its sign)
        parts.append(tabulate(rows, headers, tablefmt=tablefmt, disable_numparse=i > 0))
    return "\n\n".join(parts)
