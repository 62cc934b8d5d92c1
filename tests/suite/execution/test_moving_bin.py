"""The moving bin: scenario checks, the bin's path and estimate, splices, and the replanning loop in physics."""

import subprocess
import sys

import numpy as np
import pytest

from scenes.errors import SuiteError
from scenes.generate import generate_scene
from scenes.moving_bin import PATH_DT_S, bin_path, make_scenario, region, spec_with_bin_at
from scenes.moving_bin_check import check_scenario
from scenes.spec import load_spec
from suite.execution.bin_estimate import BinEstimator


# --- scenario ------------------------------------------------------------------------------------


def test_bad_scenarios_are_one_clear_line():
    spec = load_spec(variant="wall")
    with pytest.raises(SuiteError, match="speed_m_s.*-0.1.*greater than or equal to 0"):
        make_scenario({"speed_m_s": -0.1})
    with pytest.raises(SuiteError, match="x_lo < x_hi"):
        make_scenario({"region_m": [[0.5, 0.4], [0.3, 0.6]]})
    with pytest.raises(SuiteError, match="run into the wall"):
        check_scenario(make_scenario({"region_m": [[0.3, 0.25], [0.4, 0.6]]}), spec, reach=False)
    with pytest.raises(SuiteError, match="hold the bin's place"):
        check_scenario(make_scenario({"region_m": [[1.0, 1.0], [1.2, 1.2]]}), spec, reach=False)
    with pytest.raises(SuiteError, match="out of the arm's reach"):
        check_scenario(make_scenario({"region_m": [[0.3, 0.45], [0.75, 0.6]]}), spec)
    with pytest.raises(SuiteError, match="open and wall families, not 'gcs-arm'"):
        check_scenario(make_scenario(), load_spec(variant="gcs-arm"), reach=False)


def test_the_default_scenario_runs_on_open_and_wall():
    for family in ("open", "wall"):
        check_scenario(make_scenario(), load_spec(variant=family))


def test_a_scenario_changes_no_scene_key():
    spec = load_spec(variant="open")
    scene = generate_scene(spec, seed=0)
    key = scene.key()
    moved = spec_with_bin_at(make_scenario(), spec, (0.40, 0.55))
    assert moved.bin.center_xy_m == (0.40, 0.55) and moved.extra[-1].name == "person"
    assert scene.key() == key and spec.bin.center_xy_m == (0.36, 0.52) and spec.extra == ()
    assert generate_scene(load_spec(variant="open"), seed=0).key() == key


# --- the bin's path and its estimate --------------------------------------------------------------


@pytest.mark.parametrize("speed", [0.0, 0.1, 0.4])
def test_bin_path_keeps_its_region_speed_and_acceleration(speed):
    spec = load_spec(variant="open")
    scenario = make_scenario({"speed_m_s": speed, "seed": 3})
    path = bin_path(scenario, spec, horizon_s=60.0)
    lo, hi = region(scenario, spec)
    assert np.all(path.xy_m >= lo - 1e-9) and np.all(path.xy_m <= hi + 1e-9)
    assert np.allclose(path.xy_m[0], spec.bin.center_xy_m)
    v = np.linalg.norm(path.v_m_s, axis=1)
    assert v.max() <= speed + 1e-9
    a = np.linalg.norm(np.diff(path.v_m_s, axis=0), axis=1) / PATH_DT_S
    assert a.max() <= scenario.accel_m_s2 + 1e-6
    # the positions are the integral of the velocities (to the sampling's error)
    assert np.max(np.abs(np.cumsum(path.v_m_s[:-1] * PATH_DT_S, axis=0) + path.xy_m[0] - path.xy_m[1:])) < 0.01
    if speed > 0:
        assert v.max() == pytest.approx(speed)  # it does cruise
        again = bin_path(scenario, spec, horizon_s=60.0)
        assert np.array_equal(again.xy_m, path.xy_m)  # seeded
    else:
        assert np.all(path.xy_m == path.xy_m[0])


