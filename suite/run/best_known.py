"""Best known paths from an offline search that no benchmarked run reproduces by construction.

`python -m suite dataset rereference --from NAME --name NEW` writes a revision of a frozen dataset
(the same scenes, problems, ids, splits, tiers and regions) whose every non-trivial reference comes
from this search alone:
1. AORRTC (asymptotically optimal RRT-Connect) for `search_s` seconds, and `rrt_starts`
   RRT-Connect runs with OMPL's full simplification, on the problem's python-fcl world with every
   obstacle grown by SEARCH_PADDING_M (1 mm), at 0.01 rad per joint; each path then validated and
   certified in the true world (the margin makes that almost sure);
2. two local optimizers started from each of those paths, shortest first (one more than
   POLISH_WITHIN times as long as the best so far is left; `local_optimum`):
   `suite.run.polish.polish`, a descent of path length that keeps every segment certified, and
   Drake's KinematicTrajectoryOptimization started from the path (`polish.seeded_trajopt`: the
   `trajopt` planner's program, its control points spread along the given path instead of its own
   straight or via-point guess; once with 10 and once with 16 control points), each certified
   result descended again;
3. the shortest certified result.
No benchmarked planner's benchmark answer and no stored reference enters it (in recycle-v3, 288 of
413 best known paths were `trajopt`'s own answers read back). A trivial problem keeps its straight
certified segment. A problem the search does not solve keeps its stored reference, marked
`kept_from_source`, and is counted.

The search is journalled (`search.jsonl` beside the new dataset's files, one line a problem), so an
interrupted build resumes where it stopped.
"""

from __future__ import annotations

import json
import shutil
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from scenes.errors import SuiteError
from suite.problems.dataset import MANIFEST_FILE, PROBLEMS_FILE, SCENES_FILE, _read_jsonl, dataset_dir, read_manifest
from suite.problems.stored import dataset_hash, problem_from_record, record_hash, scene_from_record
from suite.run.polish import path_length, polish

JOURNAL_FILE = "search.jsonl"
#: The search plans with every obstacle grown by this much (m), then certifies in the true world.
SEARCH_PADDING_M = 0.001
#: A start is polished only if it is at most this many times as long as the best polished path so
#: far (the starts go shortest first): a local optimizer does not halve a path.
POLISH_WITHIN = 1.5
#: Budget (s) of the trajectory optimization started from a search path (`local_optimum`).
TRAJOPT_S = 5.0
#: Control points of the trajectory optimizations started from each path (one run per count).
TRAJOPT_CONTROL_POINTS = (10, 16)
REFINE_JOURNAL_FILE = "refine.jsonl"
#: Relative length difference under which two lengths are the same best known (0.1%).
EQUAL_TOLERANCE = 1e-3


def search_job(arg: tuple) -> dict[str, Any]:
    """The offline search of one problem (runs in a worker process): every start's length, what
    polishing made of it, and the shortest certified path."""
    from planners.registry import make_planner, planner_class
    from planners.worlds import collision_world, padded_worlds
    from scenes.collision.certify import certifier
    from suite.run.trial import make_config
    from suite.scoring.validate import validate_path

    problem, search_s, rrt_starts, polish_s = arg[:4]
    trajopt_s = arg[4] if len(arg) > 4 else TRAJOPT_S
    world = collision_world(problem)
    cert = certifier(world)
    # planned with the obstacles grown by SEARCH_PADDING_M (at full speed, with the planners' own
    # sample checks): paths a hair off the obstacles, which the exact check then certifies in the
    # true world, and which the local optimizer pulls tight again there
    attempts = [("aorrtc", {"simplifier": "rope+full", "simplify_time_s": 1.0}, search_s, 1)]
    attempts += [("rrt", {"simplifier": "rope+full", "simplify_time_s": 0.5, "resolution_rad": 0.01}, 5.0, 300 + k)
                 for k in range(rrt_starts)]
    starts, certified = [], []
    for name, cfg, budget, seed in attempts:
        t0 = time.perf_counter()
        planner = make_planner(name, make_config(planner_class(name), cfg))
        with padded_worlds(SEARCH_PADDING_M):
            result = planner.plan(problem.with_(time_limit_s=budget, seed=seed))
        entry: dict[str, Any] = {"planner": name, "seed": seed, "status": result.status.value,
                                 "plan_s": round(time.perf_counter() - t0, 3)}
        starts.append(entry)
        if result.path is None or validate_path(problem, result.path, world) is not None:
            continue
        path = np.asarray(result.path, float)
        entry["length_rad"] = round(path_length(path), 6)
        if cert.certify(path).verdict != "certified":
            entry["certification"] = "not certified"
            continue
        certified.append((path_length(path), len(starts) - 1, path))
    best = None
    for length, k, path in sorted(certified, key=lambda c: c[0]):
        entry, tag = starts[k], f"{starts[k]['planner']}:{starts[k]['seed']}"
        if best is not None and length > POLISH_WITHIN * best["length_rad"]:
            entry["polished"] = f"no: over {POLISH_WITHIN}x the best polished length"
            continue
        out, how = local_optimum(problem, path, world, cert, polish_s=polish_s, trajopt_s=trajopt_s)
        entry.update(how)
        if out is not None and (best is None or path_length(out) < best["length_rad"]):
            best = {"path": out.tolist(), "length_rad": path_length(out), "start": tag}
    return {"best": best, "starts": starts}


