"""Best known paths from an offline search that no benchmarked run reproduces by construction.

`python -m suite dataset rereference --from NAME --name NEW` writes a revision of a frozen dataset
(the same scenes, problems, ids, splits, tiers and regions) whose every non-trivial reference comes
from this search alone:
1. AORRTC (asymptotically optimal RRT-Connect) for `search_s` seconds, and `rrt_starts`
   RRT-Connect runs with OMPL's full simplification, on the problem's python-fcl world with every
   obstacle grown by SEARCH_PADDING_M (1 mm), at 0.01 rad per joint; each path then validated and
   certified in the true world (the margin makes that almost sure);
2. `suite.run.polish.polish`, a local optimizer of path length that keeps every segment
   certified, started from each of those paths, shortest first (one more than POLISH_WITHIN times
   as long as the best polished path is left);
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
from suite.problems.dataset import (
    MANIFEST_FILE,
    PROBLEMS_FILE,
    SCENES_FILE,
    _read_jsonl,
    dataset_dir,
    dataset_hash,
    problem_from_record,
    read_manifest,
    record_hash,
    scene_from_record,
)
from suite.run.polish import path_length, polish

JOURNAL_FILE = "search.jsonl"
#: The search plans with every obstacle grown by this much (m), then certifies in the true world.
SEARCH_PADDING_M = 0.001
#: A start is polished only if it is at most this many times as long as the best polished path so
#: far (the starts go shortest first): a local optimizer does not halve a path.
POLISH_WITHIN = 1.5
#: Relative length difference under which two lengths are the same best known (0.1%).
EQUAL_TOLERANCE = 1e-3


def search_job(arg: tuple) -> dict[str, Any]:
    """The offline search of one problem (runs in a worker process): every start's length, what
    polishing made of it, and the shortest certified path."""
    from planners.registry import make_planner, planner_class
    from planners.worlds import collision_world
    from scenes.fcl_certify import certifier
    from suite.run.trial import make_config
    from suite.scoring.validate import validate_path

    from planners.worlds import padded_worlds

    problem, search_s, rrt_starts, polish_s = arg
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
        p = polish(path, cert, time_s=polish_s)
        out = np.asarray(p.path, float).round(12)  # certified as it is stored
        ok = validate_path(problem, out, world) is None and cert.certify(out).verdict == "certified"
        entry.update(polished_rad=round(path_length(out), 6), polish_s=round(p.time_s, 3), polish_rounds=p.rounds,
                     polished_certified=ok)
        if not ok:  # rounding to 12 digits moved a waypoint onto a contact: keep the unpolished path
            out = path.round(12)
            if cert.certify(out).verdict != "certified":
                continue
        if best is None or path_length(out) < best["length_rad"]:
            best = {"path": out.tolist(), "length_rad": path_length(out), "start": tag}
    return {"best": best, "starts": starts}


def _journal(out: Path) -> dict[str, dict]:
    path = out / JOURNAL_FILE
    done = {}
    if path.exists():
        for line in path.read_text().splitlines():
            try:
                rec = json.loads(line)
            except json.JSONDecodeError:  # a line cut short by an interruption
                continue
            done[rec["problem_id"]] = rec
    return done


def rereference_dataset(source: str, name: str, *, search_s: float = 20.0, rrt_starts: int = 3,
                        polish_s: float = 5.0, jobs: int = 2, argv: list[str],
                        progress_bar: bool = True) -> dict[str, Any]:
    """Write dataset `name`: `source` with every non-trivial reference from the offline search.
    Returns its manifest."""
    from tqdm import tqdm

    from suite.run.build_dataset import write_dataset_files
    from suite.run.executors import Job, LocalExecutor
    from suite.run.lock import LOCK_FILE, RunLock
    from suite.run.runner import git_commit, versions, worker_init

    src, out = dataset_dir(source), dataset_dir(name)
    manifest = read_manifest(src)
    if (out / MANIFEST_FILE).exists():
        raise SuiteError(f"dataset {name!r} already exists at {out}; choose another --name")
    t0 = time.perf_counter()
    scene_rows = _read_jsonl(src / SCENES_FILE)
    scenes = {rec["scene_key"]: scene_from_record(rec) for _, _, rec in scene_rows}
    records = [rec for _, _, rec in _read_jsonl(src / PROBLEMS_FILE)]
    with RunLock(out, what="dataset rereference"):
        done = _journal(out)
        todo = [rec for rec in records if rec.get("benchmark", True) and not rec.get("trivial")
                and rec["problem_id"] not in done]
        budget = search_s + 5.0 * rrt_starts + (1 + rrt_starts) * (polish_s + 5.0) + 30.0
        work = [Job(rec["problem_id"], search_job,
                    (problem_from_record(rec, scenes[rec["scene_key"]], time_limit_s=search_s), search_s, rrt_starts,
                     polish_s), 3 * budget + 60, group=rec["scene_key"]) for rec in todo]
        bar = tqdm(total=len(work), desc="offline search", unit="problem", disable=not progress_bar, file=sys.stderr)
        if work:
            ex = LocalExecutor(jobs=min(jobs, len(work)), init=worker_init)
            with open(out / JOURNAL_FILE, "a") as journal:
                for outcome in ex.run(work):
                    res = (outcome.result if outcome.failure is None else
                           {"best": None, "starts": [], "failure": outcome.failure, "message": outcome.message})
                    rec = {"problem_id": outcome.job.key, **res}
                    journal.write(json.dumps(rec) + "\n")
                    journal.flush()
                    done[outcome.job.key] = rec
                    bar.update(1)
        bar.close()

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
                "search_s": search_s, "rrt_starts": rrt_starts, "polish_s": polish_s,
                "searched": len(pairs) + len(kept), "kept_from_source": sorted(kept),
                "new_over_old_length_quantiles": {k: round(float(np.quantile(ratio, q)), 4) for k, q in
                                                  (("min", 0), ("p10", 0.1), ("median", 0.5), ("p90", 0.9),
                                                   ("max", 1))} if len(ratio) else {},
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
        lines = [json.dumps({**r, "best": None if r.get("best") is None else
                             {k: v for k, v in r["best"].items() if k != "path"}}) for r in done.values()]
        (out / JOURNAL_FILE).write_text("\n".join(lines) + "\n")
        (out / LOCK_FILE).unlink(missing_ok=True)
    return new_manifest
