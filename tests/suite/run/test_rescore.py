"""`rescore`: a run's metrics recomputed from its stored paths reproduce a scoring of the same paths in
worlds built by hand; densified stored paths give the same values within 1%; records whose world
cannot be rebuilt keep their metrics and are counted; dataset runs take problems by problem_id."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from synthetic_runs import synthetic_records, write_run

from scenes.collision.world import CollisionWorld
from scenes.generate import generate_scene
from scenes.grasp_rule import truth_grasp, waypoint_pose
from scenes.identity_rule import CURRENT_RULE
from scenes.scene import HeldCan
from scenes.spec import load_spec
from suite.run.records import read_trials
from suite.scoring.metrics import score
from suite.run.rescore import rescore_run

#: Not a property of the path: the wall time of the timing computation.
NOT_OF_THE_PATH = {"timing_time_s"}


@pytest.fixture(scope="module")
def records():
    """The synthetic run's lines as plain JSON objects, as trials.jsonl holds them."""
    return [r.to_json() for r in synthetic_records(variants=("open",), cans=2)]


def hand_built(rec: dict) -> tuple[CollisionWorld, np.ndarray]:
    """The record's world and goal pose, built here the way `build_problems` poses the motion
    (truth grasps, cans picked in id order, every cycle of a synthetic run posable)."""
    spec = load_spec(variant=rec["variant"]).with_can_count(2)
    scene = generate_scene(spec, seed=rec["scene_seed"], check_reachable=False)
    can = scene.cans[rec["can_id"]]
    grasp = truth_grasp(scene, can)
    before = tuple(range(rec["can_id"]))
    kind = rec["problem"]
    held = HeldCan.from_grasp(can, grasp.X_WG) if kind in ("lift", "transit") else None
    opening = 2 * spec.can.radius_m if held is not None else spec.grasp.open_width_m
    removed = before + ((can.id,) if kind in ("transit", "return") else ())
    goal = {"approach": grasp.X_WGpre, "descend": grasp.X_WG, "lift": waypoint_pose(spec.waypoints.above_plate_m),
            "transit": waypoint_pose(spec.waypoints.above_bin_m),
            "return": waypoint_pose(spec.waypoints.above_plate_m)}[kind]
    return CollisionWorld(scene, gripper_opening_m=opening, held=held, removed_can_ids=removed), goal


def with_midpoints(path) -> list:
    path = np.asarray(path, float)
    out = np.empty((2 * len(path) - 1, 7))
    out[0::2], out[1::2] = path, 0.5 * (path[:-1] + path[1:])
    return out.tolist()


def assert_same_metrics(got: dict, want: dict, *, rel: float) -> None:
    assert set(got) == set(want)
    for name, value in want.items():
        if name in NOT_OF_THE_PATH:
            continue
        if value is None:
            assert got[name] is None, name
        else:
            assert got[name] == pytest.approx(value, rel=rel, abs=1e-9), name


def test_rescore_reproduces_the_metrics_and_is_invariant_to_densified_paths(tmp_path, records):
    run = write_run(tmp_path / "run", records, cans=2)
    from suite.report.write import write_report

    counts = rescore_run(run)
    table = write_report(run, plots=False)
    with_path = [r for r in records if r["path"]]
    assert counts.rescored == counts.with_path == len(with_path) and not counts.kept
    assert "rescored 24 of 24" in counts.line() and "ik" in table
    first = read_trials(run)
    assert [r.trial_id for r in first] == [r["trial_id"] for r in records]  # order and records kept
    assert not [p.name for p in run.iterdir() if p.name.endswith(".tmp")]
    assert (run / "summary.md").is_file()
    tilts = 0
    for old, new in zip(records, first):
        rescored = ("metrics", "certification")
        assert {k: v for k, v in new.to_json().items() if k not in rescored} == {k: v for k, v in old.items() if k not in rescored}
        if not old["path"]:
            assert new.metrics == {}
            continue
        assert new.certification["verdict"] in ("certified", "unproved", "collision")
        # The same metrics as scoring the stored path in a world built by hand.
        world, X_goal = hand_built(old)
        want = score(path=np.asarray(old["path"]), world=world, X_WG_goal=X_goal)
        assert_same_metrics(new.metrics, {k: (v if math.isfinite(v) else None) for k, v in want.items()}, rel=1e-9)
        assert new.metrics["path_length_rad"] == pytest.approx(old["metrics"]["path_length_rad"], rel=1e-12)
        carried_upright = world.held is not None and not world.held.can.lying
        assert (new.metrics["can_tilt_max_deg"] is not None) == carried_upright
        tilts += carried_upright
    assert tilts > 0  # some motions carry an upright can
    # A midpoint in every stored segment, rescored: the same values within 1%.
    dense = [{**r.to_json(), "path": with_midpoints(r.path)} if r.path else r.to_json() for r in first]
    write_run(run, dense, cans=2)
    rescore_run(run)
    for a, b in zip(first, read_trials(run)):
        assert_same_metrics(b.metrics, a.metrics, rel=0.01)