def local_optimum(problem, path: np.ndarray, world, cert, *, polish_s: float,
                  trajopt_s: float = TRAJOPT_S) -> tuple[np.ndarray | None, dict[str, Any]]:
    """The shortest certified path the local optimizers make of the certified `path`: the certified
    descent of `suite.run.polish.polish` from it, and Drake's trajectory optimization started
    from it (`seeded_trajopt`) and then descended too. Returns (path rounded to 12 digits, or None
    if nothing certified is left after rounding; what each step gave)."""
    from suite.run.polish import seeded_trajopt
    from suite.scoring.validate import validate_path

    def certified(Q) -> bool:
        return validate_path(problem, Q, world) is None and cert.certify(Q).verdict == "certified"

    how: dict[str, Any] = {}
    candidates = []
    p = polish(path, cert, time_s=polish_s)
    how.update(polished_rad=round(p.length_rad, 6), polish_s=round(p.time_s, 3), polish_rounds=p.rounds)
    candidates.append(p.path)
    for n in TRAJOPT_CONTROL_POINTS:
        t0 = time.perf_counter()
        r = seeded_trajopt(problem, path, time_s=trajopt_s, control_points=n)
        got: dict[str, Any] = {"status": r.status.value, "s": round(time.perf_counter() - t0, 3)}
        if r.path is not None:
            Q = np.asarray(r.path, float)
            got.update(rad=round(path_length(Q), 6), certified=certified(Q))
            if got["certified"]:
                q = polish(Q, cert, time_s=polish_s)
                got["polished_rad"] = round(q.length_rad, 6)
                candidates.append(q.path)
        how[f"trajopt_{n}"] = got
    best = None
    for Q in sorted(candidates, key=path_length):
        Q = np.asarray(Q, float).round(12)  # certified as it is stored
        if certified(Q):
            best = Q
            break
    if best is None and certified(np.asarray(path, float).round(12)):
        best = np.asarray(path, float).round(12)
    return best, how


def _read_journal(path: Path) -> dict[str, dict]:
    """problem_id -> its journalled result (a line cut short by an interruption is skipped)."""
    done = {}
    if path.exists():
        for line in path.read_text().splitlines():
            try:
                rec = json.loads(line)
            except json.JSONDecodeError:  # a line cut short by an interruption
                continue
            done[rec["problem_id"]] = rec
    return done


def _run_journalled(work: list, path: Path, done: dict[str, dict], failed, *, desc: str, jobs: int,
                    progress_bar: bool) -> None:
    """Run `work` (executor Jobs keyed by problem id) in worker processes, appending each result to
    the journal at `path` as it comes (a failed job's is `failed(outcome)`) and into `done`."""
    from tqdm import tqdm

    from suite.run.executors import LocalExecutor
    from suite.run.runner import worker_init

    bar = tqdm(total=len(work), desc=desc, unit="problem", disable=not progress_bar, file=sys.stderr)
    if work:
        ex = LocalExecutor(jobs=min(jobs, len(work)), init=worker_init)
        with open(path, "a") as journal:
            for outcome in ex.run(work):
                res = outcome.result if outcome.failure is None else failed(outcome)
                rec = {"problem_id": outcome.job.key, **res}
                journal.write(json.dumps(rec) + "\n")
                journal.flush()
                done[outcome.job.key] = rec
                bar.update(1)
    bar.close()


def _rewrite_journal(path: Path, done: dict[str, dict], strip) -> None:
    """The journal again, each record through `strip` (the paths are in the problems file now)."""
    path.write_text("\n".join(json.dumps(strip(r)) for r in done.values()) + "\n")


def _quantiles(values: np.ndarray) -> dict[str, float]:
    """min, p10, median, p90 and max of `values` to 4 digits ({} if there are none)."""
    return {k: round(float(np.quantile(values, q)), 4) for k, q in
            (("min", 0), ("p10", 0.1), ("median", 0.5), ("p90", 0.9), ("max", 1))} if len(values) else {}


