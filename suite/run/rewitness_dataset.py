"""`python -m suite dataset rewitness NAME`: the witness rule applied to a dataset built before it.

A build keeps a non-trivial problem only if its witness keeps MIN_WITNESS_CLEARANCE_M from the
scene, after a finer padded search when the first one did not (`suite.run.witnesses.
witness_with_margin`). This command applies the same rule to a dataset that was built without it:
each benchmark witness under the minimum is searched again; a better one replaces it; a problem
still under the minimum leaves the benchmark and its tiers (`benchmark: false`; its record stays
as a cycle step, so that its scene can still be executed). The manifest records the command, what
changed and the new hash. The dataset is rewritten in place: run it only on a dataset not yet
shipped (a shipped one stays frozen; `dataset recertify` makes revisions of those).
"""

from __future__ import annotations

import time
from typing import Any

from scenes.errors import SuiteError
from suite.problems.dataset import PROBLEMS_FILE, SCENES_FILE, _read_jsonl, dataset_dir, read_manifest
from suite.problems.stored import dataset_hash, problem_from_record, record_hash, scene_from_record


def rewitness_dataset(name: str, *, argv: list[str]) -> dict[str, Any]:
    """Apply the witness rule to dataset `name` in place; returns its new manifest."""
    from suite.run.build_dataset import write_dataset_files
    from suite.run.references import clearance_summary
    from suite.run.lock import LOCK_FILE, RunLock
    from suite.run.manifest import git_commit
    from suite.run.witnesses import MIN_WITNESS_CLEARANCE_M, witness_with_margin

    out = dataset_dir(name)
    manifest = read_manifest(out)
    if "rewitnessed" in manifest:
        raise SuiteError(f"dataset {name!r} was already rewitnessed ({manifest['rewitnessed']['command']})")
    t0 = time.perf_counter()
    scene_rows = _read_jsonl(out / SCENES_FILE)
    scenes = {rec["scene_key"]: scene_from_record(rec) for _, _, rec in scene_rows}
    records = [rec for _, _, rec in _read_jsonl(out / PROBLEMS_FILE)]
    replaced, dropped = [], []
    for i, rec in enumerate(records):
        w = rec.get("witness")
        if not rec.get("benchmark", True) or rec.get("trivial") or w is None or w["clearance_min_m"] >= MIN_WITNESS_CLEARANCE_M:
            continue
        problem = problem_from_record(rec, scenes[rec["scene_key"]], time_limit_s=1.0)
        new, _ = witness_with_margin(problem, w)
        rec = {**{k: v for k, v in rec.items() if k != "record_hash"}, "witness": new}
        if new["clearance_min_m"] >= MIN_WITNESS_CLEARANCE_M:
            replaced.append({"problem_id": rec["problem_id"], "old_m": w["clearance_min_m"],
                             "new_m": new["clearance_min_m"], "padding_m": new["padding_m"]})
        else:
            rec["benchmark"] = False
            dropped.append({"problem_id": rec["problem_id"], "family": rec["family"], "kind": rec["kind"],
                            "clearance_m": new["clearance_min_m"]})
        rec["record_hash"] = record_hash(rec)
        records[i] = rec
    gone = {d["problem_id"] for d in dropped}
    scene_lines = [line for _, line, _ in scene_rows]
    counts = dict(manifest["counts"])
    counts["problems"] = sum(1 for r in records if r.get("benchmark", True))
    counts["trivial"] = sum(1 for r in records if r.get("benchmark", True) and r.get("trivial"))
    counts["cycle_steps_stored"] = sum(1 for r in records if not r.get("benchmark", True))
    counts["no_margin_dropped"] = counts.get("no_margin_dropped", 0) + len(gone)
    new_manifest = {
        **manifest,
        "hash": dataset_hash(scene_lines, records),
        "counts": counts,
        "tiers": {t: [pid for pid in ids if pid not in gone] for t, ids in manifest.get("tiers", {}).items()},
        "witness_clearance_m": clearance_summary([r["witness"]["clearance_min_m"] for r in records
                                                   if r.get("benchmark", True) and not r.get("trivial")]),
        "rewitnessed": {"command": " ".join(["python -m suite", *argv]), "git_commit": git_commit(),
                        "hash_before": manifest["hash"], "min_clearance_m": MIN_WITNESS_CLEARANCE_M,
                        "replaced": replaced, "dropped": dropped, "total_s": round(time.perf_counter() - t0, 1)},
    }
    with RunLock(out, what="dataset rewitness"):
        write_dataset_files(out, scene_lines, records, new_manifest)
        (out / LOCK_FILE).unlink(missing_ok=True)
    return new_manifest