def test_estimate_is_delayed_held_and_predicts_constant_velocity():
    spec = load_spec(variant="open")
    s = make_scenario({"speed_m_s": 0.1, "estimate_noise_m": 0.0, "estimate_latency_s": 0.2,
                       "estimate_rate_hz": 10.0, "velocity_window": 3})
    path = bin_path(s, spec)
    est = BinEstimator(s, path, spec)
    t = 3.05
    newest = est.estimates(t)[-1]
    assert newest[0] == pytest.approx(2.8)  # sampled at 2.8 s, available at 3.0 s: held until 3.1 s
    assert np.allclose(newest[1], path.at(2.8)[0])
    assert est.estimates(3.09)[-1][0] == newest[0]
    # on a straight stretch at cruise speed the prediction is exact
    cruising = [t for t in np.arange(1.0, 50.0, 0.1)
                if all(np.allclose(path.at(t - d)[1], path.at(t)[1]) for d in np.arange(0.0, 0.9, 0.1))
                and np.linalg.norm(path.at(t)[1]) > 0.099]
    t = cruising[0]
    assert np.allclose(est.predict(t, t), path.at(t)[0], atol=1e-6)


# --- splices --------------------------------------------------------------------------------------


def test_a_splice_is_continuous_in_position_and_velocity():
    from scenes.robot_model import load_robot
    from suite.execution.commands import CommandStream
    from suite.execution.config import ExecutionConfig
    from suite.execution.splice import stopping_blend
    from suite.scoring.timing import time_parameterize

    robot = load_robot()
    rng = np.random.default_rng(5)
    q_a = np.array([-0.3, 0.4, 0.1, -1.5, 0.2, 1.1, 0.3])
    current = time_parameterize(np.array([q_a, q_a + rng.uniform(-0.8, 0.8, 7)]), robot=robot)
    stream = CommandStream(q_home=q_a, open_width_m=0.1, config=ExecutionConfig())
    stream.append_motion("transit", 0, current, width_m=0.0, carrying=True)
    for t_s in np.linspace(0.05, current.duration_s - 0.05, 7):
        q_s, v_s, a_s = stream.state(t_s)
        blend = stopping_blend(q_s, v_s, a_s, v_lim=robot.velocity_limits_rad_s,
                               a_lim=robot.acceleration_limits_rad_s2, q_lo=robot.lower_rad, q_hi=robot.upper_rad)
        assert blend is not None and blend.duration_s > 0
        q_b = blend.q[-1]
        new = time_parameterize(np.array([q_b, q_b + rng.uniform(-0.5, 0.5, 7)]), robot=robot)
        spliced = CommandStream(q_home=q_a, open_width_m=0.1, config=ExecutionConfig())
        spliced.append_motion("transit", 0, current, width_m=0.0, carrying=True)
        spliced.cut(t_s, can_id=0, width_m=0.0, carrying=True)
        spliced.append_motion("blend", 0, blend, width_m=0.0, carrying=True)
        spliced.append_motion("transit", 0, new, width_m=0.0, carrying=True)
        # across the splice and where the blend hands over to the new plan, sampled 1 microsecond apart
        for t in (t_s, t_s + blend.duration_s):
            (q0, v0, _), (q1, v1, _) = spliced.state(t - 1e-6), spliced.state(t + 1e-6)
            assert np.max(np.abs(q1 - q0)) < 1e-4
            assert np.max(np.abs(v1 - v0)) < 1e-3 * (1 + np.max(robot.acceleration_limits_rad_s2))
        assert np.allclose(spliced.state(t_s)[:2], stream.state(t_s)[:2], atol=1e-12)
        # the blend stops within the limits, and the new plan starts at rest where it stops
        t = np.linspace(0, blend.duration_s, 200)
        _, v, a = blend.sample(t)
        assert np.all(np.abs(v) <= 1.01 * robot.velocity_limits_rad_s + 1e-9)
        assert np.all(np.abs(a) <= np.maximum(robot.acceleration_limits_rad_s2, np.abs(a_s)) + 1e-9)
        assert np.allclose(blend.sample(blend.duration_s)[1], 0, atol=1e-9)
        assert np.allclose(new.sample(0.0)[0], q_b) and np.allclose(new.sample(0.0)[1], 0)


