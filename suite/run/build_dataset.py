"""Building a frozen dataset: scenes of every family -> distinct problems -> reference solutions -> files.

Steps:
1. For each family, scenes from consecutive seeds (`scenes.generate`), ground-truth grasps, the
   cycle's problems (`suite.problems.cycle`); problems whose goal has no IK solution are left out.
2. Identical problems (same content hash) are kept once. Each is checked for triviality (the
   straight joint segment passes the validator) and its difficulty measured.
3. Every problem gets a reference solution, the shortest valid path known: for a trivial problem
   the straight segment (no path is shorter) if it is certified; otherwise the best of a long
   AORRTC run and a few RRT-Connect runs, each shortened by OMPL's simplifier, accepted by the
   validator and certified by the exact check (`scenes.collision.certify`). A problem
   no planner solves is left out (the dataset holds known-solvable problems only).
4. Trivial problems are capped at `max_trivial_fraction` per family (those kept are chosen by
   hash, not by seed order); the others stay in the files as cycle steps (`benchmark: false`), not
   benchmark problems, so that a stored scene can still be executed in physics. Every `tune_every`-th scene of a family is in the `tune` split,
   the others in `test`. The `quick` tier takes whole scenes of every family's test split, in
   seed order, until it holds `quick_problems` problems.
"""

from __future__ import annotations

import collections
import dataclasses
import datetime as dt
import json
import logging
import sys
import time
from typing import Any

import numpy as np

from scenes.errors import SuiteError
from suite.problems.dataset import FORMAT_VERSION, MANIFEST_FILE, PROBLEMS_FILE, SCENES_FILE, dataset_dir
from suite.problems.stored import dataset_hash, problem_record, scene_record
from scenes.identity_rule import CURRENT_RULE
from suite.problems.identity import problem_id, straight_line
from suite.run.references import clearance_summary, plan_references, straight_certified
from suite.run.witnesses import MIN_WITNESS_CLEARANCE_M, choose_witness, witness_with_margin

log = logging.getLogger(__name__)

@dataclasses.dataclass(frozen=True)
class BuildSettings:
    """What `dataset build` makes.

    Attributes:
        name: the dataset's name (directory under scenes/datasets/).
        families: scene families (variants) to draw scenes from.
        scenes: scenes per family, from seeds `seed`, `seed` + 1, ...
        cans: cans per scene (None: the family's own count).
        seed: the first scene seed.
        reference_time_s: AORRTC's budget per non-trivial problem (s).
        rrt_runs: RRT-Connect runs (with full simplification) also tried per non-trivial problem.
        max_trivial_fraction: at most this fraction of a family's problems may be trivial.
        tune_every: every this-many-th scene of a family goes to the `tune` split.
        quick_problems: the `quick` tier's size (whole scenes, spread over the families).
        jobs: worker processes for the reference solutions.
        bin_warm_start: pose each cycle's bin goal from the previous cycle's first
            (`suite.problems.cycle.build_problems`); a manifest without this setting was built
            without it (`pose_settings`).
        split_rule: "stratified" (`dataset_splits.stratified_tune_scenes`: every family's tune
            share in [0.20, 0.35] of its non-trivial problems, every (family, kind) cell of 5 or
            more represented) or "every" (every `tune_every`-th scene of a family, as
            `recycle-v1` and `recycle-v2` were split; a manifest without this setting was).
        witness_paddings_m: obstacle paddings a witness with a margin is searched with, in turn
            (`witness_search`; empty: the reference is the witness).
        goal_clearance_m: the goal IK's least distance to the scene (`build_problems`; a manifest
            without this setting was posed at 0.001).
        reference_optimizers: optimizing planners also tried for the best known path, as tuned
            and seeded from the problem alone, `references.OPTIMIZER_BUDGET_S` each (`gcs` is not:
            its regions are built per world offline, which a build does not do).
        tier_rule: "balanced" (`dataset_splits.balanced_tier`: no family above 25% of the tier's
            non-trivial problems, every family with 20 or more non-trivial test problems at 8% or
            more) or "round-robin" (whole test scenes of every family in turn, as before).
    """

    name: str
    families: tuple[str, ...] = ("open", "wall", "station", "shelf", "window", "clutter")
    scenes: int = 12
    cans: int | None = 5
    seed: int = 0
    reference_time_s: float = 10.0
    rrt_runs: int = 3
    max_trivial_fraction: float = 0.3
    tune_every: int = 5
    quick_problems: int = 120
    jobs: int = 2
    bin_warm_start: bool = True
    split_rule: str = "stratified"
    tier_rule: str = "balanced"
    witness_paddings_m: tuple[float, ...] = (0.003, 0.0015)
    reference_optimizers: tuple[str, ...] = ("trajopt",)
    goal_clearance_m: float = 0.002