def rereference_dataset(source: str, name: str, *, search_s: float = 20.0, rrt_starts: int = 3,
                        polish_s: float = 5.0, trajopt_s: float = TRAJOPT_S, jobs: int = 2, argv: list[str],
                        progress_bar: bool = True) -> dict[str, Any]:
    """Write dataset `name`: `source` with every non-trivial reference from the offline search.
    Returns its manifest."""
    from suite.run.build_dataset import write_dataset_files
    from suite.run.executors import Job
    from suite.run.lock import LOCK_FILE, RunLock
    from suite.run.manifest import git_commit, versions

    src, out = dataset_dir(source), dataset_dir(name)
    manifest = read_manifest(src)
    if (out / MANIFEST_FILE).exists():
        raise SuiteError(f"dataset {name!r} already exists at {out}; choose another --name")
    t0 = time.perf_counter()
    scene_rows = _read_jsonl(src / SCENES_FILE)
    scenes = {rec["scene_key"]: scene_from_record(rec) for _, _, rec in scene_rows}
    records = [rec for _, _, rec in _read_jsonl(src / PROBLEMS_FILE)]
    with RunLock(out, what="dataset rereference"):
        done = _read_journal(out / JOURNAL_FILE)
        todo = [rec for rec in records if rec.get("benchmark", True) and not rec.get("trivial")
                and rec["problem_id"] not in done]
        n_opt = len(TRAJOPT_CONTROL_POINTS)  # per start: a descent, and n_opt optimizations each descended
        per_start = (1 + n_opt) * polish_s + n_opt * trajopt_s + 5.0
        budget = search_s + 5.0 * rrt_starts + (1 + rrt_starts) * per_start + 30.0
        work = [Job(rec["problem_id"], search_job,
                    (problem_from_record(rec, scenes[rec["scene_key"]], time_limit_s=search_s), search_s, rrt_starts,
                     polish_s, trajopt_s), 3 * budget + 60, group=rec["scene_key"]) for rec in todo]
        _run_journalled(work, out / JOURNAL_FILE, done, lambda o: {
            "best": None, "starts": [], "failure": o.failure, "message": o.message},
            desc="offline search", jobs=jobs, progress_bar=progress_bar)

        kept, new_records, pairs = [], [], []
        for rec in records:
            pid = rec["problem_id"]
            found = done.get(pid)
            if found is None:  # trivial or outside the benchmark: as it is
                new_records.append(rec)
                continue
            old_len = float(rec["reference_length_rad"])
            rec = {k: v for k, v in rec.items() if k != "record_hash"}
            best = found.get("best")
            if best is None:
                kept.append(pid)
                rec["reference"] = {**rec["reference"], "kept_from_source": True}
            else:
                rec["reference"] = {"path": best["path"], "planner": "offline-search",
                                    "config": {"search_s": search_s, "rrt_starts": rrt_starts, "polish_s": polish_s,
                                               "start": best["start"]},
                                    "time_s": round(sum(s.get("plan_s", 0) + s.get("polish_s", 0)
                                                        for s in found["starts"]), 3),
                                    "replaces": {"planner": rec["reference"].get("planner"), "length_rad": old_len}}
                rec["reference_length_rad"] = float(best["length_rad"])
                pairs.append((pid, rec["family"], old_len, float(best["length_rad"]),
                              rec["reference"]["replaces"]["planner"]))
            rec["record_hash"] = record_hash(rec)
            new_records.append(rec)

        ratio = np.array([new / old for _, _, old, new, _ in pairs if old > 0])
        scene_lines = [line for _, line, _ in scene_rows]
        counts = dict(manifest.get("counts", {}))
        new_manifest = {
            **manifest,
            "name": name,
            "hash": dataset_hash(scene_lines, new_records),
            "counts": counts,
            "references_certified": True,
            "best_known_by": {"offline-search": len(pairs), **({"kept_from_source": len(kept)} if kept else {})},
            "revision_of": {"name": manifest.get("name", source), "hash": manifest["hash"]},
            "rereferenced": {
                "command": " ".join(["python -m suite", *argv]), "git_commit": git_commit(), "versions": versions(),
                "search_s": search_s, "rrt_starts": rrt_starts, "polish_s": polish_s, "trajopt_s": trajopt_s,
                "searched": len(pairs) + len(kept), "kept_from_source": sorted(kept),
                "new_over_old_length_quantiles": _quantiles(ratio),
                "shorter_than_source": int(np.sum(ratio < 1 - EQUAL_TOLERANCE)),
                "equal_to_source": int(np.sum(np.abs(ratio - 1) <= EQUAL_TOLERANCE)),
                "longer_than_source": int(np.sum(ratio > 1 + EQUAL_TOLERANCE)),
                "longer_than_source_by_old_planner": {
                    p: sum(1 for _, _, o, n, q in pairs if q == p and n > o * (1 + EQUAL_TOLERANCE))
                    for p in sorted({q for *_, q in pairs})},
                "total_s": round(time.perf_counter() - t0, 1),
            },
        }
        if (src / "regions").is_dir() and not (out / "regions").exists():
            shutil.copytree(src / "regions", out / "regions")  # same worlds, same regions
        write_dataset_files(out, scene_lines, new_records, new_manifest)
        # the journal keeps what each start gave; the paths are in the problems file now
        _rewrite_journal(out / JOURNAL_FILE, done, lambda r: {**r, "best": None if r.get("best") is None else
                                                              {k: v for k, v in r["best"].items() if k != "path"}})
        (out / LOCK_FILE).unlink(missing_ok=True)
    return new_manifest