def test_a_join_bends_the_motion_onto_the_new_path_without_stopping():
    """A drift replan's path from the commanded position at the splice, bending toward a goal
    that moved: the join is continuous in position and velocity at the splice and where the blend
    hands over to the path's timing (and matches the acceleration at both), never stops on the way (it keeps moving at the
    join), stays within the limits, and its polyline starts at the splice and ends at the goal."""
    from scenes.robot_model import load_robot
    from suite.execution.commands import CommandStream
    from suite.execution.config import ExecutionConfig
    from suite.execution.splice import join_path, stopping_blend
    from suite.scoring.timing import time_parameterize

    robot = load_robot()
    rng = np.random.default_rng(11)
    q_a = np.array([-0.3, 0.4, 0.1, -1.5, 0.2, 1.1, 0.3])
    current = time_parameterize(np.array([q_a, q_a + rng.uniform(-0.8, 0.8, 7)]), robot=robot)
    moving = 0
    for t_s in np.linspace(0.1, current.duration_s - 0.1, 12):
        q_s, v_s, a_s = current.sample(t_s)
        # a drift replan: the goal moved a little, the new path bends toward it
        goal = current.q[-1] + rng.uniform(-0.2, 0.2, 7)
        path = np.array([q_s, 0.5 * (q_s + goal) + rng.uniform(-0.1, 0.1, 7), goal])
        join = join_path(q_s, v_s, a_s, path, robot=robot)
        stop = stopping_blend(q_s, v_s, a_s, v_lim=robot.velocity_limits_rad_s, a_lim=robot.acceleration_limits_rad_s2,
                              q_lo=robot.lower_rad, q_hi=robot.upper_rad, max_duration_s=3.0)
        if stop is None:  # near a joint limit no stop is within the limits: then no join either
            assert join is None or not join.at_rest
            continue
        assert join is not None and join.blend.duration_s > 0
        assert np.allclose(join.polyline[0], q_s) and np.allclose(join.polyline[-1], goal)
        stream = CommandStream(q_home=q_a, open_width_m=0.1, config=ExecutionConfig())
        stream.append_motion("transit", 0, current, width_m=0.0, carrying=True)
        stream.cut(t_s, can_id=0, width_m=0.0, carrying=True)
        stream.append_motion("blend", 0, join.blend, width_m=0.0, carrying=True)
        stream.append_motion("transit", 0, join.trajectory, width_m=0.0, carrying=True)
        for t in (t_s, t_s + join.blend.duration_s):
            (q0, v0, _), (q1, v1, _) = stream.state(t - 1e-6), stream.state(t + 1e-6)
            assert np.max(np.abs(q1 - q0)) < 1e-4 and np.max(np.abs(v1 - v0)) < 1e-3 * 40
        # the blend matches the acceleration at both ends too (TOPP-RA's own is piecewise constant)
        assert np.allclose(join.blend.sample(0.0)[2], a_s, atol=1e-9)
        if not join.at_rest:
            assert np.allclose(join.blend.sample(join.blend.duration_s)[2], join.trajectory.sample(0.0)[2], atol=1e-6)
        t = np.linspace(0, join.blend.duration_s, 300)
        _, v, a = join.blend.sample(t)
        assert np.all(np.abs(v) <= 1.01 * robot.velocity_limits_rad_s + 1e-9)
        assert np.all(np.abs(a) <= np.maximum(robot.acceleration_limits_rad_s2, np.abs(a_s)) * 1.02 + 1e-9)
        if not join.at_rest:
            moving += 1
            assert np.min(np.linalg.norm(v, axis=1)) > 0.05  # the arm never stops in the join
            assert np.linalg.norm(join.trajectory.sample(0.0)[1]) > 0.05
    assert moving >= 8  # a stop at the join is the exception