def pose_settings(manifest: dict[str, Any]) -> dict[str, Any]:
    """The `build_problems` keyword arguments a dataset's cycles were posed with (from its manifest),
    to pose them again identically; datasets built before a setting existed were built without it."""
    settings = manifest.get("build", {}).get("settings", {})
    return {"bin_warm_start": bool(settings.get("bin_warm_start", False)),
            "goal_clearance_m": float(settings.get("goal_clearance_m", 0.001))}


def family_spec(family: str, cans: int | None):
    """The spec a dataset build draws `family`'s scenes from: `cans` cans per scene (None: the
    spec's own count), except `clutter`, which draws its own."""
    from scenes.spec import load_spec

    spec = load_spec(variant=family)
    return spec.with_can_count(cans) if cans is not None and family != "clutter" else spec


def collect(settings: BuildSettings, *, progress=None) -> tuple[list, list[tuple[str, Any, dict]]]:
    """Scenes and their distinct, posable problems with trivial/difficulty/split filled in.

    Returns:
        (scene records, [(problem_id, problem, meta)]) in family and seed order.
    """
    from scenes.generate import generate_scene
    from scenes.grasp_rule import truth_grasp
    from suite.problems.cycle import build_problems

    scene_recs, out, seen = [], [], set()
    for family in settings.families:
        spec = family_spec(family, settings.cans)
        made, seed = 0, settings.seed
        while made < settings.scenes:
            if seed - settings.seed > 3 * settings.scenes + 10:
                raise SuiteError(f"{family}: only {made} of {settings.scenes} scenes could be built")
            try:
                scene = generate_scene(spec, seed=seed)
                problems = build_problems(scene, [truth_grasp(scene, c) for c in scene.cans],
                                          time_limit_s=1.0, seed=seed, bin_warm_start=settings.bin_warm_start,
                                          goal_clearance_m=settings.goal_clearance_m)
            except SuiteError as exc:
                log.info("%s seed %d skipped: %s", family, seed, exc)
                seed += 1
                continue
            split = "tune" if made % settings.tune_every == 0 else "test"  # `stratify` may redo it
            scene_recs.append(scene_record(scene, split=split))
            for p in problems:
                if p.pre_status is not None:
                    continue
                pid = problem_id(p)
                if pid in seen:
                    continue
                seen.add(pid)
                line = straight_line(p)
                meta = {"trivial": line.trivial, "difficulty": round(line.collision_fraction, 6),
                        "straight_length_rad": line.length_rad, "split": split}
                if line.trivial:  # the straight witness must be certified too; if not, one is planned
                    meta["straight_certified"] = straight_certified(p)
                out.append((pid, p, meta))
            made += 1
            seed += 1
            if progress is not None:
                progress(family, made)
    return scene_recs, out


def scene_counts(records: list[dict]) -> list:
    """`dataset_splits.SceneCounts` of every scene of some problem records (benchmark ones)."""
    from collections import Counter

    from suite.run.dataset_splits import SceneCounts

    by: dict[str, list[dict]] = {}
    for r in records:
        if r.get("benchmark", True):
            by.setdefault(r["scene_key"], []).append(r)
    return [SceneCounts(k, v[0]["family"], len(v), dict(Counter(r["kind"] for r in v if not r["trivial"])))
            for k, v in by.items()]


def stratify(scene_recs: list[dict], items: list) -> None:
    """Re-assign the split of every scene and problem by `stratified_tune_scenes` (in place)."""
    from suite.run.dataset_splits import stratified_tune_scenes

    recs = [{"scene_key": p.scene.key(), "family": p.scene.variant, "kind": p.kind, "trivial": m["trivial"]}
            for _, p, m in items]
    tune = stratified_tune_scenes(scene_counts(recs))
    for s in scene_recs:
        s["split"] = "tune" if s["scene_key"] in tune else "test"
    for _, p, m in items:
        m["split"] = "tune" if p.scene.key() in tune else "test"


def _references(items: list[tuple[Any, dict]], settings: BuildSettings, *, progress_bar: bool) -> dict[str, dict]:
    """Reference solutions of the non-trivial problems (and of the trivial ones whose straight
    segment is not certified)."""
    todo = [(pid, p) for pid, (p, m) in items if not m["trivial"] or not m.get("straight_certified", True)]
    return plan_references(todo, reference_time_s=settings.reference_time_s, rrt_runs=settings.rrt_runs,
                           paddings=tuple(settings.witness_paddings_m), jobs=settings.jobs, progress_bar=progress_bar,
                           optimizers=tuple(settings.reference_optimizers))


