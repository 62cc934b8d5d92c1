"""How contended the machine was while trials planned: measured per trial, summed up per run.

A trial's worker measures, across `planner.plan` (`ContentionProbe`), from Linux's /proc:

- `cpu_wait_s`: how long its process's threads were ready to run but waited for a CPU (the
  run-queue delay of /proc/self/task/*/schedstat): the time other processes took from it;
- `steal_s`: the CPU time the hypervisor took from the machine's virtual CPUs (/proc/stat's
  `steal`, all CPUs), and `machine_cpu_s`, the CPU time the machine had (all CPUs, idle included);
- `others_cpu_s`: the busy CPU time of every other process (the machine's busy time less this
  process's CPU time; a run with J workers has J - 1 of its own among them);
- `load1` and `runnable` (/proc/loadavg: the 1-minute load average and the threads runnable at the
  end, this one included) and `cores` (the CPUs this process may run on).

/proc/stat counts in ticks (10 ms), so `steal_s` and `others_cpu_s` of a trial shorter than a few
ticks are coarse; `cpu_wait_s` is in nanoseconds. Where /proc is missing (not Linux) every field
is None and no trial is called contended.

A trial is **contended** (`is_contended`) when its process waited for a CPU for more than
`WAIT_SHARE` (10%) of its planning wall time and at least `WAIT_MIN_S` (10 ms, a few scheduler
ticks: below it one preemption decides), or when the machine's steal was more than `STEAL_SHARE`
(5%) of its CPU time across the trial and at least `STEAL_MIN_S` (50 ms, 5 ticks). These are round
figures, not fitted to any run: 10% of a budget is the margin by which a wall-clock deadline moves
a late trial's outcome, and 5% steal is where cloud providers start to warn. A quiet machine running
one worker per core gives waits of a few milliseconds at most.

A **run** is contended (`run_contention`'s `run_contended`) when any of its trials is, or when a
planner's trials together waited for a CPU more than `WAIT_SHARE` of their planning wall time (and
at least `WAIT_MIN_S`): trials of a few milliseconds each stay under the per-trial floor, yet their
times, taken together, are stretched.
"""

from __future__ import annotations

import dataclasses
import os
import statistics
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from suite.run.records import TrialRecord

#: A trial is contended when its run-queue wait is above this share of its planning wall time ...
WAIT_SHARE = 0.10
#: ... and at least this long (s).
WAIT_MIN_S = 0.01
#: Or when the machine's steal is above this share of its CPU time across the trial ...
STEAL_SHARE = 0.05
#: ... and at least this much (CPU-seconds, all CPUs).
STEAL_MIN_S = 0.05
#: The rule in one line, for manifests, summaries and reports.
RULE = (f"a trial is contended when its process waited for a CPU more than {WAIT_SHARE:.0%} of its planning wall "
        f"time (and at least {WAIT_MIN_S * 1000:g} ms), or when the machine's steal was above {STEAL_SHARE:.0%} "
        f"of its CPU time across the trial (and at least {STEAL_MIN_S * 1000:g} ms); a run is contended when a "
        f"trial is, or when one planner's trials together waited more than {WAIT_SHARE:.0%} of their planning "
        "wall time")
#: Ticks per second of /proc/stat's counters.
_HZ = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


