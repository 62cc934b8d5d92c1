"""report.html from a run's saved files: its tables, one drill-down per problem, the drawing data,
self-containment, older records, and the command's one-line errors."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from synthetic_runs import synthetic_records, write_dataset_run, write_run

from scenes.errors import SuiteError
from scenes.robot_model import load_robot
from suite.cli import main
from suite.report.html import REPORT_FILE, write_html
from suite.report.html.problems import thin
from suite.run.records import TrialRecord, problem_key


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    records = synthetic_records(seeds=(3,), variants=("open", "wall"), cans=1)
    records[0] = records[0].with_(status="no_solution", path=None, metrics={},
                                  stats={"reason": "knot 7 (t=12): IK failed (kIterationLimit)"})
    run_dir = write_run(tmp_path_factory.mktemp("run"), records)
    page = write_html(run_dir).read_text(encoding="utf-8")
    return run_dir, records, page


def _data(page: str) -> dict:
    m = re.search(r'<script type="application/json" id="report-data">(.*?)</script>', page, re.S)
    return json.loads(m.group(1))


def test_page_holds_the_tables_and_one_drilldown_per_problem(run):
    _, records, page = run
    problems = {problem_key(r) for r in records}
    assert len(problems) == 10  # 2 families x 1 can x 5 motions
    assert len(re.findall(r'<section class="drill" ', page)) == len(problems)
    assert len(re.findall(r'<tr data-pid="', page)) == len(problems)
    for header in ("success (95% CI)", "time to solve, failures at budget (s)", "Per scene family",
                   "By stated reason (trials)", "Run settings and provenance"):
        assert header in page
    for planner in ("ik", "rrt", "trajopt"):
        assert re.search(rf"<tr><th>{planner}</th><td>\d+/10 \(\d+%\)<span", page), planner
    # the planner's stated reason, numbers masked, counted once for ik
    assert re.search(r"<td>knot # \(t=#\): IK failed \(kIterationLimit\)</td><td class=num>1</td>", page)
    # as stated, in that problem's drill-down
    assert "knot 7 (t=12): IK failed (kIterationLimit)" in page


def test_each_successful_path_is_drawn_from_its_start_to_its_goal(run):
    _, records, page = run
    data = _data(page)
    robot = load_robot()
    assert set(data["planners"]) == {"ik", "rrt", "trajopt"} and len(data["problems"]) == 10
    drawn = 0
    for r in records:
        pid = "s{}-{}-c{}-{}".format(*problem_key(r))
        entry = data["problems"][pid]
        assert entry["scene"] is None  # synthetic scenes (check_reachable=False) cannot be generated again
        if r.status != "success":
            assert r.planner not in entry["paths"]
            continue
        g = np.reshape(entry["paths"][r.planner]["g"], (-1, 3)) / 1000
        q = np.asarray(r.path)
        assert np.allclose(g[0], robot.gripper_pose(q[0])[:3, 3], atol=0.001)
        assert np.allclose(g[-1], robot.gripper_pose(q[-1])[:3, 3], atol=0.001)
        joints = np.reshape(entry["paths"][r.planner]["q"], (-1, 7)) / 1000
        s = np.asarray(entry["paths"][r.planner]["s"]) / 1000
        assert np.allclose(joints[[0, -1]], q[[0, -1]], atol=0.001)
        assert s[-1] == pytest.approx(r.metrics["path_length_rad"], abs=0.002)
        drawn += 1
    assert drawn >= 20
    assert data["scenes"] == {} and "The scenes are not drawn" in page  # said, not made up


@pytest.fixture(scope="module")
def dataset_run(tmp_path_factory):
    run_dir, ds = write_dataset_run(tmp_path_factory.mktemp("dsrun"), "recycle-v2.1:quick:family=window")
    return run_dir, ds, _data(write_html(run_dir).read_text(encoding="utf-8"))


def test_dataset_problems_are_drawn_in_their_own_world(dataset_run):
    _, ds, data = dataset_run
    assert set(data["problems"]) == set(ds.ids)
    held = 0
    for pid, p in zip(ds.ids, ds.problems):
        entry = data["problems"][pid]
        scene = data["scenes"][entry["scene"]]
        assert entry["scene"] == p.scene.key()
        assert {k for k, _, _ in scene["top"]} >= {"plate", "bin"}
        assert set(scene["cans"]) == {str(c.id) for c in p.scene.cans}
        gone = set(p.removed_can_ids) | ({p.held.can.id} if p.held else set())
        assert set(entry["removed"]) == gone  # recycled and held cans are not drawn on the plate
        assert ("held" in entry) == (p.held is not None)
        held += "held" in entry
        assert entry["paths"]["ref"]["g"] == entry["ref"]["g"]  # "ref" followed the reference exactly
        assert "stuck" not in entry["paths"]
    assert held > 0


def test_page_is_self_contained(run):
    _, _, page = run
    assert not re.search(r"""(src|href)\s*=\s*["']?(https?:)?//""", page)
    assert "<link" not in page and "@import" not in page
    assert page.count("<script") == 2  # the inline data and the inline code


