"""Frozen datasets: build small, load, verify, run; and every bad input one line."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from scenes.errors import SuiteError
from scenes.identity_rule import CURRENT_RULE
from suite.problems.dataset import load_dataset, summary, verify_dataset
from suite.problems.identity import problem_id
from suite.run.build_dataset import BuildSettings, build_dataset

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """One `wall` scene of 2 cans: its transits and returns are non-trivial."""
    d = tmp_path_factory.mktemp("ds") / "small"
    settings = BuildSettings(name=str(d), families=("wall",), scenes=2, cans=2, seed=31, reference_time_s=1.0,
                             rrt_runs=1, tune_every=2, quick_problems=4, jobs=1)
    manifest = build_dataset(settings, argv=["dataset", "build"], progress_bar=False)
    return d, manifest


def _copy(d: Path, dest: Path) -> Path:
    """A copy of dataset directory d's files at dest, to edit."""
    dest.mkdir()
    for f in d.iterdir():
        (dest / f.name).write_text(f.read_text())
    return dest


def test_round_trip_same_problems_and_hashes(small):
    d, manifest = small
    ds = load_dataset(str(d))
    assert ds.hash == manifest["hash"] and len(ds.problems) == manifest["counts"]["problems"]
    assert manifest["identity_rule"] == CURRENT_RULE  # a new dataset's ids are made with the current rule
    assert len(set(ds.ids)) == len(ds.ids)
    for pid, p in zip(ds.ids, ds.problems):
        assert problem_id(p) == pid  # the loaded problem hashes to what was stored
        assert ds.meta[pid]["reference_length_rad"] >= ds.meta[pid]["straight_length_rad"] - 1e-9
    again = load_dataset(str(d))
    assert [problem_id(p) for p in again.problems] == list(ds.ids)


def test_trivial_cap_and_references(small):
    d, manifest = small
    info = summary(load_dataset(str(d)))
    assert info["trivial"] <= 0.3 / 0.7 * (info["problems"] - info["trivial"]) + 1e-9
    assert info["problems"] - info["trivial"] > 0
    ds = load_dataset(str(d))
    for pid in ds.ids:
        ref = ds.references[pid]
        assert ref.shape[1] == 7 and len(ref) >= 2
        if ds.meta[pid]["trivial"]:
            assert len(ref) == 2  # the straight segment is the reference: nothing is shorter


def test_quick_tier_is_a_subset_of_the_test_split(small):
    d, manifest = small
    quick = load_dataset(f"{d}:quick")
    assert 0 < len(quick.problems) <= len(load_dataset(str(d)).problems)
    assert {m["split"] for m in quick.meta.values()} == {"test"}


def test_verify_passes_then_catches_a_hand_edit(small, tmp_path):
    d, _ = small
    counts = verify_dataset(str(d))
    assert counts["problems"] > 0 and counts["identity_rule"] == CURRENT_RULE
    edited = _copy(d, tmp_path / "edited")
    lines = (edited / "problems.jsonl").read_text().splitlines()
    rec = json.loads(lines[1])
    rec["q_goal"][0] += 0.05  # a hand edit of one goal
    lines[1] = json.dumps(rec, sort_keys=True)
    (edited / "problems.jsonl").write_text("\n".join(lines) + "\n")
    with pytest.raises(SuiteError, match=rf"problem {rec['problem_id']} \(line 2\)"):
        verify_dataset(str(edited))


def test_a_manifest_with_an_unknown_identity_rule_is_one_line(small, tmp_path):
    d, _ = small
    edited = _copy(d, tmp_path / "rule")
    manifest = json.loads((edited / "manifest.json").read_text())
    (edited / "manifest.json").write_text(json.dumps({**manifest, "identity_rule": "round7"}))
    with pytest.raises(SuiteError, match=r"identity_rule.*round7.*round9-unsigned-zero"):
        load_dataset(str(edited))


def test_verify_rejects_a_colliding_reference(small, tmp_path):
    d, _ = small
    edited = _copy(d, tmp_path / "bad-ref")
    lines = (edited / "problems.jsonl").read_text().splitlines()
    k, rec = next((i, json.loads(line)) for i, line in enumerate(lines) if not json.loads(line)["trivial"])
    rec["reference"]["path"] = [rec["q_start"], rec["q_goal"]]  # the straight segment collides
    from suite.problems.stored import record_hash

    rec["reference_length_rad"] = float(np.linalg.norm(np.subtract(rec["q_goal"], rec["q_start"])))
    rec["record_hash"] = record_hash(rec)  # even with a re-computed record hash
    lines[k] = json.dumps(rec, sort_keys=True)
    (edited / "problems.jsonl").write_text("\n".join(lines) + "\n")
    with pytest.raises(SuiteError, match=r"reference rejected: collision"):
        verify_dataset(str(edited))


def test_unknown_dataset_and_tier_are_one_line(small):
    d, _ = small
    with pytest.raises(SuiteError, match=r"has no tier or split 'nope'; allowed: \['all', 'quick', 'test', 'tune'\]"):
        load_dataset(f"{d}:nope")
    with pytest.raises(SuiteError, match=r"no dataset at .*known datasets"):
        load_dataset("no-such-dataset")