def _select(items: list[tuple[str, tuple[Any, dict]]], settings: BuildSettings) -> list[tuple[str, tuple[Any, dict]]]:
    """Cap each family's trivial problems at max_trivial_fraction (lowest hashes kept)."""
    keep = []
    families = sorted({p.scene.variant for _, (p, _) in items})
    f = settings.max_trivial_fraction
    for family in families:
        fam = [(pid, pm) for pid, pm in items if pm[0].scene.variant == family]
        hard = [x for x in fam if not x[1][1]["trivial"]]
        easy = sorted((x for x in fam if x[1][1]["trivial"]), key=lambda x: x[0])
        cap = int(np.floor(len(hard) * f / (1 - f))) if f < 1 else len(easy)
        chosen = {pid for pid, _ in easy[:cap]} | {pid for pid, _ in hard}
        keep += [x for x in fam if x[0] in chosen]
    return keep


def _quick_tier(records: list[dict], scene_recs: list[dict], settings: BuildSettings) -> list[str]:
    """Whole test-split scenes of every family, round robin in seed order, up to quick_problems."""
    by_scene: dict[str, list[str]] = {}
    for r in (r for r in records if r["benchmark"]):
        by_scene.setdefault(r["scene_key"], []).append(r["problem_id"])
    queues = {}
    for s in scene_recs:
        if s["split"] == "test" and by_scene.get(s["scene_key"]):
            queues.setdefault(s["family"], []).append(s["scene_key"])
    tier: list[str] = []
    while len(tier) < settings.quick_problems and any(queues.values()):
        for family in sorted(queues):
            if queues[family] and len(tier) < settings.quick_problems:
                tier += by_scene[queues[family].pop(0)]
    return tier


def build_dataset(settings: BuildSettings, *, argv: list[str], progress_bar: bool = True) -> dict[str, Any]:
    """Build and write the dataset (its directory locked meanwhile); returns its manifest."""

    from suite.run.lock import LOCK_FILE, RunLock

    out = dataset_dir(settings.name)
    if (out / MANIFEST_FILE).exists():
        raise SuiteError(f"dataset {settings.name!r} already exists at {out}; choose another --name")
    with RunLock(out, what="dataset build"):  # one build per dataset directory
        if (out / MANIFEST_FILE).exists():
            raise SuiteError(f"dataset {settings.name!r} already exists at {out}; choose another --name")
        manifest = _build_locked(settings, out, argv=argv, progress_bar=progress_bar)
        # the dataset now exists (a build that took the lock after us fails on its manifest), and
        # its directory is committed as data: no lock file left in it
        (out / LOCK_FILE).unlink(missing_ok=True)
        return manifest


