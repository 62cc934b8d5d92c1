"""Physics execution: plans run in a Drake simulation with contact; are the cans recycled?"""

import json
import math

import numpy as np
import pytest

from planners.registry import planner_class
from scenes.generate import generate_scene
from scenes.grasp_rule import truth_grasp
from scenes.spec import load_spec
from suite.execution.job_spec import ExecutionJob
from suite.execution.monitor import bin_region, where
from suite.execution.plan_loop import can_pose_from, open_loop, plan_cans
from suite.execution.simulate import execute_cycles
from suite.problems.cycle import build_problems
from suite.run.records import TrialRecord
from suite.run.trial import config_dict, make_config


def _one_can_scene(*, lying: bool, variant: str = "open"):
    spec = load_spec(variant=variant).with_can_count(1)
    for seed in range(100):
        scene = generate_scene(spec, seed=seed)
        if scene.cans[0].lying == lying:
            return scene
    raise AssertionError("no such scene in 100 seeds")


def _execute(scene, grasps, planner="rrt"):
    problems = build_problems(scene, grasps, time_limit_s=5.0, seed=scene.seed)
    job = ExecutionJob(planner, config_dict(make_config(planner_class(planner), None)), scene, "truth", 5.0,
                       scene.seed)
    cans = plan_cans(problems, job)
    assert all(not failed for _, _, failed in cans), cans
    return execute_cycles(scene, open_loop(cans), q_home=problems[0].q_start, planner=planner)


@pytest.mark.parametrize("lying", [False, True])
def test_one_can_end_to_end_lands_in_the_bin(lying):
    scene = _one_can_scene(lying=lying)
    out = _execute(scene, [truth_grasp(scene, scene.cans[0])])
    assert out.cans_attempted == 1 and out.stopped == ""
    assert out.cans_in_bin == 1, out.to_json()
    assert out.cans[0].where == "bin" and out.clear_time_s is not None
    assert 0 < out.clear_time_s < out.sim_time_s
    # The arm follows its command closely and the can does not move in the closed gripper.
    assert out.peak_tracking_error_rad < 0.05
    assert out.peak_slip_m < 0.01
    lo, hi = bin_region(scene.spec)
    assert np.all(np.array(out.cans[0].p_WC_m) > lo) and np.all(np.array(out.cans[0].p_WC_m) < hi)
    json.dumps(out.to_json())  # the record is plain JSON


def test_a_grasp_3cm_off_the_can_is_reported_not_recycled():
    scene = _one_can_scene(lying=False)
    good = truth_grasp(scene, scene.cans[0])
    # 3 cm along the gripper's z axis (across both the approach and the closing direction): the
    # fingers close on the rim of the can instead of across its diameter.
    bad_X = good.X_WG.copy()
    bad_X[:3, 3] += 0.03 * good.X_WG[:3, 2]
    bad_pre = good.X_WGpre.copy()
    bad_pre[:3, 3] += 0.03 * good.X_WG[:3, 2]
    bad = type(good)(good.can_id, bad_X, bad_pre, good.lying)
    out = _execute(scene, [bad])
    assert out.cans_attempted == 1
    assert out.cans_in_bin == 0
    assert out.cans[0].where in ("plate", "elsewhere")
    assert out.clear_time_s is None


def test_where_classifies_bin_plate_and_elsewhere():
    spec = load_spec(variant="open")
    lo, hi = bin_region(spec)
    assert where(spec, (lo + hi) / 2) == "bin"
    assert where(spec, np.array([*spec.plate.center_m[:2], spec.plate_top_z_m + 0.03])) == "plate"
    assert where(spec, np.array([-0.5, -0.5, 0.03])) == "elsewhere"
    above_bin = (lo + hi) / 2
    above_bin[2] = hi[2] + 0.2  # still in the gripper over the bin
    assert where(spec, above_bin) == "elsewhere"