def test_warm_start_guess_keeps_the_shape_and_moves_the_ends():
    from planners.base import warm_start_guess
    from suite.problems.cycle import build_problems
    from scenes.grasp_rule import truth_grasp

    scene = generate_scene(load_spec(variant="open").with_can_count(1), seed=0)
    (transit,) = [p for p in build_problems(scene, [truth_grasp(scene, scene.cans[0])], time_limit_s=2.0, seed=0)
                  if p.kind == "transit"]
    assert warm_start_guess(transit, 10) is None
    old = np.linspace(transit.q_start - 0.1, transit.q_goal + 0.05, 30)
    g = warm_start_guess(transit.with_(warm_start=old), 10)
    assert g.shape == (10, 7)
    assert np.array_equal(g[0], transit.q_start) and np.array_equal(g[-1], transit.q_goal)

    from planners.registry import planner_class
    from suite.run.trial import make_config

    cls = planner_class("trajopt")
    result = cls(make_config(cls, None)).plan(transit.with_(warm_start=old))
    assert result.status.value == "success" and result.stats["initial_guess"] == "warm_start"


# --- the loop in physics --------------------------------------------------------------------------


def _job(*, planner="rrt", cans=1, variant="open", seed=0, **scenario):
    from planners.registry import planner_class
    from suite.execution.moving_bin import plan_scene_job
    from suite.run.trial import config_dict, make_config

    scene = generate_scene(load_spec(variant=variant).with_can_count(cans), seed=seed)
    return plan_scene_job(scene, make_scenario(scenario), planner=planner,
                          planner_config=config_dict(make_config(planner_class(planner), None)), time_limit_s=5.0,
                          seed=seed)


def test_a_planner_tied_to_its_world_is_not_applicable():
    from suite.execution.moving_bin import MovingBinJob, run_moving_bin

    scene = generate_scene(load_spec(variant="open").with_can_count(1), seed=0)
    job = MovingBinJob("gcs", {}, scene, make_scenario(), (), (), 5.0, 0)
    rec = run_moving_bin(job)
    assert rec.status == "not_applicable" and "fixed world" in rec.reason and rec.to_json()["cans_in_bin"] == 0


@pytest.mark.slow
def test_a_static_bin_through_the_loop_reproduces_todays_execution():
    from planners.registry import planner_class
    from suite.execution.job_spec import ExecutionJob
    from suite.execution.plan_loop import open_loop
    from suite.execution.moving_bin import run_moving_bin
    from suite.execution.simulate import execute_cycles
    from suite.run.trial import config_dict, make_config

    # without speed-and-separation monitoring: its protective stops near the standing person would
    # (rightly) make the loop differ from the open-loop execution
    job = _job(cans=2, variant="wall", seed=3, speed_m_s=0.0, estimate_noise_m=0.0, ssm=False)
    record = run_moving_bin(job)
    assert record.status == "ok" and record.stopped == ""
    # today's open-loop execution of the same plans (its transit and return from the trial as well)
    from suite.execution.plan_loop import plan_cans
    from suite.problems.cycle import build_problems
    from scenes.grasp_rule import truth_grasp

    scene = job.scene
    problems = build_problems(scene, [truth_grasp(scene, c) for c in scene.cans], time_limit_s=5.0, seed=3)
    ejob = ExecutionJob("rrt", config_dict(make_config(planner_class("rrt"), None)), scene, "truth", 5.0, 3)
    today = execute_cycles(scene, open_loop(plan_cans(problems, ejob)), q_home=problems[0].q_start, planner="rrt")
    assert record.cans_in_bin == today.cans_in_bin == 2
    assert record.collisions == today.collisions == 0
    assert record.contacts_bin == record.contacts_person == 0
    assert record.replans == 0 and record.deadline_misses == 0  # nothing moved: nothing to replan
    assert [f["where"] for f in record.fates] == [c.where for c in today.cans]
    # the cans land where today's land, to within the bin's own size
    for f, c in zip(record.fates, today.cans):
        assert np.linalg.norm(np.array(f["p_WC_m"][:2]) - np.array(c.p_WC_m[:2])) < 0.2