def refine_job(arg: tuple) -> dict[str, Any]:
    """`local_optimum` from a problem's stored reference (runs in a worker process)."""
    from planners.worlds import collision_world
    from scenes.collision.certify import certifier

    problem, path, polish_s, trajopt_s = arg
    world = collision_world(problem)
    out, how = local_optimum(problem, np.asarray(path, float), world, certifier(world), polish_s=polish_s,
                             trajopt_s=trajopt_s)
    return {"path": None if out is None else out.tolist(), "how": how}


def refine_dataset(name: str, *, polish_s: float = 2.0, trajopt_s: float = TRAJOPT_S, jobs: int = 2,
                   argv: list[str], progress_bar: bool = True) -> dict[str, Any]:
    """Run the local optimizers again from every offline-search reference of dataset `name`, in
    place, keeping a result only if it is shorter and certified (a second pass after
    `rereference_dataset`, for a revision not yet shipped). Journalled in refine.jsonl."""
    from suite.run.build_dataset import write_dataset_files
    from suite.run.executors import Job
    from suite.run.lock import LOCK_FILE, RunLock
    from suite.run.manifest import git_commit

    out = dataset_dir(name)
    manifest = read_manifest(out)
    t0 = time.perf_counter()
    scene_rows = _read_jsonl(out / SCENES_FILE)
    scenes = {rec["scene_key"]: scene_from_record(rec) for _, _, rec in scene_rows}
    records = [rec for _, _, rec in _read_jsonl(out / PROBLEMS_FILE)]
    with RunLock(out, what="dataset refine"):
        journal_path = out / REFINE_JOURNAL_FILE
        done = _read_journal(journal_path)
        todo = [rec for rec in records if rec["reference"].get("planner") == "offline-search"
                and rec["problem_id"] not in done]
        work = [Job(rec["problem_id"], refine_job,
                    (problem_from_record(rec, scenes[rec["scene_key"]], time_limit_s=trajopt_s),
                     rec["reference"]["path"], polish_s, trajopt_s),
                    3 * (len(TRAJOPT_CONTROL_POINTS) * (trajopt_s + polish_s) + polish_s) + 60,
                    group=rec["scene_key"]) for rec in todo]
        _run_journalled(work, journal_path, done, lambda o: {"path": None, "how": {
            "failure": o.failure, "message": o.message}}, desc="refining", jobs=jobs, progress_bar=progress_bar)
        new_records, gains = [], []
        for rec in records:
            found = done.get(rec["problem_id"])
            if found is None or found.get("path") is None:
                new_records.append(rec)
                continue
            length = path_length(np.asarray(found["path"], float))
            if length < rec["reference_length_rad"] - 1e-9:
                gains.append(length / rec["reference_length_rad"])
                rec = {k: v for k, v in rec.items() if k != "record_hash"}
                rec["reference"] = {**rec["reference"], "path": found["path"],
                                    "config": {**rec["reference"]["config"], "refined": True}}
                rec["reference_length_rad"] = length
                rec["record_hash"] = record_hash(rec)
            new_records.append(rec)
        g = np.array(gains)
        scene_lines = [line for _, line, _ in scene_rows]
        manifest = {**manifest, "hash": dataset_hash(scene_lines, new_records), "refined": {
            "command": " ".join(["python -m suite", *argv]), "git_commit": git_commit(), "polish_s": polish_s,
            "trajopt_s": trajopt_s, "trajopt_control_points": list(TRAJOPT_CONTROL_POINTS), "tried": len(done),
            "shortened": len(gains), "new_over_old_length_quantiles": _quantiles(g),
            "total_s": round(time.perf_counter() - t0, 1)}}
        write_dataset_files(out, scene_lines, new_records, manifest)
        _rewrite_journal(journal_path, done, lambda r: {k: v for k, v in r.items() if k != "path"})
        (out / LOCK_FILE).unlink(missing_ok=True)
    return manifest
