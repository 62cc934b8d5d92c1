"""`import`: an external planner's results file judged exactly like a suite trial.

Each line of the results file (`ResultLine`, the schema of a line) names a problem of the
dataset by `problem_id`. Every line is checked before anything is judged: a line that is not a
JSON object, lacks a field, names a problem the dataset (tier) does not hold, repeats a problem,
or gives a path that is not an (N, 7) list of finite numbers is one `SuiteError` naming the line,
and nothing is written. Then every problem of the tier becomes one ordinary trial record made by
`suite.run.trial.judge_result` (validator, TOPP-RA, metrics), the function every suite trial ends
in; a problem the file leaves out is `no_result`.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import hashlib
import json
import os
import re
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import Field

from planners.base import PlanResult, PlanStatus
from scenes.errors import SuiteError
from scenes.schema import load
from suite.run.records import MANIFEST_FILE, NO_RESULT, TRIALS_FILE, TrialRecord

#: Reported statuses kept as the record's status when the line has no path; any other word with
#: no path is recorded as no_solution.
KEPT_FAILURES = tuple(s.value for s in (PlanStatus.NO_SOLUTION, PlanStatus.TIMEOUT, PlanStatus.ERROR,
                                        PlanStatus.INVALID_START, PlanStatus.INVALID_GOAL))
PLANNER_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+-]{0,63}$")

_Q = Annotated[tuple[float, float, float, float, float, float, float],
               Field(description="joint positions of iiwa_joint_1..7, rad")]


@dataclasses.dataclass(frozen=True)
class ResultLine:
    """One line of the results file: an external planner's answer to one problem. The schema of a
    line (`read_results` loads each into it; the export's schema.json is generated from it)."""

    problem_id: Annotated[str, Field(description="the problem's problem_id, as exported")]
    status: Annotated[str, Field(description="your planner's own status word (kept as reported_status); "
                                             f"{', '.join(KEPT_FAILURES)} are kept as the record's status when "
                                             "path is null")]
    path: Annotated[Annotated[tuple[_Q, ...], Field(min_length=1)] | None, Field(description=(
        "your solution: waypoints (N >= 1) of iiwa_joint_1..7 in rad, from q_start to q_goal, joined by "
        "straight joint-space segments; null for no solution. A non-null path is judged as a claimed "
        "solution whatever status says"))]
    planning_time_s: Annotated[float, Field(ge=0, description="your planner's wall time for this problem, s")]
    hardware: Annotated[str | dict[str, Any] | None, Field(description="where it ran (CPU, GPU), kept in the "
                                                                       "record")] = None
    notes: Annotated[str | None, Field(description="free text, kept in the record")] = None
    stats: Annotated[dict[str, Any] | None, Field(description="planner statistics (plain JSON), kept in the "
                                                              "record")] = None

    @property
    def path_array(self) -> np.ndarray | None:
        """The path as an (N, 7) float array, or None."""
        return None if self.path is None else np.asarray(self.path, float)


def read_results(path: str | Path, *, known: set[str], dataset: str,
                 elsewhere: Callable[[str], bool] = lambda pid: False) -> list[ResultLine]:
    """Read and check a results file: each line is loaded into `ResultLine` (`scenes.schema.load`),
    then its problem_id is checked against the dataset's tier and the lines before it.

    Args:
        path: the JSON-lines results file.
        known: the problem_ids that can be answered (the tier's).
        dataset: the dataset's `NAME:TIER`, for messages.
        elsewhere: whether an unknown problem_id is in the dataset outside the tier (for the message).

    Returns:
        The lines, in file order.

    Raises:
        SuiteError: one line naming the file, the line number and what is wrong.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise SuiteError(f"cannot read results file {str(path)!r}: {getattr(exc, 'strerror', None) or exc}") from None
    out: list[ResultLine] = []
    seen: dict[str, int] = {}
    for lineno, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        where = f"{path} line {lineno}"
        try:
            rec = json.loads(line)
        except ValueError:
            raise SuiteError(f"{where} is not valid JSON") from None
        if not isinstance(rec, dict):
            raise SuiteError(f"{where} is not a JSON object")
        result = load(ResultLine, rec, where=f"{where}: ")
        pid = result.problem_id
        if pid not in known:
            name, _, tier = dataset.partition(":")
            if elsewhere(pid):
                raise SuiteError(f"{where}: problem_id {pid!r} is in dataset {name} but not in tier {tier!r} "
                                 "being imported")
            raise SuiteError(f"{where}: problem_id {pid!r} is not a problem of dataset {dataset}")
        if pid in seen:
            raise SuiteError(f"{where}: problem_id {pid!r} was already answered on line {seen[pid]}")
        seen[pid] = lineno
        out.append(result)
    return out


def _reported(line: ResultLine) -> PlanResult:
    """The planner's answer as a PlanResult: a path is a claimed solution, else its failure."""
    stats: dict[str, Any] = {"reported_status": line.status}
    if line.stats:
        stats["external_stats"] = line.stats
    if line.path is not None:
        return PlanResult(PlanStatus.SUCCESS, line.path_array, stats)
    status = line.status if line.status in KEPT_FAILURES else PlanStatus.NO_SOLUTION.value
    return PlanResult(PlanStatus(status), None, stats)


@dataclasses.dataclass(frozen=True)
class ImportCounts:
    """What an import did: records written per status, and paths sent after the time budget."""

    planner: str
    problems: int
    statuses: dict[str, int]
    over_budget: int

    def line(self) -> str:
        parts = ", ".join(f"{n} {s}" for s, n in sorted(self.statuses.items(), key=lambda kv: -kv[1]))
        text = f"imported {self.planner}: {self.problems} problems: {parts}"
        if self.over_budget:
            text += f"; {self.over_budget} paths reported after the time budget (flagged over_budget)"
        return text


def judge_results(lines: list[ResultLine], ds, *, planner: str) -> list[TrialRecord]:
    """One trial record per problem of the dataset (tier), in its order: judged lines, and
    no_result for the problems the file leaves out (`hardware` and `notes`, the line's own,
    kept in its `extra`)."""
    from planners.worlds import collision_world
    from suite.run.trial import judge_result, make_trial, trial_record

    import sys

    from tqdm import tqdm

    by_id = {ln.problem_id: ln for ln in lines}
    records = []
    # progress on a terminal, as compare shows it (a long import judges dense paths for minutes)
    bar = tqdm(total=len(by_id), desc="judging", unit="path", file=sys.stderr, disable=not sys.stderr.isatty())
    for pid, problem in zip(ds.ids, ds.problems):
        spec = make_trial(problem, planner=planner, planner_config={}, run_seed=0, meta=ds.meta[pid])
        record = trial_record(spec)
        record["external"] = True
        line = by_id.get(pid)
        if line is None:
            record.update(status=NO_RESULT, planning_time_s=None, path=None, metrics={}, stats={})
        else:
            judge_result(record, spec=spec, world=collision_world(problem), result=_reported(line),
                         planning_time_s=line.planning_time_s)
            if line.path is not None and line.planning_time_s > problem.time_limit_s:
                record["stats"]["over_budget"] = True  # a solution sent after the budget: flagged, not failed
            if line.hardware is not None:
                record["hardware"] = line.hardware
            if line.notes is not None:
                record["notes"] = line.notes
            bar.update(1)
        records.append(TrialRecord.from_json(record))
    bar.close()
    return records


def import_results(*, dataset: str, results: str | Path, planner: str, out: str | Path | None = None,
                   into: str | Path | None = None, time_limit_s: float = 5.0,
                   argv: list[str] | None = None) -> tuple[Path, ImportCounts]:
    """Judge a results file and write its records: a new run directory (`out`) or appended to an
    existing run on the same dataset (`into`).

    Args:
        dataset: `NAME[:TIER]` the problems were exported from.
        results: the results file.
        planner: the name the records carry.
        out: a new run directory (manifest.json and trials.jsonl written), or None.
        into: an existing run directory to add the records to, or None (exactly one of out, into).
        time_limit_s: the budget the problems were exported with, s (records' time_limit_s).
        argv: the command line, for the manifest.

    Returns:
        The run directory and the counts.

    Raises:
        SuiteError: a bad planner name, dataset, results line or run directory; nothing is written.
    """
    from suite.problems.dataset import load_dataset, parse_dataset_arg

    if (out is None) == (into is None):
        raise SuiteError("give exactly one of --out DIR (a new run) and --into RUN (an existing run)")
    if not PLANNER_NAME.match(planner):
        raise SuiteError(f"--planner {planner!r}: use 1-64 letters, digits, '_', '.', '+' or '-'")
    name, tier = parse_dataset_arg(dataset)
    ds = load_dataset(dataset, time_limit_s=time_limit_s)
    label = f"{name}:{tier}"
    lines = read_results(results, known=set(ds.ids), dataset=label,
                         elsewhere=lambda pid: tier != "all" and pid in load_dataset(name).ids)
    run_dir = Path(out if out is not None else into)
    if out is not None:
        if (run_dir / TRIALS_FILE).exists():
            raise SuiteError(f"--out {str(run_dir)!r} already holds a run; use --into to add to it, or another --out")
    else:
        _check_into(run_dir, name=name, tier=tier, planner=planner)
    records = judge_results(lines, ds, planner=planner)
    provenance = {"planner": planner, "results_file": str(results), "results_sha256": _sha256(results),
                  "lines": len(lines), "dataset": {"name": name, "tier": tier, "hash": ds.hash},
                  "time_limit_s": time_limit_s,
                  "imported_utc": dt.datetime.now(dt.UTC).isoformat(timespec="seconds")}
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
        if out is not None:
            _write_manifest(run_dir, provenance, argv=argv or [])
            mode = "w"
        else:
            _add_to_manifest(run_dir, provenance)
            mode = "a"
        with open(run_dir / TRIALS_FILE, mode) as f:
            f.write("".join(json.dumps(r.to_json()) + "\n" for r in records))
            f.flush()
            os.fsync(f.fileno())
    except OSError as exc:
        raise SuiteError(f"cannot write the run {str(run_dir)!r}: {exc.strerror}") from None
    statuses: dict[str, int] = {}
    for r in records:
        statuses[r.status] = statuses.get(r.status, 0) + 1
    over = sum(1 for r in records if (r.stats or {}).get("over_budget"))
    return run_dir, ImportCounts(planner, len(records), statuses, over)


def _sha256(path: str | Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:20]


def _check_into(run_dir: Path, *, name: str, tier: str, planner: str) -> None:
    """An existing run on the same dataset and tier that has no records of this planner yet."""
    from suite.run.records import read_manifest, read_trials

    if not (run_dir / TRIALS_FILE).is_file():
        raise SuiteError(f"--into {str(run_dir)!r} holds no {TRIALS_FILE}; use --out for a new run")
    run_ds = read_manifest(run_dir).get("dataset") or {}
    if run_ds.get("name") != name or run_ds.get("tier", "all") != tier:
        where = f"{run_ds['name']}:{run_ds.get('tier', 'all')}" if run_ds.get("name") else "generated scenes"
        raise SuiteError(f"--into {str(run_dir)!r} is a run on {where!r}, not on {name}:{tier}; import with "
                         f"--dataset {where} or into another run")
    if any(r.planner == planner for r in read_trials(run_dir)):
        raise SuiteError(f"--into {str(run_dir)!r} already has records of planner {planner!r}; import under another "
                         "--planner name")


def _write_manifest(run_dir: Path, provenance: dict[str, Any], *, argv: list[str]) -> None:
    from suite.run.executors import cpu_description
    from suite.run.manifest import git_commit, versions

    ds = provenance["dataset"]
    manifest = {
        "command": " ".join(["python -m suite", *argv]),
        "config": {"planners": [provenance["planner"]], "dataset": f"{ds['name']}:{ds['tier']}",
                   "time_limit_s": provenance["time_limit_s"], "seed": 0},
        "dataset": ds,
        "imports": [provenance],
        "versions": versions(),
        "git_commit": git_commit(),
        "machine": cpu_description(),  # where the paths were judged; each record keeps its planner's hardware
        "started_utc": provenance["imported_utc"],
    }
    (run_dir / MANIFEST_FILE).write_text(json.dumps(manifest, indent=2) + "\n")


def _add_to_manifest(run_dir: Path, provenance: dict[str, Any]) -> None:
    """Record the import in an existing run's manifest (a new `imports` list; nothing else changes)."""
    path = run_dir / MANIFEST_FILE
    manifest = json.loads(path.read_text()) if path.is_file() else {}
    manifest.setdefault("imports", []).append(provenance)
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(manifest, indent=2) + "\n")
    os.replace(tmp, path)