def test_an_arm_the_person_walks_into_backs_away_from_them():
    """Standing over the bin with the person (by the estimate) pressed against it, the arm escapes:
    it backs away, rises, and stops, validated in the world without the person; it ends farther
    from them than it started, and the command is continuous."""
    from planners.registry import planner_class
    from planners.worlds import drake_plan_scene
    from scenes.ik import IkOptions, PoseIk
    from scenes.moving_bin import drop_pose
    from suite.execution.commands import CommandStream
    from suite.execution.moving_bin_episode import Episode
    from suite.run.trial import make_config

    job = _job(cans=1, variant="open", seed=2, speed_m_s=0.0, estimate_noise_m=0.0)
    cls = planner_class("rrt")
    ep = Episode(job, cls(make_config(cls, None)))
    ep._next_can(0.0)  # the can's problems
    spec, t = job.scene.spec, 1.0
    bin_xy = ep.estimator.predict(t, t)
    q = PoseIk(drake_plan_scene(ep.transit_template)).solve(
        drop_pose(spec, bin_xy), q_seed=np.asarray(job.q_home), rng=np.random.default_rng(0),
        options=IkOptions(free_yaw=True))
    assert q is not None
    ep.stream = CommandStream(q_home=q, open_width_m=spec.grasp.open_width_m, config=job.config)
    ep.stream.append_hold("wait", ep.can_id, t, width_from_m=0.0, carrying=True)
    ep.mode = "transit"
    # the person steps toward the gripper until 2 cm from the arm: inside its 5 cm margin
    towards = ep.robot.gripper_pose(q[None, :])[0][:2, 3] - (bin_xy + ep.person_offset)
    ep.person_offset = ep.person_offset + (ep._separation(t, q) - 0.02) * towards / np.linalg.norm(towards)
    before = ep._separation(t, q)
    assert ep._crowded(t), before
    ep.on_stream_end(t)
    assert ep.escapes_total == 1 and [s.phase for s in ep.stream.segments][-2:] == ["escape", "escape"]
    after = ep._separation(t, ep.stream.q_end)
    assert after > before + 0.05
    assert ep.robot.gripper_pose(ep.stream.q_end[None, :])[0][2, 3] > ep.robot.gripper_pose(q[None, :])[0][2, 3]
    ts = np.linspace(t, ep.stream.duration_s, 400)
    qs = np.array([ep.stream.state(x)[0] for x in ts])
    assert np.max(np.abs(np.diff(qs, axis=0))) < 0.02  # no jump
    assert np.max(np.abs(ep.stream.state(ep.stream.duration_s)[1])) < 1e-6  # at rest at its end
    # the arm is clear now: no second escape
    assert not ep._crowded(t)


@pytest.mark.slow
def test_speed_and_separation_monitoring_stops_the_arm_near_the_person():
    """The person stands beside a still bin: the arm, arriving fast over the bin next to them,
    makes protective stops (a stopping blend, then a plan from rest), and never touches them."""
    from suite.execution.moving_bin import run_moving_bin

    record = run_moving_bin(_job(cans=1, variant="open", seed=4, speed_m_s=0.0))
    assert record.status == "ok" and record.ssm_holds > 0
    assert record.contacts_person == 0 and record.person_min_distance_m > 0
    assert record.cans_in_bin == 1


