"""Export a run as OMPL benchmark logs, for OMPL's `ompl_benchmark_statistics.py` and Planner Arena.

The format is the one `ompl::tools::Benchmark::saveResultsToStream` writes (documented in OMPL's
doc/markdown/benchmark.md, "The benchmark logfile format"). Facts the parser relies on:

- One log file holds one experiment; the experiment name, host name and seed are read as the
  last (or first) whitespace-separated token of their line, so they must hold no spaces.
- Run properties are "name TYPE" lines; the parser turns spaces in a name into underscores and
  adds a column of that SQL type to the `runs` table, so names are plain words.
- Each run is one line of values, each followed by "; "; an empty value (or nan, inf) is NULL.
- Planner Arena draws an enum attribute by joining the `status` column with the `enums` table,
  so the outcome enum is named "status".
- An optimizing planner's runs may add "K progress properties for each run", the property names,
  "N runs" and one line per run of "v1,v2,;" points (the properties in name order) before the
  closing "."; the parser stores them in its `progress` table.

Files written (in run_dir/arena/): `ompl_benchmark.log` (every trial of the run, one experiment)
and `ompl_benchmark_<kind>.log` (one experiment per problem kind). Turn them into a database with
`ompl_benchmark_statistics.py run_dir/arena/*.log -d benchmark.db` and open it in Planner Arena.
"""

from __future__ import annotations

import datetime as dt
import json
import logging
import math
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from suite.run.records import (
    STATUSES,
    TrialRecord,
    is_success,
    metric,
    planners_in,
    problem_kinds_in,
    read_manifest,
    read_trials,
)

log = logging.getLogger(__name__)

ARENA_DIR = "arena"
LOG_NAME = "ompl_benchmark.log"
LIBRARY = "suite"

#: Run properties every trial has, besides one REAL per metric: name -> (SQL type, value getter).
FIXED_PROPERTIES: dict[str, tuple[str, Any]] = {
    "time": ("REAL", lambda r: metric(r, "planning_time_s")),
    "solved": ("BOOLEAN", lambda r: int(is_success(r))),
    "scene seed": ("INTEGER", lambda r: int(r.scene_seed)),
    "can id": ("INTEGER", lambda r: None if r.can_id is None else int(r.can_id)),  # None: a free transit
}


def _token(text: str) -> str:
    """A value that must be one whitespace-free token in the log."""
    return re.sub(r"\s+", "_", str(text).strip()) or "unknown"


def property_name(metric_name: str) -> str:
    """A metric's run-property name: lower-case words (the parser turns spaces into underscores)."""
    words = re.sub(r"[^a-z0-9]+", " ", metric_name.lower()).split()
    return " ".join(words)


def _value(v: Any, sql_type: str) -> str:
    if v is None:
        return ""
    if sql_type == "REAL":
        v = float(v)
        return repr(v) if math.isfinite(v) else ""
    return str(int(v))


def _metric_names(records: Sequence[TrialRecord]) -> list[str]:
    names: dict[str, None] = {}
    for r in records:
        for k, v in (r.metrics or {}).items():
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                names.setdefault(k, None)
    reserved = set(FIXED_PROPERTIES) | {"status"}
    return sorted(k for k in names if property_name(k) and property_name(k) not in reserved)


def _settings_lines(config: Any) -> list[str]:
    """A planner's configuration as "name = value" lines (one line each, sorted)."""
    if not isinstance(config, dict):
        return [] if config is None else [f"config = {json.dumps(config, default=str)}"]
    out = []
    for k in sorted(config):
        v = config[k]
        text = v if isinstance(v, str) else json.dumps(v, default=str, sort_keys=True)
        out.append(f"{' '.join(str(k).split())} = {' '.join(str(text).split())}")
    return out


def _suite_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("can-recycling-planner-suite")
    except PackageNotFoundError:
        return "0.0.0"


def _multiline(text: str) -> list[str]:
    lines = [ln for ln in text.splitlines() if not ln.startswith("|>>>")]
    return ["<<<|", *lines, "|>>>"]