def test_thin_keeps_a_polyline_within_tolerance():
    t = np.linspace(0, np.pi, 200)
    pts = np.column_stack([t, np.sin(t), np.zeros_like(t)])
    keep = thin(pts, 0.002)
    assert keep[0] == 0 and keep[-1] == 199 and 5 < len(keep) < 60
    kept = pts[keep]

    def distance(p):  # from a point to the thinned polyline
        a, b = kept[:-1], kept[1:]
        u = np.clip(np.einsum("ij,ij->i", p - a, b - a) / np.einsum("ij,ij->i", b - a, b - a), 0, 1)
        return np.min(np.linalg.norm(a + u[:, None] * (b - a) - p, axis=1))

    assert max(distance(p) for p in pts) <= 0.002 + 1e-9
    assert max(distance(p) for p in pts) > 0.0005  # it did thin


def test_older_records_without_newer_fields(tmp_path):
    records = synthetic_records(seeds=(0,), variants=("open",), cans=1, planners=("ik", "rrt"))
    older = ("problem_id", "certification", "attribution", "warm", "setup_time_s", "scene_key")
    # a run from before problem ids, certification, warm flags and setup times
    records = [TrialRecord.from_json({k: v for k, v in r.to_json().items() if k not in older}) for r in records]
    page = write_html(write_run(tmp_path, records, planners=("ik", "rrt"), cans=1)).read_text(encoding="utf-8")
    assert len(re.findall(r'<section class="drill" ', page)) == 5
    assert "not checked" in page  # the exact verdict of a success that never had one
    assert "Cold starts" not in page  # no warm flags: no table made up


def test_report_command_and_its_errors(run, tmp_path, capsys):
    run_dir, _, _ = run
    (run_dir / REPORT_FILE).unlink()
    assert main(["report", str(run_dir), "--no-plots"]) == 0
    assert str(run_dir / REPORT_FILE) in capsys.readouterr().out
    assert (run_dir / REPORT_FILE).stat().st_size > 10_000
    assert main(["report", str(tmp_path / "nowhere")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nowhere" in err[0] and "does not exist" in err[0]
    assert main(["report", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "holds no trials.jsonl" in err[0]


def test_replay_of_one_problem(dataset_run, tmp_path):
    from suite.report.replay import write_replay

    run_dir, ds, _ = dataset_run
    pid = ds.ids[0]
    replay = write_replay(run_dir, pid[:8], out=tmp_path / "r.html")  # a unique prefix will do
    start, end = replay.schedule["ref"]
    assert start == 0.0 and end > 0.1
    assert replay.schedule["stuck"] == "no path (timeout)"
    text = replay.path.read_text(encoding="utf-8")
    assert len(text) > 1_000_000 and "meshcat" in text  # its commands are embedded encoded
    with pytest.raises(SuiteError, match="no problem 'nothing'"):
        write_replay(run_dir, "nothing")