def test_can_pose_from_a_simulated_pose():
    X = np.eye(4)
    X[:3, 3] = [0.6, -0.1, 0.081]
    assert not can_pose_from(3, X).lying
    c, s = math.cos(0.4), math.sin(0.4)
    # axis along (c, s, 0): lying with that yaw
    R = np.array([[0, -s, c], [0, c, s], [-1, 0, 0.0]])
    X[:3, :3] = R
    pose = can_pose_from(3, X)
    assert pose.lying and pose.id == 3
    assert abs(pose.axis_yaw_rad - 0.4) < 1e-9


def _scene_with_a_moved_can():
    """A 2-can scene and the same scene with can 1 moved 10 cm (on the plate, clear of can 0)."""
    import dataclasses

    spec = load_spec(variant="open").with_can_count(2)
    plate_c, half = np.array(spec.plate.center_m[:2]), np.array(spec.plate.size_m[:2]) / 2 - 0.07
    for seed in range(30):
        believed = generate_scene(spec, seed=seed)
        a, b = believed.cans
        for angle in np.linspace(0, 2 * np.pi, 16, endpoint=False):
            xy = np.array(b.p_WC_m[:2]) + 0.10 * np.array([np.cos(angle), np.sin(angle)])
            if np.all(np.abs(xy - plate_c) <= half) and np.linalg.norm(xy - np.array(a.p_WC_m[:2])) > 0.14:
                moved = dataclasses.replace(b, p_WC_m=(float(xy[0]), float(xy[1]), b.p_WC_m[2]))
                return believed, dataclasses.replace(believed, cans=(a, moved))
    raise AssertionError("no scene with room to move a can")


def test_reperceive_picks_a_moved_can_from_where_it_really_is():
    """The plan was made for where the can was; the can has since moved 10 cm. Open loop grasps at
    the old place and misses it; closed loop (perceive after each pick) recycles it."""
    from suite.execution.job_spec import ExecutionJob
    from suite.execution.jobs import run_execution

    believed, actual = _scene_with_a_moved_can()
    config = config_dict(make_config(planner_class("rrt"), None))
    problems = build_problems(believed, [truth_grasp(believed, c) for c in believed.cans], time_limit_s=5.0,
                              seed=believed.seed)
    job = ExecutionJob("rrt", config, believed, "perceived", 5.0, believed.seed)
    stale = execute_cycles(actual, open_loop(plan_cans(problems, job)), q_home=problems[0].q_start,
                           planner="rrt")
    assert stale.cans[0].where == "bin"
    assert stale.cans[1].where != "bin"

    closed = run_execution(ExecutionJob("rrt", config, actual, "perceived", 5.0, actual.seed, reperceive=True))
    assert closed.cans_in_bin == 2, closed
    # planned in the world the cameras saw, rebuilt after the pick; judged and simulated in the truth
    assert closed.worlds == {"planned": "perceived", "judged": "truth", "physics": "truth"}
    # the loop ends on what the cameras see: a last look finds the plate empty
    assert [w["cans"] for w in closed.perceived_worlds] == [2, 1, 0]
    assert closed.stopped == ""
    assert closed.perception_induced == []


def _cli(*args):
    import subprocess
    import sys

    return subprocess.run([sys.executable, "-m", "suite", *args], capture_output=True, text=True)


def test_execute_command_writes_the_record_and_a_self_contained_replay(tmp_path):
    import re

    out = tmp_path / "run"
    r = _cli("execute", "--planner", "rrt", "--seed", "0", "--cans", "1", "--variant", "open", "--out", str(out))
    assert r.returncode == 0, r.stderr
    assert "in bin 1/1" in r.stdout
    (rec,) = json.loads((out / "execution.json").read_text())["executions"]
    assert rec["planner"] == "rrt" and rec["cans_in_bin"] == 1 and rec["replay"] == "replay_rrt.html"
    html = (out / "replay_rrt.html").read_text()
    assert html.lstrip().startswith("<!DOCTYPE html>")
    # Self-contained: no script or stylesheet fetched from anywhere.
    assert not re.search(r"<script[^>]+src=", html) and not re.search(r"<link[^>]+href=\"http", html)
    import base64

    commands = [base64.b64decode(b) for b in re.findall(r'data:application/octet-binary;base64,([A-Za-z0-9+/=]+)', html)]
    assert any(b"set_animation" in c for c in commands)  # the recorded motion, embedded


