"""The GCS paper's arm experiment: its poses by its IK recipe, and the exact GCS optimum by enumeration."""

from __future__ import annotations

import numpy as np
import pytest

from suite.paper.gcs_arm import TASK_POSES, _restriction_cost, region_paths, task_configurations


def test_the_task_poses_are_reached_by_the_papers_ik_recipe():
    from scenes.collision.world import CollisionWorld
    from scenes.robot_model import load_robot, rpy_to_matrix
    from suite.paper.gcs_arm import paper_scene

    scene = paper_scene()
    q = task_configurations(scene)
    robot = load_robot("iiwa14-spheres")
    world = CollisionWorld(scene)
    for name, (p, rpy) in TASK_POSES.items():
        X = robot.gripper_pose(q[name])
        np.testing.assert_allclose(X[:3, 3], p, atol=1e-6)
        R = X[:3, :3].T @ rpy_to_matrix(rpy)
        angle = np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))
        assert angle <= 1e-3 + 1e-6
        assert world.is_free(q[name])


def test_region_paths_are_every_simple_path():
    edges = [(0, 1), (1, 0), (1, 2), (2, 1), (0, 2), (2, 0), (2, 3), (3, 2)]
    paths = region_paths(edges, [0], [3])
    assert sorted(paths) == [[0, 1, 2, 3], [0, 2, 3]]


def test_the_restriction_is_the_shortest_path_through_its_regions():
    """An L-shaped corridor of two boxes in the plane: from s in the first to g in the second the
    shortest path bends at the inner corner (0.2, 0.2) of their overlap."""
    def box(lo, hi):
        A = np.vstack([np.eye(2), -np.eye(2)])
        return A, np.concatenate([hi, -np.asarray(lo)])

    (A0, b0), (A1, b1) = box([0, 0], [1, 0.2]), box([0, 0], [0.2, 1])
    s, g = np.array([1.0, 0.1]), np.array([0.1, 1.0])
    corner = np.array([0.2, 0.2])
    expected = np.linalg.norm(corner - s) + np.linalg.norm(g - corner)
    assert _restriction_cost([0, 1], s, g, [A0, A1], [b0, b1]) == pytest.approx(expected, rel=1e-5)
    # a single region holding both ends: the straight segment
    (A2, b2) = box([0, 0], [1, 1])
    assert _restriction_cost([0], s, g, [A2], [b2]) == pytest.approx(np.linalg.norm(g - s), rel=1e-9)


def test_compare_runs_the_gcs_arm_dataset_and_judges_it(tmp_path):
    """The paper's tasks are a dataset like any other: `compare` plans them, the validator and
    the certifier judge every path, and `gcs` loads the regions that ship with the dataset."""
    from suite.cli import main
    from suite.run.records import read_trials

    out = tmp_path / "run"
    assert main(["compare", "--dataset", "gcs-arm:tasks", "--planners", "rrt,gcs", "--out", str(out),
                 "--no-progress", "--jobs", "2"]) == 0
    recs = read_trials(out)
    assert len(recs) == 10 and {r.planner for r in recs} == {"rrt", "gcs"}
    assert {r.family for r in recs} == {"gcs-arm"}
    for r in recs:
        if r.status == "success":
            assert r.certification["verdict"] in ("certified", "collision", "unproved")
        else:
            assert r.reason_code
    gcs = [r for r in recs if r.planner == "gcs"]
    assert all(r.stats.get("regions_cache") in ("hit", None) for r in gcs)  # never built inside a trial
    assert sum(r.status == "success" for r in recs if r.planner == "rrt") >= 1


def test_finding_3_does_not_hold_where_an_optimum_collides():
    """Rounding optimal in every task is not the paper's finding when the 'optimum' collides in our
    world: a colliding path is not a solution."""
    from suite.paper.gcs_arm_report import PAPER, findings

    table = {t: {} for t in PAPER["lengths_rad"]}

    def opt(valid):
        return {"connected": True, "rounding_optimal": True, "linear_rounding_optimal": True, "relaxation_gap": 0.05,
                "linear_gap": 0.05, "rounded_path_valid": valid, "linear_path_valid": valid}

    optimality = {"paper": {t: opt(True) for t in table},
                  "ours": {t: opt(i != 0) for i, t in enumerate(table)}}
    third = findings(table, optimality, {})[2]
    held = {x["regions"]: x["held"] for x in third["by_regions"]}
    assert held == {"ours": False, "paper": True}


def test_a_protocol_run_writes_what_compare_writes_and_resumes(tmp_path):
    """`paper gcs-arm` runs its comparisons through the runner, not the command line: a run holds
    the files, settings and trials that `compare` writes for the same settings; run again, it is
    resumed (nothing planned twice); with other settings it is refused."""
    import json

    import yaml

    from scenes.errors import SuiteError
    from suite.cli import main
    from suite.paper.gcs_arm_protocol import PAPER_GCS, comparison_run
    from suite.run.records import read_trials

    settings = tmp_path / "config.yaml"
    settings.write_text(yaml.safe_dump({"planner_configs": {"gcs": dict(PAPER_GCS)}}))
    api, cli = tmp_path / "api", tmp_path / "cli"
    run = dict(settings=settings, planners=["rrt"], dataset="gcs-arm:tasks", jobs=1, time_limit_s=1.0, progress=False)
    comparison_run(api, seed=0, **run)
    assert main(["compare", "--dataset", "gcs-arm:tasks", "--planners", "rrt", "--seed", "0", "--jobs", "1",
                 "--time-limit-s", "1", "--config", str(settings), "--out", str(cli), "--no-progress"]) == 0

    def files(d):
        return sorted(str(p.relative_to(d)) for p in d.rglob("*") if p.is_file())

    assert files(api) == files(cli) and "report.html" in files(api) and "summary.md" in files(api)
    manifests = [json.loads((d / "manifest.json").read_text()) for d in (api, cli)]
    assert manifests[0].keys() == manifests[1].keys() and manifests[0]["config"] == manifests[1]["config"]
    assert manifests[0]["status"] == "complete" and manifests[0]["trials_recorded"] == 5
    assert sorted(r.trial_id for r in read_trials(api)) == sorted(r.trial_id for r in read_trials(cli))
    lines = (api / "trials.jsonl").read_text()
    comparison_run(api, seed=0, **run)  # resumed: every trial is recorded already
    assert (api / "trials.jsonl").read_text() == lines
    with pytest.raises(SuiteError, match="seed"):
        comparison_run(api, seed=1, **run)