def test_records_whose_world_cannot_be_rebuilt_keep_their_metrics(tmp_path, records, capsys):
    from planners.base import PlanningProblem
    from suite.cli import main
    from suite.problems.identity import problem_id

    recs = [dict(r) for r in records]
    solved = [i for i, r in enumerate(recs) if r["path"]]
    recs[solved[0]]["scene_key"] = "0123456789abcdef"  # not the scene the seed gives
    recs[solved[1]]["problem_id"] = "f" * 20  # not the problem's content hash
    # A correct problem_id is accepted.
    good = recs[solved[2]]
    world, X_goal = hand_built(good)
    problem = PlanningProblem(kind=good["problem"], scene=world.scene, can_id=good["can_id"],
                              q_start=np.asarray(good["q_start"]), q_goal=np.asarray(good["q_goal"]),
                              X_WG_goal=X_goal, waypoints=(), held=world.held,
                              gripper_opening_m=world.gripper_opening_m, removed_can_ids=(), time_limit_s=1.0, seed=0)
    removed = tuple(range(good["can_id"])) + ((good["can_id"],) if good["problem"] in ("transit", "return") else ())
    good["problem_id"] = problem_id(problem.with_(removed_can_ids=removed))
    run = write_run(tmp_path / "run", recs, cans=2)
    assert main(["rescore", str(run), "--no-plots"]) == 0
    out = capsys.readouterr().out
    assert "rescored 22 of 24" in out and "2 kept their stored metrics" in out
    assert "regenerated scene differs from the run's" in out and "does not hash to its problem_id" in out
    after = read_trials(run)
    for i in solved[:2]:
        assert after[i].metrics == recs[i]["metrics"]  # kept as stored
    assert "turning_angle_rad" in after[solved[2]].metrics


def test_a_dataset_run_takes_problems_and_references_from_the_dataset(tmp_path, records):
    from planners.base import PlanningProblem
    from suite.problems.stored import dataset_hash, problem_record, scene_record

    rec = next(r for r in records if r["path"] and r["problem"] == "transit")
    world, X_goal = hand_built(rec)
    removed = tuple(range(rec["can_id"] + 1))
    problem = PlanningProblem(kind="transit", scene=world.scene, can_id=rec["can_id"],
                              q_start=np.asarray(rec["q_start"]), q_goal=np.asarray(rec["q_goal"]), X_WG_goal=X_goal,
                              waypoints=(), held=world.held, gripper_opening_m=world.gripper_opening_m,
                              removed_can_ids=removed, time_limit_s=1.0, seed=0)
    reference = np.array([rec["q_start"], rec["q_goal"]])
    length = float(np.linalg.norm(reference[1] - reference[0]))
    ds_dir = tmp_path / "ds"
    ds_dir.mkdir()
    scene_line = json.dumps(scene_record(world.scene, split="test"))
    prob = problem_record(problem, {"benchmark": True, "trivial": False, "difficulty": 0.1, "split": "test",
                                    "straight_length_rad": length, "reference_length_rad": length,
                                    "reference": {"path": reference.tolist()}}, rule=CURRENT_RULE)
    (ds_dir / "scenes.jsonl").write_text(scene_line + "\n")
    (ds_dir / "problems.jsonl").write_text(json.dumps(prob) + "\n")
    h = dataset_hash([scene_line], [prob])
    (ds_dir / "manifest.json").write_text(json.dumps({"format_version": 1, "hash": h, "tiers": {},
                                                      "identity_rule": CURRENT_RULE}))
    # The run's record names the problem by id and lacks the reference (it comes from the dataset);
    # a second record names a problem the dataset does not hold.
    mine = {**rec, "problem_id": prob["problem_id"]}
    stray = {**rec, "trial_id": "stray", "problem_id": "0" * 20}
    run = write_run(tmp_path / "run", [mine, stray], cans=2)
    manifest = json.loads((run / "manifest.json").read_text())
    manifest["dataset"] = {"name": str(ds_dir), "tier": "all", "hash": h}
    (run / "manifest.json").write_text(json.dumps(manifest))
    counts = rescore_run(run)
    assert counts.rescored == 1 and counts.kept == {"problem_id not in the dataset": 1}
    got = read_trials(run)[0].metrics
    want = score(path=np.asarray(rec["path"]), world=world, X_WG_goal=X_goal, reference_length_rad=length)
    assert got["length_ratio"] == pytest.approx(want["path_length_rad"] / length, rel=1e-12)
    assert got["length_ratio"] > 1.0
    assert_same_metrics(got, {k: (v if math.isfinite(v) else None) for k, v in want.items()}, rel=1e-9)