def cores_available() -> int:
    """The CPUs this process may run on: its affinity, capped by a cgroup CPU quota if one is set."""
    try:
        n = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        n = os.cpu_count() or 1
    try:
        with open("/sys/fs/cgroup/cpu.max") as f:
            quota, period = f.read().split()[:2]
        if quota != "max":
            n = max(1, min(n, int(-(-int(quota) // int(period)))))
    except (OSError, ValueError):
        pass
    return n


def _stat() -> tuple[int, int, int] | None:
    """(all ticks, idle ticks (idle + iowait), steal ticks) of the machine (/proc/stat's cpu line)."""
    try:
        with open("/proc/stat") as f:
            fields = f.readline().split()
        v = [int(x) for x in fields[1:9]]  # user nice system idle iowait irq softirq steal (guest is in user)
    except (OSError, ValueError):
        return None
    v += [0] * (8 - len(v))
    return sum(v), v[3] + v[4], v[7]


def _waits_ns() -> dict[str, int] | None:
    """Run-queue wait (ns) of each thread of this process (/proc/self/task/TID/schedstat, field 2)."""
    try:
        tids = os.listdir("/proc/self/task")
    except OSError:
        return None
    out = {}
    for tid in tids:
        try:
            with open(f"/proc/self/task/{tid}/schedstat") as f:
                out[tid] = int(f.read().split()[1])
        except (OSError, ValueError, IndexError):  # a thread that ended meanwhile
            continue
    return out or None


def _loadavg() -> tuple[float, int] | tuple[None, None]:
    """(1-minute load average, threads runnable now) from /proc/loadavg."""
    try:
        with open("/proc/loadavg") as f:
            parts = f.read().split()
        return float(parts[0]), int(parts[3].split("/")[0])
    except (OSError, ValueError, IndexError):
        return None, None


@dataclasses.dataclass(frozen=True)
class ContentionProbe:
    """The counters at the start of a measured stretch (`start`); `stop` gives the contention
    across it (a plain JSON dict, a record's `contention`)."""

    stat: tuple[int, int, int] | None
    waits_ns: dict[str, int] | None

    @classmethod
    def start(cls) -> "ContentionProbe":
        return cls(_stat(), _waits_ns())

    def stop(self, *, wall_s: float, cpu_s: float | None) -> dict[str, Any]:
        """The contention across the stretch.

        Args:
            wall_s: its wall time (s).
            cpu_s: this process's CPU time across it (s), or None.

        Returns:
            {cpu_wait_s, steal_s, machine_cpu_s, others_cpu_s, load1, runnable, cores, contended}.
        """
        stat, waits = _stat(), _waits_ns()
        load1, runnable = _loadavg()
        out: dict[str, Any] = {"cpu_wait_s": None, "steal_s": None, "machine_cpu_s": None, "others_cpu_s": None,
                               "load1": load1, "runnable": runnable, "cores": cores_available()}
        if waits is not None and self.waits_ns is not None:
            out["cpu_wait_s"] = round(sum(w - self.waits_ns.get(t, 0) for t, w in waits.items()) / 1e9, 6)
        if stat is not None and self.stat is not None:
            total, idle, steal = (b - a for a, b in zip(self.stat, stat))
            out["machine_cpu_s"] = total / _HZ
            out["steal_s"] = steal / _HZ
            if cpu_s is not None:
                out["others_cpu_s"] = round(max(0.0, (total - idle - steal) / _HZ - cpu_s), 6)
        out["contended"] = is_contended(out, wall_s=wall_s)
        return out


def is_contended(contention: dict[str, Any] | None, *, wall_s: float | None) -> bool | None:
    """Whether a trial's measured contention passes the rule (`RULE`); None if nothing was measured."""
    if not isinstance(contention, dict):
        return None
    wait, steal, machine = (contention.get(k) for k in ("cpu_wait_s", "steal_s", "machine_cpu_s"))
    known = False
    if isinstance(wait, (int, float)) and isinstance(wall_s, (int, float)):
        known = True
        if wait >= WAIT_MIN_S and wait > WAIT_SHARE * wall_s:
            return True
    if isinstance(steal, (int, float)) and isinstance(machine, (int, float)) and machine > 0:
        known = True
        if steal >= STEAL_MIN_S and steal > STEAL_SHARE * machine:
            return True
    return False if known else None


def record_contended(record: TrialRecord) -> bool | None:
    """Whether a trial record was contended, by the current rule (None: it measured nothing)."""
    return is_contended(record.contention, wall_s=record.planning_time_s)


# --- the run -------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class MachineSample:
    """The machine's counters at one moment (the parent's, around a whole run)."""

    t_s: float
    stat: tuple[int, int, int] | None
    load1: float | None


def machine_sample() -> MachineSample:
    return MachineSample(time.monotonic(), _stat(), _loadavg()[0])


def machine_across(before: MachineSample) -> dict[str, Any]:
    """The machine across a stretch that started at `before`: {wall_s, busy_share, steal_share,
    load1_start, load1_end, cores} (shares of all CPUs' time; None where /proc is missing)."""
    after = machine_sample()
    out: dict[str, Any] = {"wall_s": round(after.t_s - before.t_s, 3), "busy_share": None, "steal_share": None,
                           "load1_start": before.load1, "load1_end": after.load1, "cores": cores_available()}
    if before.stat is not None and after.stat is not None:
        total, idle, steal = (b - a for a, b in zip(before.stat, after.stat))
        if total > 0:
            out["busy_share"] = round((total - idle) / total, 4)
            out["steal_share"] = round(steal / total, 4)
    return out


def median_or_none(values: list[float]) -> float | None:
    """The median, or None for no values."""
    return statistics.median(values) if values else None


def run_contention(records: Sequence[TrialRecord], *, machine: dict[str, Any] | None = None) -> dict[str, Any]:
    """A run's contention from its records: how many trials were measured and contended (and which),
    their share of planning wall time spent waiting for a CPU, the load average they saw, and the
    budget clock(s) of the run; `machine`, the parent's `machine_across` of the run, if known.

    Returns:
        {rule, budget_clock, trials, measured, contended, contended_ids, by_planner: {NAME:
        {measured, contended, cpu_wait_s, planning_wall_s, cpu_wait_share, contended_together}},
        cpu_wait_share, load1: {median, max}, run_contended, machine}.
    """
    measured = contended = 0
    ids: list[str] = []
    by_planner: dict[str, dict[str, Any]] = {}
    loads: list[float] = []
    for rec in records:
        verdict = record_contended(rec)
        if verdict is None:
            continue
        measured += 1
        p = by_planner.setdefault(str(rec.planner), {"measured": 0, "contended": 0, "cpu_wait_s": 0.0,
                                                            "planning_wall_s": 0.0})
        p["measured"] += 1
        if verdict:
            contended += 1
            p["contended"] += 1
            ids.append(str(rec.trial_id))
        c = rec.contention
        if isinstance(c.get("cpu_wait_s"), (int, float)) and isinstance(rec.planning_time_s, (int, float)):
            p["cpu_wait_s"] += c["cpu_wait_s"]
            p["planning_wall_s"] += rec.planning_time_s
        if isinstance(c.get("load1"), (int, float)):
            loads.append(float(c["load1"]))
    for p in by_planner.values():
        wait, wall = p["cpu_wait_s"], p["planning_wall_s"]
        p["cpu_wait_share"] = round(wait / wall, 4) if wall > 0 else None
        p["contended_together"] = wall > 0 and wait >= WAIT_MIN_S and wait > WAIT_SHARE * wall
        p["cpu_wait_s"], p["planning_wall_s"] = round(wait, 6), round(wall, 6)
    wait_s = sum(p["cpu_wait_s"] for p in by_planner.values())
    wall_s = sum(p["planning_wall_s"] for p in by_planner.values())
    clocks = sorted({str(r.budget_clock or "wall") for r in records})
    return {"rule": RULE, "budget_clock": clocks[0] if len(clocks) == 1 else clocks, "trials": len(records),
            "measured": measured, "contended": contended, "contended_ids": ids, "by_planner": by_planner,
            "cpu_wait_share": round(wait_s / wall_s, 4) if wall_s > 0 else None,
            "load1": {"median": median_or_none(loads), "max": max(loads) if loads else None},
            "run_contended": bool(contended or any(p["contended_together"] for p in by_planner.values())),
            "machine": machine}