@pytest.mark.slow
@pytest.mark.parametrize("margin_m", [0.01, 0.2])
def test_a_replan_that_misses_its_deadline_keeps_the_plan_and_never_releases_off_the_bin(margin_m):
    """A deadline of a microsecond: every replan misses. The first transit (planned at rest, the
    arm waits for it) aims at a prediction the fast bin leaves; no replan is ever spliced in, and
    the can is released only over the opening, or the arm stops safely holding it (a release
    margin of 0.2 m leaves no place over the opening: the arm must stop)."""
    from suite.execution.moving_bin_episode import Episode
    from planners.registry import planner_class
    from suite.run.trial import make_config

    job = _job(cans=2, speed_m_s=0.4, accel_m_s2=1.0, replan_deadline_s=1e-6, max_wait_s=1.0, seed=1,
               release_margin_m=margin_m, ssm=False)
    cls = planner_class("rrt")
    episode = Episode(job, cls(make_config(cls, None)))
    record = episode.run()
    bound = [e for e in record.events if e.trigger in ("drift", "arrival")]
    assert bound, "the bin moved: the loop must have tried to replan"
    assert all(e.outcome == "missed" for e in bound)
    assert record.splices == 0 and record.deadline_misses == len(bound)
    phases = [s.phase for s in episode.stream.segments]
    assert "blend" not in phases
    assert phases.count("transit") == record.cans_attempted  # only the first transit of each can ran
    spec = job.scene.spec
    half = np.array(spec.bin.outer_size_m[:2]) / 2 - spec.bin.wall_thickness_m
    fates = {f["can_id"]: f["where"] for f in record.fates}
    for can in record.cans:
        if can.released:
            assert can.release_offset_m < float(np.linalg.norm(half))
        else:  # given up: put back on the plate, never dropped off the bin
            assert can.put_down and fates[can.can_id] == "plate", (can, fates)
    # every can is attempted and counted, given up or not
    assert record.cans_attempted == 2 and record.cans_not_attempted == 0 and record.stopped == ""
    if margin_m > 0.1:  # no place over the opening: both cans given up and put down
        assert record.cans_given_up == record.cans_put_down == 2 and record.cans_in_bin == 0
        assert phases.count("put_down") == 2 and phases.count("retreat") == 4  # descend, approach reversed


@pytest.mark.slow
def test_a_moving_bin_episode_replans_and_splices_without_a_jump_or_a_stop():
    from suite.execution.moving_bin import run_moving_bin

    record = run_moving_bin(_job(cans=1, speed_m_s=0.2, seed=0, dwell_s=0.0))
    assert record.status == "ok" and record.replans > 0 and record.splices > 0
    assert record.splice_jump_q_rad < 1e-9 and record.splice_jump_v_rad_s < 1e-9
    spliced = [e for e in record.events if e.outcome == "spliced" and e.trigger == "drift"]
    assert spliced and all(e.splice_speed_rad_s > 0.01 for e in spliced)  # joined while moving
    assert record.splices_at_rest < record.splices
    assert record.cans_in_bin == 1 and record.releases_moving == 1
    assert record.to_json()["replans_per_can"] == record.replans


@pytest.mark.slow
def test_modelled_latency_gives_the_same_records_twice():
    """Two runs of a small sweep in modelled mode give identical records (no wall-clock field)."""
    import json

    from suite.execution.moving_bin import run_moving_bin_job

    def sweep():
        return [run_moving_bin_job(_job(planner=p, cans=1, speed_m_s=0.3, seed=2, dwell_s=0.0,
                                        latency_mode="modelled")) for p in ("rrt", "trajopt")]

    first, second = sweep(), sweep()
    assert all(r.status == "ok" and r.latency_mode == "modelled" for r in first)
    assert all(r.wall_time_s is None and r.latency_parts_s == {} for r in first)
    assert sum(r.replans for r in first) > 0
    assert [json.dumps(r.to_json(), sort_keys=True) for r in first] == [json.dumps(r.to_json(), sort_keys=True)
                                                                         for r in second]


# --- the command ----------------------------------------------------------------------------------


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "suite", *args], capture_output=True, text=True)


def test_compare_refuses_bad_moving_bin_input_in_one_line(tmp_path):
    out = tmp_path / "run"
    cases = [
        (["--moving-bin", "-0.1", "--execute"], "-0.1"),
        (["--moving-bin", "0.1"], "--execute"),
        (["--moving-bin", "0.1", "--execute", "--variant", "station"], "station"),
    ]
    far = tmp_path / "far.yaml"
    far.write_text("region_m: [[0.3, 0.45], [0.75, 0.6]]\n")
    cases.append((["--moving-bin", "0.1", "--execute", "--moving-bin-scenario", str(far)], "out of the arm's reach"))
    for args, word in cases:
        r = _cli("compare", "--planners", "rrt", "--out", str(out), *args)
        assert r.returncode == 2, r.stderr
        assert word in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
        assert not out.exists()  # refused before anything was written
