"""The run's budget clock and machine contention in its summary: a warning naming the contended
trials, a table per planner, and the same in summary.json (`suite.run.contention` measures and
defines it)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from tabulate import tabulate

from suite.run.contention import (
    RULE,
    WAIT_SHARE,
    median_or_none,
    record_contended,
    run_contention,
)
from suite.run.records import TrialRecord

#: How many contended trials a warning names before it counts the rest.
NAMED_TRIALS = 10

CONTENTION_INTRO = (
    "Measured across each trial's planning, in its worker (Linux /proc): the time its process waited for a "
    "CPU that other processes held, the steal of the machine's virtual CPUs, and the 1-minute load average; "
    f"{RULE}. CPU / wall is the trial's process CPU time over its planning wall time (about 1 for a "
    "single-threaded planner that had its core, lower when it waited).")


def budget_clocks(records: Sequence[TrialRecord]) -> list[str]:
    """The budget clocks of a run's records ("wall" for records from before budgets had clocks)."""
    return sorted({str(r.budget_clock or "wall") for r in records})


def contended_ids(records: Sequence[TrialRecord]) -> list[str]:
    """The trial ids of the contended records, in file order."""
    return [str(r.trial_id) for r in records if record_contended(r)]


def contention_warning(records: Sequence[TrialRecord]) -> str | None:
    """One paragraph for the top of summary.md when the run was contended (None otherwise): how many
    trials, which (the first NAMED_TRIALS ids, then a count), the planners whose trials together
    waited, and what that means for the run's clock."""
    run = run_contention(records)
    if not run["run_contended"]:
        return None
    ids = run["contended_ids"]
    parts = ["**Warning: the machine was contended.**"]
    if ids:
        named = ", ".join(f"`{i}`" for i in ids[:NAMED_TRIALS])
        more = f" and {len(ids) - NAMED_TRIALS} more (summary.json lists them all)" if len(ids) > NAMED_TRIALS else ""
        parts.append(f"{len(ids)} of {run['measured']} measured trials waited for a CPU (or lost it to steal): "
                     f"{named}{more}.")
    together = [f"{p} ({100 * c['cpu_wait_share']:.0f}%)" for p, c in run["by_planner"].items()
                if c["contended_together"]]
    if together:
        parts.append(f"Planners whose trials together spent more than {WAIT_SHARE:.0%} of their planning wall time "
                     f"waiting for a CPU: {', '.join(together)}.")
    parts.append("Their planning times are stretched, and with this run's wall-clock budget their outcomes may be too."
                 if "wall" in budget_clocks(records) else
                 "Their wall times are stretched; this run's budget is CPU time, which the contention does not spend.")
    return " ".join(parts) + f" Rule: {RULE}."


def contention_rows(records: Sequence[TrialRecord], planners: Sequence[str]) -> tuple[list[str], list[list[Any]]]:
    """Per planner: trials measured and contended, median CPU / wall, share of planning wall time spent
    waiting for a CPU, median load average."""
    headers = ["planner", "trials measured", "contended", "median CPU / wall", "CPU wait / wall time",
               "median load (1 min)"]
    rows = []
    for p in planners:
        mine = [r for r in records if r.planner == p and record_contended(r) is not None]
        ratios = [r.planning_cpu_time_s / r.planning_time_s for r in mine
                  if isinstance(r.planning_cpu_time_s, (int, float)) and r.planning_time_s]
        waits = [(r.contention.get("cpu_wait_s"), r.planning_time_s) for r in mine]
        waits = [(w, t) for w, t in waits if isinstance(w, (int, float)) and isinstance(t, (int, float))]
        loads = [r.contention["load1"] for r in mine if isinstance(r.contention.get("load1"), (int, float))]
        wall = sum(t for _, t in waits)
        ratio, load = median_or_none(ratios), median_or_none(loads)
        rows.append([p, len(mine), sum(bool(record_contended(r)) for r in mine),
                     "n/a" if ratio is None else f"{ratio:.2f}",
                     "n/a" if not wall else f"{100 * sum(w for w, _ in waits) / wall:.1f}%",
                     "n/a" if load is None else f"{load:.2f}"])
    return headers, rows


def clock_line(records: Sequence[TrialRecord]) -> str:
    """What the budgets were measured on."""
    clocks = budget_clocks(records)
    if clocks == ["cpu"]:
        return ("Budgets are CPU time (`--budget-clock cpu`): each trial's budget, and the rule that a success "
                "after it is a timeout, run on its worker process's CPU time; the times reported are wall times.")
    if clocks == ["wall"]:
        return "Budgets are wall-clock time (`--budget-clock wall`)."
    return f"Budgets on several clocks: {', '.join(clocks)} (each record's `budget_clock` says which)."


def contention_markdown(records: Sequence[TrialRecord], planners: Sequence[str]) -> str:
    """summary.md's section: the clock, the rule, and the table (or why there is none)."""
    md = ["## Budget clock and machine contention", "", clock_line(records), ""]
    if not any(record_contended(r) is not None for r in records):
        md.append("No trial of this run measured the machine's contention (records from before it was measured, "
                  "or not on Linux).")
        return "\n".join(md) + "\n"
    md += [CONTENTION_INTRO, "", tabulate(*reversed(contention_rows(records, planners)), tablefmt="github")]
    return "\n".join(md) + "\n"


def contention_json(records: Sequence[TrialRecord]) -> dict[str, Any]:
    """summary.json's `contention`: `suite.run.contention.run_contention` of the records (rule,
    budget_clock, trials, measured, contended, contended_ids, by_planner, cpu_wait_share, load1)."""
    out = run_contention(records)
    out.pop("machine", None)  # the parent's view of the run is the manifest's
    return out
