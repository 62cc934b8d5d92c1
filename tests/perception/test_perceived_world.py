"""The perceived collision world (`perception.world`): built from the cameras, it holds the loose
objects the truth holds and none of the cans' or the robot's space; planners plan in it while the
judge keeps the truth, and a path the truth rejects is a perception-induced failure with a cause."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from perception.pipeline import PerceptionSetup, noise_rng
from perception.voxel_boxes import clear_of_cans, merge_boxes
from perception.world import LOOSE_PREFIXES, VOXEL_PREFIX, WorldParams, fixtures, perceive_world
from perception.world_evidence import fill_row_holes, inside
from scenes.errors import SuiteError
from scenes.generate import generate_scene
from scenes.scene import CanPose, Scene
from scenes.spec import load_spec
from scenes.spec_parts import Obstacle, pose_tuple

ROBUST_KINECT = PerceptionSetup(pipeline="robust", sensor="kinect-v1")


@pytest.fixture(scope="module")
def clutter():
    scene = generate_scene(load_spec(variant="clutter").with_can_count(5), seed=4321, check_reachable=False)
    detections, world = perceive_world(scene, setup=ROBUST_KINECT, rng=noise_rng(scene.seed))
    return scene, detections, world


def _samples_inside(o: Obstacle, n: int = 3000) -> np.ndarray:
    rng = np.random.default_rng(0)
    extent = np.asarray(o.size_m, float) if o.shape == "box" else np.array([2 * o.size_m[0], 2 * o.size_m[0], o.size_m[1]])
    local = rng.uniform(-0.5, 0.5, (n, 3)) * extent
    X = o.pose()
    p = local @ X[:3, :3].T + X[:3, 3]
    return p[inside(p, o.shape, o.size_m, X, 0.0)]


def _covered(points: np.ndarray, boxes) -> np.ndarray:
    hit = np.zeros(len(points), bool)
    for b in boxes:
        hit |= inside(points, "box", b.size_m, b.pose(), 0.0)
    return hit


def test_world_holds_the_fixtures_the_cans_seen_and_the_loose_objects_as_boxes(clutter):
    scene, detections, world = clutter
    spec = world.scene.spec
    names = [o.name for o in spec.extra]
    assert not any(n.startswith(LOOSE_PREFIXES) for n in names)  # nothing loose is read from the truth
    assert [o for o in spec.extra if not o.name.startswith(VOXEL_PREFIX)] == list(fixtures(scene.spec))
    assert len(world.scene.cans) == len(detections) >= len(scene.cans) - 1
    boxes = [o for o in spec.extra if o.name.startswith(VOXEL_PREFIX)]
    assert world.boxes == len(boxes) > 0
    plate_top = scene.spec.plate_top_z_m
    ws = spec
    near_can = world.params.can_point_margin_m + world.params.unseen_clear_m  # a can's own surroundings
    for o in scene.spec.extra:  # every distractor above the plate is inside the seen boxes, but beside a can
        p = _samples_inside(o)
        p = p[p[:, 2] > plate_top + 0.001]
        for c in world.scene.cans:
            p = p[~inside(p, "cylinder", (ws.can.radius_m, ws.can.height_m), c.X_WC(), near_can)]
        assert _covered(p, boxes).mean() > 0.97, o.name
    r = scene.spec.can.radius_m
    for c in scene.cans:  # a can seen is a can of the world; a can missed is an obstacle like any other
        p = _samples_inside(Obstacle(f"can_{c.id}", "cylinder", (r, scene.spec.can.height_m),
                                     pose_tuple(c.X_WC()), (1, 0, 0, 1)))
        seen = any(np.hypot(*(np.asarray(d.p_WC_m[:2]) - c.p_WC_m[:2])) < r for d in detections)
        if seen:  # its space is its own (a neighbour's padded box may graze its side)
            assert _covered(p, boxes).mean() < 0.05
        else:
            assert _covered(p[p[:, 2] > plate_top + 0.001], boxes).mean() > 0.95
    # the perceived cans are grown by the padding; the held can keeps the truth's total margin
    assert spec.can.radius_m == pytest.approx(scene.spec.can.radius_m + world.can_padding_m)
    assert spec.can.radius_m + spec.grasp.held_margin_m == pytest.approx(
        scene.spec.can.radius_m + scene.spec.grasp.held_margin_m)


def test_the_robot_in_view_is_left_out_and_only_then(clutter):
    from scenes.collision.world import CollisionWorld
    from scenes.ik import Q_READY, PoseIk
    from scenes.drake_scene import build_drake_scene
    from scenes.grasp_rule import waypoint_pose

    scene, _, _ = clutter
    # the arm above the plate, in every camera's view
    ik = PoseIk(build_drake_scene(scene, mode="plan", cameras=False, gripper_opening_m=scene.spec.grasp.open_width_m))
    X = waypoint_pose((*scene.spec.plate.center_m[:2], scene.spec.plate_top_z_m + 0.22))
    q = ik.solve(X, q_seed=Q_READY, rng=np.random.default_rng(0))
    assert q is not None
    _, filtered = perceive_world(scene, setup=ROBUST_KINECT, rng=noise_rng(scene.seed), q_robot=q)
    assert CollisionWorld(filtered.scene, gripper_opening_m=scene.spec.grasp.open_width_m).is_free(q)
    from scenes.render import render

    images = render(scene, q_iiwa=q)  # the same frames, the arm's pose withheld from the builder
    _, unfiltered = perceive_world(scene, setup=ROBUST_KINECT, rng=noise_rng(scene.seed), images=images)
    assert not CollisionWorld(unfiltered.scene, gripper_opening_m=scene.spec.grasp.open_width_m).is_free(q)


def test_row_holes_are_filled_far_only_as_a_projector_shadow():
    d = np.array([[0.7, np.nan, np.nan, 0.9, np.nan, 0.8], [np.nan, 0.5, np.nan, np.nan, np.nan, 0.6]])
    f = fill_row_holes(d, max_px=2)  # no shadow model: a dropout hides what is behind it
    assert f[0].tolist() == [0.7, 0.7, 0.7, 0.9, 0.8, 0.8]
    assert np.isnan(f[1, 0]) and np.isnan(f[1, 2:5]).all()  # an open end, and a run longer than 2, stay empty
    assert np.isposinf(fill_row_holes(np.array([[0.7, np.inf, 0.8]]), 3)[0, 1])  # nothing in range is not a hole
    # far surface on the left, a nearer object on the right, the run as wide as their disparity jump
    fb = 40.0
    width = round(fb * (1 / 0.6 - 1 / 0.73))  # 12 px
    row = np.array([[0.73] * 3 + [np.nan] * width + [0.6] * 3])
    assert fill_row_holes(row, 24, shadow_px_m=fb)[0, 3:3 + width].tolist() == [0.73] * width
    assert (fill_row_holes(row[:, ::-1], 24, shadow_px_m=fb)[0, 3:3 + width] == 0.6).all()  # near object on the left
    narrow = np.array([[0.73] * 3 + [np.nan] * 4 + [0.6] * 3])  # much narrower than the jump: a dropout
    assert (fill_row_holes(narrow, 24, shadow_px_m=fb)[0, 3:7] == 0.6).all()


def test_merged_boxes_cover_exactly_the_occupied_voxels():
    occ = np.random.default_rng(3).random((9, 7, 5)) < 0.4
    got = np.zeros_like(occ, dtype=int)
    for (i, j, k), (a, b, c) in merge_boxes(occ):
        got[i:i + a, j:j + b, k:k + c] += 1
    assert (got == occ).all()


def test_bad_world_settings_are_refused():
    with pytest.raises(SuiteError, match="voxel_m"):
        WorldParams(voxel_m=0.0)
    with pytest.raises(SuiteError, match="coarser"):
        WorldParams(voxel_m=0.2)
    with pytest.raises(SuiteError, match="padding"):
        WorldParams(can_padding_m=-0.001)


def test_problems_plan_in_the_perceived_world_and_are_judged_in_the_truth(clutter):
    from suite.problems.cycle import build_problems

    scene, detections, world = clutter
    problems = build_problems(scene, [d.grasp for d in detections[:1]], time_limit_s=1.0, seed=1, world=world)
    assert len(problems) == 5
    truth_ids = {c.id for c in scene.cans}
    for p in problems:
        assert p.scene is scene and p.plan_world is not None and p.plan_world.scene is world.scene
        planned = p.for_planner()
        assert planned.scene is world.scene and planned.plan_world is None
        assert set(p.removed_can_ids) <= truth_ids
        assert not set(planned.removed_can_ids) & truth_ids
    lift, transit = problems[2], problems[3]
    assert lift.held is not None and lift.held.can.id in truth_ids
    assert lift.plan_world.held.can.id == world.can_of_detection[detections[0].id]
    assert transit.plan_world.removed_can_ids == (world.can_of_detection[detections[0].id],)
    from suite.problems.identity import problem_id

    truth_problems = build_problems(scene, [d.grasp for d in detections[:1]], time_limit_s=1.0, seed=1)
    if truth_problems[0].pre_status is None and problems[0].pre_status is None:
        assert problem_id(truth_problems[0]) != problem_id(problems[0])  # the plan world is part of the identity


def test_a_path_free_in_the_seen_world_that_strikes_the_truth_is_perception_induced(clutter):
    from planners.base import PlanWorld
    from planners.worlds import collision_world
    from suite.problems.cycle import build_problems
    from suite.scoring.perception_failure import perception_induced
    from scenes.robot_model import load_robot

    scene, detections, world = clutter
    p = build_problems(scene, [d.grasp for d in detections[:1]], time_limit_s=1.0, seed=1)[0]
    assert p.pre_status is None
    # the truth gets a box where the gripper passes halfway along the straight line; the planner's
    # world (the truth without it, as if the cameras had missed it) does not
    q_mid = (p.q_start + p.q_goal) / 2
    robot = load_robot(scene.spec.robot)
    X = np.eye(4)
    X[:3, 3] = robot.link_poses(q_mid)[8][:3, 3]
    box = Obstacle("distractor_9", "box", (0.04, 0.04, 0.04), pose_tuple(X), (0, 0, 1, 1))
    truth = Scene(dataclasses.replace(scene.spec, extra=scene.spec.extra + (box,)), scene.seed, scene.cans)
    problem = p.with_(scene=truth, plan_world=PlanWorld(scene, None, ()))
    path = np.array([p.q_start, p.q_goal])
    if collision_world(p).path_free(path, resolution_rad=0.01) >= 0:
        pytest.skip("the straight line is not free in this layout")
    found = perception_induced(problem, path, collision_world(problem), collision_world(problem.for_planner()))
    assert found is not None and found["object"] == "distractor_9" and found["cause"] == "object_under_covered"
    # a path that also collides in the planner's own world is the planner's failure, not perception's
    assert perception_induced(problem, path, collision_world(problem), collision_world(problem)) is None


def test_a_perceived_world_without_perceived_grasps_is_refused(tmp_path):
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-m", "suite", "compare", "--variant", "open", "--scenes", "1", "--grasps",
                          "truth", "--world", "perceived", "--out", str(tmp_path / "run")], capture_output=True, text=True)
    assert out.returncode != 0
    assert "perceived grasps" in out.stderr and len(out.stderr.strip().splitlines()) == 1, out.stderr
    assert not (tmp_path / "run").exists()


def test_depth_sigmas_follow_the_sensor_model():
    from perception.world_evidence import depth_sigmas
    from scenes.sensor import SENSOR_PRESETS, SensorSpec

    z = np.array([0.5, 0.73, 1.2])
    for sensor in (SENSOR_PRESETS["kinect-v1"], SENSOR_PRESETS["kinect-v1"].with_noise(scale=2.0),
                   SensorSpec(kind="gaussian", depth_sigma_m=0.003)):
        assert np.allclose(depth_sigmas(sensor, z), [sensor.depth_sigma_at_m(float(v)) for v in z])
    assert (depth_sigmas(None, z) == 0).all()


def test_inside_matches_the_shapes():
    X = np.eye(4)
    X[:3, 3] = (1.0, 2.0, 3.0)
    p = X[:3, 3] + np.array([[0.0, 0.0, 0.0], [0.11, 0.0, 0.0], [0.0, 0.0, 0.24], [0.3, 0.3, 0.3]])
    assert inside(p, "box", (0.2, 0.2, 0.5), X, 0.0).tolist() == [True, False, True, False]
    assert inside(p, "box", (0.2, 0.2, 0.5), X, 0.02).tolist() == [True, True, True, False]
    assert inside(p, "cylinder", (0.1, 0.5), X, 0.0).tolist() == [True, False, True, False]
    assert inside(p, "capsule", (0.1, 0.3), X, 0.0).tolist() == [True, False, True, False]
    assert inside(p, "sphere", (0.25,), X, 0.0).tolist() == [True, True, True, False]


def test_a_box_is_kept_out_of_a_perceived_cans_held_model():
    """A box reaching into the disc a can holds where it stands loses the face that costs least;
    one beside the disc's square corner stays; one wholly inside is dropped."""
    can = CanPose(1000, (0.0, 0.0, 0.1), False, 0.0)
    R, H = 0.038, 0.132
    # a corner poking 3 mm into the disc from the +x, +y diagonal
    d = R / np.sqrt(2) - 0.003
    lo, hi = clear_of_cans([d, d, 0.05], [d + 0.05, d + 0.01, 0.15], [can], R, H)
    gap = np.hypot(np.clip(0.0, lo[0], hi[0]), np.clip(0.0, lo[1], hi[1]))
    # raising the long x side's low face costs 11% of the box, the short y side's 56%
    assert gap >= R - 1e-9 and lo[0] > d and lo[1] == pytest.approx(d)
    corner = ([R * 0.75, R * 0.75, 0.05], [0.1, 0.1, 0.15])  # inside the square, outside the disc
    kept = clear_of_cans(*corner, [can], R, H)
    assert np.allclose(kept[0], corner[0]) and np.allclose(kept[1], corner[1])
    assert clear_of_cans([-0.01, -0.01, 0.08], [0.01, 0.01, 0.12], [can], R, H) is None
    above = clear_of_cans([-0.01, -0.01, 0.15], [0.01, 0.01, 0.2], [can], R, H)  # its low face raised to the top
    assert above is not None and above[0][2] == pytest.approx(0.1 + H / 2)
    lying = CanPose(1001, (0.0, 0.0, 0.05), True, 0.0)  # along x: its box is cleared
    lo, hi = clear_of_cans([0.06, -0.02, 0.02], [0.2, 0.02, 0.08], [lying], R, H)
    assert lo[0] == pytest.approx(H / 2)