def test_filters_keep_the_named_families_and_kinds(small):
    d, _ = small
    full = load_dataset(str(d))
    kinds = {m["kind"] for m in full.meta.values()}
    assert len(kinds) > 1
    kind = sorted(kinds)[0]
    sel = load_dataset(f"{d}:all:kind={kind}")
    assert list(sel.ids) == [pid for pid in full.ids if full.meta[pid]["kind"] == kind]
    both = load_dataset(f"{d}:all:family=wall,kind={'+'.join(sorted(kinds))}")
    assert both.ids == full.ids
    assert sel.picking_orders == full.picking_orders  # every stored cycle step still counts
    with pytest.raises(SuiteError, match=r"has no family 'window'; allowed: \['wall'\]"):
        load_dataset(f"{d}:all:family=window")
    with pytest.raises(SuiteError, match=r"dataset filter 'colour=red' .* FIELD one of family, kind"):
        load_dataset(f"{d}:test:colour=red")
    with pytest.raises(SuiteError, match=r"'family' given twice"):
        load_dataset(f"{d}:all:family=wall,family=wall")


def compare(*args):
    return subprocess.run([sys.executable, "-m", "suite", "compare", *args], capture_output=True, text=True,
                          cwd=ROOT, timeout=240)


def test_compare_runs_exactly_the_stored_problems(small, tmp_path):
    d, manifest = small
    out = tmp_path / "run"
    r = compare("--dataset", f"{d}:quick", "--planners", "rrt", "--time-limit-s", "2", "--out", str(out),
                "--no-plots", "--no-progress")
    assert r.returncode == 0, r.stderr
    records = [json.loads(line) for line in (out / "trials.jsonl").read_text().splitlines()]
    quick = load_dataset(f"{d}:quick")
    assert sorted(r["problem_id"] for r in records) == sorted(quick.ids)
    assert all(r["reference_length_rad"] == quick.meta[r["problem_id"]]["reference_length_rad"] for r in records)
    run_manifest = json.loads((out / "manifest.json").read_text())
    assert run_manifest["dataset"] == {"name": str(d), "tier": "quick", "hash": manifest["hash"]}


@pytest.mark.parametrize("flag", [["--variant", "wall"], ["--scenes", "2"], ["--cans", "1"], ["--grasps", "truth"]])
def test_dataset_with_a_generated_scene_flag_is_one_error_line(flag, tmp_path):
    r = compare("--dataset", "recycle-v1", *flag, "--out", str(tmp_path / "x"))
    assert r.returncode == 2 and r.stderr.count("\n") == 1
    assert f"{flag[0]} selects generated scenes" in r.stderr and not (tmp_path / "x").exists()


def test_built_references_are_certified_and_verify_requires_it(small):
    d, manifest = small
    assert manifest["references_certified"] is True
    counts = verify_dataset(str(d))
    assert counts["references_must_be_certified"] is True
    assert counts["references"] == {"certified": counts["problems"], "unproved": 0, "collision": 0}


def test_recertify_replaces_an_uncertified_reference_and_keeps_the_problems(small, tmp_path):
    from suite.run.recertify_dataset import recertify_dataset

    d, _ = small
    src = _copy(d, tmp_path / "src")
    lines = (src / "problems.jsonl").read_text().splitlines()
    k, rec = next((i, json.loads(line)) for i, line in enumerate(lines) if not json.loads(line)["trivial"])
    rec["reference"]["path"] = [rec["q_start"], rec["q_goal"]]  # collides: not certified
    lines[k] = json.dumps(rec, sort_keys=True)
    (src / "problems.jsonl").write_text("\n".join(lines) + "\n")
    out = tmp_path / "revised"
    manifest = recertify_dataset(str(src), str(out), reference_time_s=1.0, rrt_runs=1, jobs=1, argv=["test"],
                                 progress_bar=False)
    r = manifest["recertified"]
    assert r["source_verdicts"]["collision"] == 1 and r["replaced"] == 1 and r["dropped"] == []
    assert manifest["references_certified"] is True and manifest["revision_of"]["name"] == json.loads(
        (src / "manifest.json").read_text())["name"]
    counts = verify_dataset(str(out))  # every reference certified, hashes consistent
    assert counts["references"]["certified"] == counts["problems"]
    new = {json.loads(x)["problem_id"]: json.loads(x) for x in (out / "problems.jsonl").read_text().splitlines()}
    assert set(new) == {json.loads(x)["problem_id"] for x in lines}  # the same problems
    assert new[rec["problem_id"]]["reference"]["replaces"]["verdict"] == "collision"
    assert (src / "problems.jsonl").read_text().splitlines()[k] == lines[k]  # the source is untouched