def benchmark_log(
    records: Sequence[TrialRecord],
    *,
    experiment: str,
    manifest: dict[str, Any] | None = None,
    planners: Sequence[str] | None = None,
) -> str:
    """One experiment in OMPL's benchmark log format: every planner and its trials as runs.

    Args:
        records: the trials of this experiment.
        experiment: its name (spaces become underscores).
        manifest: the run's manifest (command, config, machine), for the preamble.
        planners: planner order (default: the manifest's, then order of appearance).

    Returns:
        The log text.
    """
    manifest = manifest or {}
    config = manifest.get("config") or {}
    machine = manifest.get("machine") or {}
    planners = list(planners) if planners is not None else planners_in(records, manifest)
    statuses = list(STATUSES) + sorted({str(r.status) for r in records} - set(STATUSES))
    metrics = _metric_names(records)
    props = {**FIXED_PROPERTIES, "status": ("ENUM", lambda r: statuses.index(str(r.status)))}
    for m in metrics:
        props[property_name(m)] = ("REAL", lambda r, m=m: metric(r, m))
    names = sorted(props)

    started = manifest.get("started_utc") or dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds")
    exp_props = {
        "trials INTEGER": len(records),
        "scenes INTEGER": len({(r.scene_seed, r.variant) for r in records}),
        "problems INTEGER": len({(r.scene_seed, r.variant, r.can_id, r.task_index, r.problem)
                                 for r in records}),
    }
    counts = {p: sum(r.planner == p for r in records) for p in planners}
    time_limits = sorted({float(r.time_limit_s) for r in records if r.time_limit_s is not None})
    time_limit = time_limits[-1] if time_limits else float(config.get("time_limit_s") or 0.0)
    seed = config.get("seed", 0)
    total_time = sum(t for t in (metric(r, "planning_time_s") for r in records) if math.isfinite(t))
    setup = "\n".join(
        [f"command: {manifest.get('command', 'unknown')}",
         f"variants: {', '.join(sorted({str(r.variant) for r in records}))}",
         f"problem kinds: {', '.join(problem_kinds_in(records))}",
         "time: planning wall time (s) measured by the suite's orchestrator; status: the trial outcome",
         f"config: {json.dumps(config, default=str, sort_keys=True)}"]
    )
    cpu = "\n".join(f"{k}: {v}" for k, v in sorted(machine.items())) if machine else "unknown"

    out = [
        f"{LIBRARY} version {_suite_version()}",
        f"Experiment {_token(experiment)}",
        f"{len(exp_props)} experiment properties",
        *(f"{k} = {v}" for k, v in exp_props.items()),
        f"Running on {_token(machine.get('hostname') or machine.get('node') or 'unknown')}",
        f"Starting at {started}",
        *_multiline(setup),
        *_multiline(cpu),
        f"{int(seed) if isinstance(seed, int) else 0} is the random seed",
        f"{time_limit!r} seconds per run",
        "0.0 MB per run",
    ]
    if len(set(counts.values())) == 1:
        out.append(f"{next(iter(counts.values()))} runs per planner")
    out += [
        f"{total_time!r} seconds spent to collect the data",
        "1 enum type",
        "|".join(["status", *statuses]),
        f"{len(planners)} planners",
    ]
    for p in planners:
        mine = [r for r in records if r.planner == p]
        settings = _settings_lines(mine[0].planner_config if mine else None)
        out += [_token(p), f"{len(settings)} common properties", *settings]
        out.append(f"{len(names)} properties for each run")
        out += [f"{n} {props[n][0]}" for n in names]
        out.append(f"{len(mine)} runs")
        for r in mine:
            typ = {n: ("REAL" if props[n][0] == "REAL" else "INTEGER") for n in names}
            out.append("".join(f"{_value(props[n][1](r), typ[n])}; " for n in names))
        out += _progress_lines(mine)
        out.append(".")
    return "\n".join(out) + "\n"


#: The progress properties of an optimizing planner's runs, in the order OMPL writes them (its
#: per-point std::map sorts them by name); Planner Arena's "Progress" tab plots them against time.
PROGRESS_PROPERTIES = ("best cost REAL", "time REAL")


def _progress_lines(records: Sequence[TrialRecord]) -> list[str]:
    """The progress block of one planner: every run's (best cost, time) points as "c,t,;c,t,;",
    written when any of its runs recorded progress (`stats.progress`, see planners.ompl_solve)."""
    series = [(r.stats or {}).get("progress") for r in records]
    if not any(series):
        return []
    lines = [f"{len(PROGRESS_PROPERTIES)} progress properties for each run", *PROGRESS_PROPERTIES,
             f"{len(records)} runs"]
    for points in series:
        lines.append("".join(f"{'nan' if c is None else repr(float(c))},{float(t)!r},;" for t, c in (points or [])))
    return lines


def write_arena_logs(run_dir: str | Path, *, records: Sequence[TrialRecord] | None = None) -> list[Path]:
    """Write run_dir/arena/ompl_benchmark.log (the whole run) and one log per problem kind.

    Returns:
        The written log files.
    """
    run_dir = Path(run_dir)
    records = list(records) if records is not None else read_trials(run_dir)
    if not records:
        log.warning("%s: no trial records, no benchmark log", run_dir)
        return []
    manifest = read_manifest(run_dir)
    planners = planners_in(records, manifest)
    variants = "_".join(sorted({str(r.variant) for r in records}))
    out_dir = run_dir / ARENA_DIR
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    groups = [("all_motions", LOG_NAME, list(records))] + [
        (k, f"ompl_benchmark_{k}.log", [r for r in records if r.problem == k]) for k in problem_kinds_in(records)
    ]
    for label, name, recs in groups:
        path = out_dir / name
        path.write_text(
            benchmark_log(recs, experiment=f"cans_{variants}_{label}", manifest=manifest, planners=planners),
            encoding="utf-8",
        )
        written.append(path)
    log.info("wrote %d OMPL benchmark logs to %s", len(written), out_dir)
    return written
