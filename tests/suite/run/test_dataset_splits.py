"""Stratified tune split and balanced quick tier: the rules hold on drawn compositions and on the
shipped dataset's own, where the old rules broke them."""

from __future__ import annotations

import json

import numpy as np
import pytest

from suite.problems.dataset import dataset_dir
from suite.run.build_dataset import scene_counts
from suite.run.dataset_splits import (
    SceneCounts,
    balanced_tier,
    split_violations,
    stratified_tune_scenes,
    tier_violations,
)

KINDS = ("approach", "descend", "lift", "transit", "return")


def _drawn(rng, families=6, scenes=(6, 16)) -> list[SceneCounts]:
    out = []
    for f in range(families):
        hard = rng.dirichlet(np.ones(5))  # each family its own mix of hard kinds
        for k in range(rng.integers(*scenes)):
            nt = {kind: int(rng.poisson(4 * p)) for kind, p in zip(KINDS, hard)}
            out.append(SceneCounts(f"f{f}-s{k}", f"family{f}", sum(nt.values()) + int(rng.integers(0, 4)), nt))
    return out


@pytest.mark.parametrize("seed", range(20))
def test_the_split_rules_hold_on_drawn_compositions(seed):
    scenes = _drawn(np.random.default_rng(seed))
    tune = stratified_tune_scenes(scenes)
    assert tune <= {s.key for s in scenes}
    assert split_violations(scenes, tune) == [], seed
    assert stratified_tune_scenes(list(reversed(scenes))) == tune  # the order of the input does not matter


@pytest.mark.parametrize("seed", range(20))
def test_the_tier_rules_hold_on_drawn_compositions(seed):
    scenes = _drawn(np.random.default_rng(100 + seed), scenes=(8, 20))
    tune = stratified_tune_scenes(scenes)
    test = [s for s in scenes if s.key not in tune]
    keys = balanced_tier(test, target=100)
    assert len(set(keys)) == len(keys) and set(keys) <= {s.key for s in test}  # whole test scenes, once
    tier = [s for s in test if s.key in keys]
    assert sum(s.problems for s in tier) >= 80
    assert tier_violations(tier, test, min_nontrivial=0.0) == [], seed


def test_on_the_shipped_composition_the_new_rules_hold_where_the_old_broke():
    """recycle-v2.1's scenes: its every-5th split left shelf with 1 of 60 non-trivial problems in
    tune and its quick tier was 28% window; the stratified split and the balanced tier are not."""
    d = dataset_dir("recycle-v2.1")
    records = [json.loads(line) for line in (d / "problems.jsonl").read_text().splitlines()]
    scenes = scene_counts(records)
    old_tune = {r["scene_key"] for r in records if r["split"] == "tune"}
    assert any(v.startswith("shelf: tune holds 1 of 60") for v in split_violations(scenes, old_tune))
    tune = stratified_tune_scenes(scenes)
    assert split_violations(scenes, tune) == []
    test = [s for s in scenes if s.key not in tune]
    tier = [s for s in test if s.key in balanced_tier(test, target=100)]
    assert tier_violations(tier, test) == []
    old_quick = set(json.loads((d / "manifest.json").read_text())["tiers"]["quick"])
    old = [s for s in scenes if any(r["problem_id"] in old_quick for r in records if r["scene_key"] == s.key)]
    assert any("window holds 21 of 74" in v for v in tier_violations(old, [s for s in scenes if s.key not in old_tune]))


def test_the_default_dataset_ships_its_rules_read_from_its_files():
    """The default dataset, read from its files alone: the stratified split (no scene on both sides),
    the balanced quick tier of whole test scenes with 70% non-trivial problems, and witnesses with a
    margin (95% at 1 mm or more, none under 0.1 mm)."""
    from suite.problems import DEFAULT_DATASET

    d = dataset_dir(DEFAULT_DATASET)
    records = [json.loads(line) for line in (d / "problems.jsonl").read_text().splitlines()]
    bench = [r for r in records if r.get("benchmark", True)]
    sides = {}
    for r in bench:
        sides.setdefault(r["scene_key"], set()).add(r["split"])
    assert all(len(s) == 1 for s in sides.values())
    scenes = scene_counts(bench)
    tune = {k for k, s in sides.items() if s == {"tune"}}
    assert split_violations(scenes, tune) == []
    quick = set(json.loads((d / "manifest.json").read_text())["tiers"]["quick"])
    in_quick = {r["scene_key"] for r in bench if r["problem_id"] in quick}
    assert all(r["problem_id"] in quick for r in bench if r["scene_key"] in in_quick)  # whole scenes
    assert in_quick.isdisjoint(tune)
    tier = [s for s in scenes if s.key in in_quick]
    assert tier_violations(tier, [s for s in scenes if s.key not in tune]) == []
    quick_recs = [r for r in bench if r["problem_id"] in quick]
    assert sum(not r["trivial"] for r in quick_recs) >= 0.7 * len(quick_recs)
    clear = np.array([r["witness"]["clearance_min_m"] for r in bench if not r["trivial"]])
    assert clear.min() >= 1e-4 and np.mean(clear >= 1e-3) >= 0.95