def test_every_problem_stores_a_certified_witness_with_its_clearance(small):
    from planners.worlds import collision_world
    from suite.scoring.metrics import min_clearance_m

    d, manifest = small
    ds = load_dataset(str(d))
    assert set(ds.witnesses) == set(ds.ids)
    records = {json.loads(x)["problem_id"]: json.loads(x) for x in (d / "problems.jsonl").read_text().splitlines()}
    for pid, p in zip(ds.ids, ds.problems):
        w = records[pid]["witness"]
        world = collision_world(p)
        assert w["clearance_min_m"] == pytest.approx(min_clearance_m(world, ds.witnesses[pid]), abs=1e-12)
        assert 0.0 <= w["padding_m"] <= 0.003
        if w["padding_m"]:  # a margin path is kept only where it keeps farther off than the reference
            assert w["clearance_min_m"] > min_clearance_m(world, ds.references[pid])
    c = manifest["witness_clearance_m"]
    assert c["n"] == sum(not m["trivial"] for m in ds.meta.values()) and c["min"] <= c["median"]


def test_rereference_takes_every_best_known_from_the_offline_search_and_resumes(small, tmp_path):
    from suite.run.best_known import JOURNAL_FILE, rereference_dataset

    d, _ = small
    src_records = [json.loads(x) for x in (d / "problems.jsonl").read_text().splitlines()]
    hard = [r["problem_id"] for r in src_records if not r["trivial"]]
    out = tmp_path / "v-next"
    out.mkdir()
    # an interrupted search left one problem in the journal (not solved): it is not searched again
    (out / JOURNAL_FILE).write_text(json.dumps({"problem_id": hard[0], "best": None, "starts": []}) + "\n")
    manifest = rereference_dataset(str(d), str(out), search_s=0.5, rrt_starts=1, polish_s=0.5, trajopt_s=1.0,
                                   jobs=1, argv=["test"], progress_bar=False)
    r = manifest["rereferenced"]
    assert r["searched"] == len(hard) and r["kept_from_source"] == [hard[0]]
    counts = verify_dataset(str(out))  # every reference certified, hashes consistent
    assert counts["references"]["certified"] == counts["problems"]
    new = {json.loads(x)["problem_id"]: json.loads(x) for x in (out / "problems.jsonl").read_text().splitlines()}
    assert set(new) == {r["problem_id"] for r in src_records}  # the same problems and ids
    for pid in hard[1:]:
        ref = new[pid]["reference"]
        assert ref["planner"] == "offline-search" and ref["replaces"]["length_rad"] > 0
    assert new[hard[0]]["reference"]["kept_from_source"] is True
    journal = [json.loads(x) for x in (out / JOURNAL_FILE).read_text().splitlines()]
    assert {j["problem_id"] for j in journal} == set(hard) and all("path" not in (j["best"] or {}) for j in journal)
    with pytest.raises(SuiteError, match="already exists"):
        rereference_dataset(str(d), str(out), search_s=0.5, rrt_starts=1, polish_s=0.5, trajopt_s=1.0, jobs=1,
                            argv=["test"], progress_bar=False)
    # the second pass: from every offline-search path again, in place, only shorter certified ones kept
    from suite.run.best_known import REFINE_JOURNAL_FILE, refine_dataset

    before = {pid: r["reference_length_rad"] for pid, r in new.items()}
    m = refine_dataset(str(out), polish_s=0.3, trajopt_s=1.0, jobs=1, argv=["test"], progress_bar=False)
    assert m["refined"]["tried"] == len(hard) - 1  # the one kept from the source is not an offline-search path
    counts = verify_dataset(str(out))
    assert counts["references"]["certified"] == counts["problems"]
    after = {json.loads(x)["problem_id"]: json.loads(x) for x in (out / "problems.jsonl").read_text().splitlines()}
    assert all(after[pid]["reference_length_rad"] <= before[pid] for pid in before)
    assert len((out / REFINE_JOURNAL_FILE).read_text().splitlines()) == len(hard) - 1


def test_polish_never_lengthens_and_keeps_every_segment_certified(small):
    from planners.worlds import collision_world
    from scenes.collision.certify import certifier
    from suite.run.polish import path_length, polish

    d, _ = small
    ds = load_dataset(str(d))
    pid = next(pid for pid in ds.ids if not ds.meta[pid]["trivial"])
    world = collision_world(ds.problems[ds.ids.index(pid)])
    cert = certifier(world)
    # a raw RRT-Connect path (no shortcuts) with every motion certified: certified, with slack to take
    from planners.ompl_rrt import RRTConnectConfig
    from planners.registry import make_planner

    problem = ds.problems[ds.ids.index(pid)].with_(time_limit_s=60.0, seed=5)
    raw = make_planner("rrt", RRTConnectConfig(motion_check="certified", simplify_time_s=0.0,
                                               resolution_rad=0.01)).plan(problem)
    path = np.asarray(raw.path, float)
    assert cert.certify(path).verdict == "certified"
    p = polish(path, cert, time_s=2.0)
    assert p.length_rad < path_length(path) and p.length_before_rad == pytest.approx(path_length(path))
    assert np.array_equal(p.path[0], path[0]) and np.array_equal(p.path[-1], path[-1])
    assert cert.certify(p.path).verdict == "certified"
    lo, hi = world.robot.lower_rad, world.robot.upper_rad
    assert np.all(p.path >= lo - 1e-12) and np.all(p.path <= hi + 1e-12)