def test_execute_command_rejects_bad_input_in_one_line(tmp_path):
    r = _cli("execute", "--planner", "nope", "--out", str(tmp_path / "x"))
    assert r.returncode == 2 and "nope" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    r = _cli("execute", "--planner", "rrt", "--cans", "-1", "--out", str(tmp_path / "x"))
    assert r.returncode == 2 and "-1" in r.stderr
    blocker = tmp_path / "file"
    blocker.write_text("keep me")
    r = _cli("execute", "--planner", "rrt", "--cans", "1", "--out", str(blocker / "sub"))
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert blocker.read_text() == "keep me"


def test_dataset_execution_picks_cans_whose_steps_are_all_outside_the_benchmark():
    # open seed 1 of recycle-v1:quick: only the lifts of cans 0-2 are benchmark problems; every step of
    # cans 3 and 4 is a trivial step stored outside the benchmark. They must be picked all the same.
    from suite.execution.jobs import jobs_from_records
    from suite.problems.dataset import load_dataset
    from suite.run.trial import TrialSpec

    ds = load_dataset("recycle-v1:quick")
    mine = [p for p in ds.problems if (p.scene.variant, p.scene.seed) == ("open", 1)]
    key = mine[0].scene.key()
    assert {p.can_id for p in mine} < set(ds.picking_orders[key])  # some cans have no benchmark problem
    trials = [TrialSpec(f"t{i}", "rrt", {}, p) for i, p in enumerate(mine)]
    records = [TrialRecord(planner="rrt", status="success", problem=t.problem.kind, scene_seed=1, variant="open",
                           can_id=t.problem.can_id, trial_id=t.trial_id,
                           path=[list(t.problem.q_start), list(t.problem.q_goal)], q_start=list(t.problem.q_start))
               for t in trials]
    (job,) = jobs_from_records(trials, records, grasps="truth", time_limit_s=5.0, seed=0, reperceive=False,
                               replay_dir=None, cycle_steps=ds.cycle_steps, picking_orders=ds.picking_orders)
    assert [c for c, _, _ in job.cans] == list(ds.picking_orders[key]) == [0, 1, 2, 3, 4]
    paths = {c: p for c, p, _ in job.cans}
    assert all(path is not None for path in paths[3])  # can 3: five stored trivial steps, all executable
    (failed_4,) = [f for c, _, f in job.cans if c == 4]
    assert failed_4 == "return not in the dataset"  # its last return is stored once, under another scene


def test_a_can_flung_off_the_table_comes_to_rest_and_the_simulation_stays_finite():
    """The moving bin's 'non-finite pose' error: a can struck off the table fell for ever, its spin
    growing in the discrete solver until its pose overflowed. It now rests on the room's floor."""
    from pydrake.math import RigidTransform
    from pydrake.multibody.math import SpatialVelocity

    from suite.execution.commands import CommandStream
    from suite.execution.config import ExecutionConfig
    from suite.execution.monitor import Monitor
    from suite.execution.plant import build_simulation

    scene = generate_scene(load_spec(variant="open"), seed=3)
    config = ExecutionConfig()
    q_home = np.zeros(7)
    stream = CommandStream(q_home=q_home, open_width_m=scene.spec.grasp.open_width_m, config=config)
    stream.append_hold("wait", None, 8.0, width_from_m=scene.spec.grasp.open_width_m, carrying=False)
    sim = build_simulation(scene, stream, q_home=q_home, config=config)
    monitor = Monitor(sim, scene, stream, lambda: 0.0)
    can = monitor.can_bodies[scene.cans[0].id]
    x_edge = scene.spec.table.center_m[0] + scene.spec.table.size_m[0] / 2
    sim.plant.SetFreeBodyPose(sim.pc, can, RigidTransform([x_edge + 0.3, 0.0, 0.2]))
    sim.plant.SetFreeBodySpatialVelocity(sim.pc, can, SpatialVelocity(w=[30.0, 45.0, 10.0], v=[2.4, -0.5, 1.0]))
    sim.simulator.Initialize()
    for k in range(1, 401):  # 8 s, as the monitor checks it
        sim.simulator.AdvanceTo(k * 0.02)
        monitor.check(sim.root, full=True)
    p = sim.plant.EvalBodyPoseInWorld(sim.pc, can).translation()
    assert np.all(np.isfinite(p)) and p[2] < -0.3
    assert np.linalg.norm(sim.plant.EvalBodySpatialVelocityInWorld(sim.pc, can).get_coeffs()) < 1e-2  # at rest
    assert monitor.fates([])[0].where == "elsewhere"


