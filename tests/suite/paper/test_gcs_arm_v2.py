"""gcs-arm-v2: the paper's tasks as free transits in its world without the stand-in plate, beside the
first revision gcs-arm (the same tasks, posed as `transit`s of cans 0-9 in the world with the plate
buried in the table)."""

from __future__ import annotations

import json

import numpy as np

from suite.problems.dataset import PROBLEMS_FILE, SCENES_FILE, dataset_dir


def _lines(name: str, file: str) -> list[dict]:
    return [json.loads(line) for line in (dataset_dir(name) / file).read_text().splitlines() if line.strip()]


def test_the_code_still_builds_the_stored_scene_and_tasks():
    from suite.paper.gcs_arm import DATASET, paper_scene, task_problems

    assert DATASET == "gcs-arm-v2"
    (stored_scene,) = _lines(DATASET, SCENES_FILE)
    scene = paper_scene()
    assert scene.key() == stored_scene["scene_key"] and stored_scene["cans"] == []
    assert scene.spec.plate is None and scene.spec.bin is None and scene.spec.cans is None
    stored = _lines(DATASET, PROBLEMS_FILE)
    posed = task_problems(scene)
    assert [label for label, _ in posed] == [r["task"] for r in stored]
    for (_, p), r in zip(posed, stored):
        assert (p.kind, p.can_id, p.task_index) == (r["kind"], r["can_id"], r["task_index"]) == ("free", None, p.task_index)
        np.testing.assert_allclose(p.q_start, r["q_start"], atol=1e-7)
        np.testing.assert_allclose(p.q_goal, r["q_goal"], atol=1e-7)
    assert [p.task_index for _, p in posed] == list(range(10))


def test_the_revision_holds_the_first_ones_tasks_in_the_same_free_space():
    from scenes.collision.world import CollisionWorld
    from suite.problems.stored import scene_from_record

    old, new = _lines("gcs-arm", PROBLEMS_FILE), _lines("gcs-arm-v2", PROBLEMS_FILE)
    assert [r["task"] for r in old] == [r["task"] for r in new]
    assert [r["kind"] for r in old] == ["transit"] * 10 and [r["can_id"] for r in old] == list(range(10))
    assert [r["task_index"] for r in new] == list(range(10)) and {r["can_id"] for r in new} == {None}
    for a, b in zip(old, new):
        assert a["q_start"] == b["q_start"] and a["q_goal"] == b["q_goal"] and a["problem_id"] != b["problem_id"]
    worlds = [CollisionWorld(scene_from_record(_lines(name, SCENES_FILE)[0])) for name in ("gcs-arm", "gcs-arm-v2")]
    assert worlds[0].scene.spec.plate is not None and worlds[1].scene.spec.plate is None
    rng = np.random.default_rng(0)
    q = rng.uniform(worlds[0].robot.lower_rad, worlds[0].robot.upper_rad, size=(2000, 7))
    free = [w.states_free(q) for w in worlds]
    assert np.array_equal(free[0], free[1]) and 0.3 < free[0].mean() < 0.95


def test_compare_plans_the_free_transits_and_names_their_tasks(tmp_path):
    from suite.cli import main
    from suite.run.records import read_trials

    out = tmp_path / "run"
    assert main(["compare", "--dataset", "gcs-arm-v2:tasks", "--planners", "rrt,gcs", "--time-limit-s", "1",
                 "--out", str(out), "--no-progress", "--jobs", "2"]) == 0
    recs = read_trials(out)
    assert len(recs) == 10 and {r.problem for r in recs} == {"free"} and {r.can_id for r in recs} == {None}
    rrt = [r for r in recs if r.planner == "rrt"]
    assert sorted(r.task_index for r in rrt) == [0, 1, 2, 3, 4]
    assert len({r.trial_id for r in recs}) == 10 and len({r.seed for r in rrt}) == 5
    # the regions shipped with the dataset: never built inside a trial
    caches = [r.stats.get("regions_cache") for r in recs if r.planner == "gcs"]
    assert set(caches) <= {"hit", None} and "hit" in caches
    page = (out / "report.html").read_text()
    assert "task 0" in page
