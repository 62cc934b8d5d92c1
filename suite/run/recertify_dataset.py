"""A certified revision of a frozen dataset: the same problems, every reference certified.

`python -m suite dataset recertify --from NAME --name NEW` gives each benchmark reference of NAME
its exact verdict (`suite.scoring.validate.certify_path`). A reference that is not certified is
planned again as a build plans one (`suite.run.references.reference_job`: AORRTC and RRT-Connect runs,
shortened, validated, and accepted only if certified); the shortest certified path replaces it and
the old one is recorded beside it (`reference.replaces`). A problem none of them solves is left
out, and counted. Everything else (scenes, problems, splits, tiers, the build's settings, `gcs`'s
regions) is copied as it is; the source dataset is not touched.
"""

from __future__ import annotations

import shutil
import sys
import time
from typing import Any

import numpy as np

from scenes.errors import SuiteError
from suite.problems.dataset import MANIFEST_FILE, PROBLEMS_FILE, SCENES_FILE, _read_jsonl, dataset_dir, read_manifest
from suite.problems.stored import dataset_hash, problem_from_record, record_hash, scene_from_record


def _verdicts(records: list[dict], scenes: dict, *, progress_bar: bool) -> dict[str, dict]:
    """problem_id -> the certification record of its stored reference (benchmark problems)."""
    from tqdm import tqdm

    from planners.worlds import collision_world
    from suite.scoring.validate import certify_path

    out = {}
    bench = [r for r in records if r.get("benchmark", True)]
    for rec in tqdm(bench, desc="certifying references", unit="problem", disable=not progress_bar, file=sys.stderr):
        problem = problem_from_record(rec, scenes[rec["scene_key"]], time_limit_s=1.0)
        out[rec["problem_id"]] = certify_path(np.asarray(rec["reference"]["path"], float), collision_world(problem))
    return out


def recertify_dataset(source: str, name: str, *, reference_time_s: float = 10.0, rrt_runs: int = 3, jobs: int = 2,
                      argv: list[str], progress_bar: bool = True) -> dict[str, Any]:
    """Write dataset `name`: `source` with every benchmark reference certified. Returns its manifest."""
    from suite.run.build_dataset import write_dataset_files
    from suite.run.references import plan_references
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
    verdicts = _verdicts(records, scenes, progress_bar=progress_bar)
    todo = [(pid, problem_from_record(rec, scenes[rec["scene_key"]], time_limit_s=1.0))
            for rec in records if (pid := rec["problem_id"]) in verdicts and verdicts[pid]["verdict"] != "certified"]
    t_check = time.perf_counter() - t0
    planned = plan_references(todo, reference_time_s=reference_time_s, rrt_runs=rrt_runs, paddings=(), jobs=jobs,
                              progress_bar=progress_bar)
    dropped, replaced, new_records = [], [], []
    for rec in records:
        pid = rec["problem_id"]
        if pid not in planned:
            new_records.append(rec)
            continue
        ref = planned[pid].get("reference")
        if ref is None:
            dropped.append(pid)
            continue
        old = rec["reference"]
        cert = verdicts[pid]
        rec = {k: v for k, v in rec.items() if k != "record_hash"}
        rec["reference"] = {**{k: ref[k] for k in ("path", "planner", "config", "time_s")},
                            "replaces": {"planner": old.get("planner"), "length_rad": rec["reference_length_rad"],
                                         "verdict": cert["verdict"], "pair": cert.get("pair"),
                                         "penetration_m": cert.get("penetration_m")}}
        rec["reference_length_rad"] = float(np.sum(np.linalg.norm(np.diff(np.asarray(ref["path"]), axis=0), axis=1)))
        rec["record_hash"] = record_hash(rec)
        replaced.append((pid, rec["family"], rec["reference"]["replaces"]["length_rad"], rec["reference_length_rad"]))
        new_records.append(rec)
    gone = set(dropped)
    counts = dict(manifest.get("counts", {}))
    counts["problems"] = sum(1 for r in new_records if r.get("benchmark", True))
    counts["trivial"] = sum(1 for r in new_records if r.get("benchmark", True) and r.get("trivial"))
    scene_lines = [line for _, line, _ in scene_rows]
    tally = {v: sum(1 for c in verdicts.values() if c["verdict"] == v) for v in ("certified", "unproved", "collision")}
    ratio = [new / old for _, _, old, new in replaced if old > 0]
    new_manifest = {
        **manifest,
        "name": name,
        "hash": dataset_hash(scene_lines, new_records),
        "counts": counts,
        "references_certified": True,
        "tiers": {t: [pid for pid in ids if pid not in gone] for t, ids in manifest.get("tiers", {}).items()},
        "revision_of": {"name": manifest.get("name", source), "hash": manifest["hash"]},
        "recertified": {
            "command": " ".join(["python -m suite", *argv]), "git_commit": git_commit(), "versions": versions(),
            "source_verdicts": tally, "replaced": len(replaced), "dropped": sorted(dropped),
            "replaced_by_family": {f: sum(1 for _, fam, _, _ in replaced if fam == f)
                                   for f in sorted({fam for _, fam, _, _ in replaced})},
            "new_over_old_length_quantiles": dict(zip(("min", "median", "max"),
                                                      [round(float(np.quantile(ratio, q)), 4) for q in (0, 0.5, 1)]))
            if ratio else {},
            "reference_time_s": reference_time_s, "rrt_runs": rrt_runs,
            "check_s": round(t_check, 1), "total_s": round(time.perf_counter() - t0, 1),
        },
    }
    with RunLock(out, what="dataset recertify"):
        if (out / MANIFEST_FILE).exists():
            raise SuiteError(f"dataset {name!r} already exists at {out}; choose another --name")
        if (src / "regions").is_dir() and not (out / "regions").exists():
            shutil.copytree(src / "regions", out / "regions")  # same worlds, same regions
        write_dataset_files(out, scene_lines, new_records, new_manifest)
        (out / LOCK_FILE).unlink(missing_ok=True)
    return new_manifest