def test_a_can_that_cannot_be_planned_is_skipped_and_the_rest_planned_around_it():
    """An unreachable grasp between two real ones: with `skip` the can after it is posed again (the
    first can gone) and the run goes on; with `stop` nothing after it is planned."""
    from suite.execution.plan_loop import plan_open_loop

    spec = load_spec(variant="open").with_can_count(2)
    scene = generate_scene(spec, seed=11)
    first, second = (truth_grasp(scene, c) for c in scene.cans)
    far = first.X_WG.copy()
    far[:3, 3] += [2.0, 0.0, 0.0]  # out of the arm's reach: no goal IK
    bad = type(first)(99, far, far, False)
    cfg = config_dict(make_config(planner_class("rrt"), None))
    for policy, n in (("skip", 3), ("stop", 2)):
        job = ExecutionJob("rrt", cfg, scene, "truth", 5.0, scene.seed, on_failure=policy)
        planned, q_home = plan_open_loop(scene, [first, bad, second], None, job, [], [])
        assert len(planned) == n and np.all(np.isfinite(q_home))
        assert not planned[0][2] and "ik_failed" in planned[1][2]
    assert planned[0][0] == scene.cans[0].id
    job = ExecutionJob("rrt", cfg, scene, "truth", 5.0, scene.seed)
    planned, _ = plan_open_loop(scene, [first, bad, second], None, job, [], [])
    assert planned[2][0] == scene.cans[1].id and not planned[2][2]
    provide = open_loop(planned, skip=True)
    got = [provide(None) for _ in range(3)]
    assert [c.can_id for c, _ in got[:2]] == [scene.cans[0].id, scene.cans[1].id]
    assert got[2][0] is None and got[2][1].startswith(f"skipped can {planned[1][0]}: ")


def test_an_unknown_failure_policy_is_refused():
    from scenes.errors import SuiteError

    scene = generate_scene(load_spec(variant="open").with_can_count(1), seed=1)
    with pytest.raises(SuiteError, match="on-failure policy 'retry'; allowed: skip, stop"):
        ExecutionJob("rrt", {}, scene, "truth", 5.0, 1, on_failure="retry")


def test_a_skip_plans_and_counts_each_can_once(monkeypatch):
    """After a failure the later cans are planned once, in the rebuilt problems only: every planning
    time (and perception-induced record) belongs to a problem tried once."""
    import suite.execution.plan_loop as loop
    from suite.execution.plan_loop import plan_open_loop

    scene = generate_scene(load_spec(variant="open").with_can_count(2), seed=11)
    first, second = (truth_grasp(scene, c) for c in scene.cans)
    far = first.X_WG.copy()
    far[:3, 3] += [2.0, 0.0, 0.0]
    bad = type(first)(99, far, far, False)
    planned_kinds = []
    real = loop.plan_cans

    def counting(problems, job, induced=None, planning_s=None):
        planned_kinds.extend((p.can_id, p.kind) for p in problems)
        return real(problems, job, induced, planning_s)

    monkeypatch.setattr(loop, "plan_cans", counting)
    job = ExecutionJob("rrt", config_dict(make_config(planner_class("rrt"), None)), scene, "truth", 5.0, scene.seed)
    times: list[float] = []
    planned, _ = plan_open_loop(scene, [first, bad, second], None, job, [], times)
    assert len(planned) == 3
    assert len(planned_kinds) == len(set(planned_kinds)) == 15  # each can's five problems, once
    assert len(times) == len(planned_kinds)  # one planning time per problem tried