def _build_locked(settings: BuildSettings, out, *, argv: list[str], progress_bar: bool) -> dict[str, Any]:
    from suite.run.manifest import git_commit, versions

    t0 = time.perf_counter()

    def say(family, made):
        if progress_bar:
            print(f"\r{family}: {made}/{settings.scenes} scenes", end="", file=sys.stderr, flush=True)

    scene_recs, items = collect(settings, progress=say)
    if settings.split_rule == "stratified":
        stratify(scene_recs, items)
    if progress_bar:
        print(file=sys.stderr)
    t_collect = time.perf_counter() - t0
    keyed = [(pid, (p, m)) for pid, p, m in items]
    refs = _references(keyed, settings, progress_bar=progress_bar)
    t_refs = time.perf_counter() - t0 - t_collect
    solved, unsolved, no_margin = [], [], []
    for pid, (p, m) in keyed:
        if m["trivial"] and m.get("straight_certified", True):
            # no path is shorter; stored with the exact stored configurations at its ends
            ref = {"path": [list(map(float, p.q_start)), list(map(float, p.q_goal))], "planner": "straight",
                   "config": {}, "time_s": 0.0}
        else:
            ref = refs.get(pid, {}).get("reference")
        if ref is None:
            unsolved.append(pid)
            continue
        witness, _ = witness_with_margin(p, choose_witness(p, ref, refs.get(pid, {}).get("witness")))
        if not m["trivial"] and witness["clearance_min_m"] < MIN_WITNESS_CLEARANCE_M:
            no_margin.append(pid)  # known solvable only to a checker's tolerance (suite.run.witnesses)
            continue
        m = {**m, "witness": witness}
        solved.append((pid, (p, {**m, "reference": {k: ref[k] for k in ("path", "planner", "config", "time_s")},
                                 "reference_length_rad": float(np.sum(np.linalg.norm(np.diff(np.asarray(ref["path"]), axis=0), axis=1)))})))
    chosen = _select(solved, settings)
    chosen_ids = {pid for pid, _ in chosen}
    # Trivial problems left out of the benchmark are kept as cycle steps (`benchmark: false`), so
    # that every stored scene can still be executed in physics cycle by cycle.
    records = [problem_record(p, {**m, "benchmark": pid in chosen_ids}, rule=CURRENT_RULE) for pid, (p, m) in solved]
    used_scenes = {r["scene_key"] for r in records if r["benchmark"]}
    records = [r for r in records if r["scene_key"] in used_scenes]
    scene_recs = [s for s in scene_recs if s["scene_key"] in used_scenes]
    scene_lines = [json.dumps(s, sort_keys=True) for s in scene_recs]
    if settings.tier_rule == "balanced":
        from suite.run.dataset_splits import balanced_tier

        test = [s for s in scene_counts(records) if s.key in {r["scene_key"] for r in scene_recs if r["split"] == "test"}]
        keys = balanced_tier(test, target=settings.quick_problems)
        quick = [r["problem_id"] for k in keys for r in records if r["scene_key"] == k and r["benchmark"]]
    else:
        quick = _quick_tier(records, scene_recs, settings)
    from suite.run.dataset_splits import split_violations, tier_violations

    counts_all = scene_counts(records)
    tune_keys = {r["scene_key"] for r in scene_recs if r["split"] == "tune"}
    in_quick = {r["scene_key"] for r in records if r["problem_id"] in set(quick)}
    rules = {"split": split_violations(counts_all, tune_keys),
             "quick": tier_violations([s for s in counts_all if s.key in in_quick],
                                      [s for s in counts_all if s.key not in tune_keys])}
    for what, broken in rules.items():
        for line in broken:
            log.warning("%s rule broken: %s", what, line)
    manifest = {
        "name": settings.name,
        "format_version": FORMAT_VERSION,
        "hash": dataset_hash(scene_lines, records),
        "identity_rule": CURRENT_RULE,
        "counts": {"scenes": len(scene_recs), "problems": sum(r["benchmark"] for r in records),
                   "trivial": sum(r["trivial"] and r["benchmark"] for r in records),
                   "cycle_steps_stored": sum(not r["benchmark"] for r in records),
                   "candidates": len(items), "unsolved_dropped": len(unsolved),
                   "no_margin_dropped": len(no_margin),
                   "trivial_dropped": len(solved) - len(chosen)},
        "references_certified": True,
        "witness_clearance_m": clearance_summary([r["witness"]["clearance_min_m"] for r in records
                                                   if r["benchmark"] and not r["trivial"]]),
        "best_known_by": dict(sorted(collections.Counter(
            r["reference"]["planner"] for r in records if r["benchmark"] and not r["trivial"]).items())),
        "rules_broken": rules,  # the split and tier rules (suite.run.dataset_splits) this build could not meet  # every reference passed the exact check (`dataset verify` enforces it)
        "tiers": {"quick": quick},
        "splits": ({"tune": f"every {settings.tune_every}th scene of each family (the first, then every {settings.tune_every}th)",
                    "test": "the other scenes"} if settings.split_rule == "every" else
                   {"tune": "whole scenes, per family 20-35% of its non-trivial problems and one of every (family, "
                            "kind) cell of 5 or more (suite.run.dataset_splits.stratified_tune_scenes)",
                    "test": "the other scenes"}),
        "build": {"command": " ".join(["python -m suite", *argv]), "settings": dataclasses.asdict(settings),
                  "versions": versions(), "git_commit": git_commit(),
                  "built_utc": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
                  "collect_s": round(t_collect, 1), "references_s": round(t_refs, 1)},
    }
    write_dataset_files(out, scene_lines, records, manifest)
    return manifest


def write_dataset_files(out, scene_lines: list[str], records: list[dict], manifest: dict[str, Any]) -> None:
    """Write a dataset's scenes, problems and manifest into directory `out` (created): each to a
    temporary file first, then renamed, the manifest last (a dataset without one does not exist)."""
    out.mkdir(parents=True, exist_ok=True)
    tmp = {}
    for fname, text in ((SCENES_FILE, "\n".join(scene_lines) + "\n"),
                        (PROBLEMS_FILE, "\n".join(json.dumps(r, sort_keys=True) for r in records) + "\n"),
                        (MANIFEST_FILE, json.dumps(manifest, indent=1) + "\n")):
        tmp[fname] = out / (fname + ".tmp")
        tmp[fname].write_text(text)
    for fname, path in tmp.items():
        path.replace(out / fname)
