"""The python-fcl world against Drake, and its own guarantees (sphere covers, joint tables, held can)."""

from __future__ import annotations

import functools

import fcl
import numpy as np
import pytest

from scenes.collision import build, joint_tables, motion, shapes
from scenes.collision.world import CollisionWorld
from scenes.generate import generate_scene
from scenes.grasp_rule import truth_grasp
from scenes.scene import HeldCan
from scenes.spec import load_spec
from suite.bench.collision import drake_checker

AGREEMENT_CONFIGS = 2000
#: A disagreement with Drake is tolerated only this close to contact (Drake's signed distance).
CONTACT_MARGIN_M = 1e-3
#: Plate side and bin side of the wall, the arm reaching forward at gripper height 0.25 m (the
#: wall is 0.35 m high): only joint 1 differs, so the straight motion sweeps through the wall.
Q_PLATE_SIDE = np.array([-0.6, 0.9, 0.0, -1.2, 0.0, 0.9, 0.0])
Q_BIN_SIDE = np.array([0.6, 0.9, 0.0, -1.2, 0.0, 0.9, 0.0])
Q_READY = np.array([-1.57, 0.1, 0.0, -1.2, 0.0, 1.6, 0.0])
Q_RAISED = np.array([-0.5, -0.2, 0.3, -1.0, 0.2, 1.2, 0.5])


@functools.lru_cache(maxsize=None)
def _setup(variant: str):
    """A 5-can scene (`gcs-arm`: none, as the paper's), its python-fcl world and Drake's collision
    checker (built once per variant)."""
    spec = load_spec(variant=variant)
    scene = generate_scene(spec if variant == "gcs-arm" else spec.with_can_count(5), seed=0)
    return scene, CollisionWorld(scene), drake_checker(scene)


def _drake_env_distance(checker, q, fixed_links=("iiwa_link_0", "iiwa_link_1")) -> float:
    """Drake's signed distance between the robot and the environment (negative in penetration)."""
    from pydrake.planning import RobotCollisionType

    rc = checker.CalcRobotClearance(q, 10.0)
    plant = checker.plant()
    # Links whose distance to the scene does not depend on q are not part of the clearance.
    fixed = {plant.GetBodyByName(n).index() for n in fixed_links}
    return min(
        d
        for d, t, b in zip(rc.distances(), rc.collision_types(), rc.robot_indices())
        if t == RobotCollisionType.kEnvironmentCollision and b not in fixed
    )


def _drake_min_distance(checker, q) -> float:
    """Drake's smallest signed distance over all robot pairs (scene and self)."""
    return float(np.min(checker.CalcRobotClearance(q, 10.0).distances()))


@pytest.mark.parametrize("variant", ["open", "wall", "gcs-arm"])
def test_is_free_agrees_with_drake(variant):
    scene, world, checker = _setup(variant)
    Q = world.robot.random_configurations(np.random.default_rng(100), AGREEMENT_CONFIGS)
    ours = np.array([world.is_free(q) for q in Q])
    drake = np.array(checker.CheckConfigsCollisionFree(Q, parallelize=False))
    # Both answers occur, so agreement is not trivial.
    assert 0.2 < ours.mean() < 0.9
    agreement = float((ours == drake).mean())
    print(f"{variant}: raw agreement with Drake {agreement:.4f} on {len(Q)} configurations")
    for q in Q[ours != drake]:
        assert abs(_drake_min_distance(checker, q)) < CONTACT_MARGIN_M
    assert agreement >= 0.995
    # The batched paths give the same answers as the single-state path.
    np.testing.assert_array_equal(world.states_free(Q), ours)
    first = int(np.flatnonzero(~ours)[0])
    assert world.first_collision(Q) == first
    assert world.first_collision(Q[ours]) == -1


@pytest.mark.parametrize("variant", ["open", "wall", "gcs-arm"])
def test_clearance_matches_drake_signed_distance(variant):
    scene, world, checker = _setup(variant)
    Q = world.robot.random_configurations(np.random.default_rng(101), 60)
    ours = world.clearances(Q)
    # The paper's link 1 is a sphere off joint 1's axis: its distance to the scene depends on q1.
    fixed = ("iiwa_link_0",) if world.robot.name == "iiwa14-spheres" else ("iiwa_link_0", "iiwa_link_1")
    drake = np.array([_drake_env_distance(checker, q, fixed) for q in Q])
    assert (ours > 0).any() and (ours < 0).any()  # free and penetrating configurations
    np.testing.assert_allclose(ours, drake, rtol=0, atol=1e-3)


def test_motion_through_the_wall_is_not_free():
    _, wall, wall_checker = _setup("wall")
    _, open_world, _ = _setup("open")
    assert wall.is_free(Q_PLATE_SIDE) and wall.is_free(Q_BIN_SIDE)
    assert not wall.motion_free(Q_PLATE_SIDE, Q_BIN_SIDE, resolution_rad=0.01)
    assert not wall_checker.CheckEdgeCollisionFree(Q_PLATE_SIDE, Q_BIN_SIDE)
    # The same sweep without the wall is free: the wall is what stops it.
    assert open_world.motion_free(Q_PLATE_SIDE, Q_BIN_SIDE, resolution_rad=0.01)
    assert open_world.path_free(np.array([Q_PLATE_SIDE, Q_BIN_SIDE]), resolution_rad=0.01) == -1
    bad = wall.path_free(np.array([Q_PLATE_SIDE, Q_BIN_SIDE]), resolution_rad=0.01)
    samples = wall.interpolate(np.array([Q_PLATE_SIDE, Q_BIN_SIDE]), 0.01)
    assert 0 < bad < len(samples) - 1 and not wall.is_free(samples[bad]) and wall.is_free(samples[bad - 1])


@pytest.mark.parametrize("variant", ["open", "wall"])
def test_clearly_free_motion_is_free(variant):
    _, world, checker = _setup(variant)
    assert world.motion_free(Q_READY, Q_RAISED, resolution_rad=0.01)
    assert checker.CheckEdgeCollisionFree(Q_READY, Q_RAISED)


def test_held_can_is_part_of_the_robot():
    from scenes.drake_scene import build_drake_scene

    scene, _, _ = _setup("open")
    can = scene.cans[1]
    held = HeldCan.from_grasp(can, truth_grasp(scene, can).X_WG)
    opening = 2 * scene.spec.can.radius_m
    with_can = CollisionWorld(scene, held=held, gripper_opening_m=opening)
    without = CollisionWorld(scene, gripper_opening_m=opening, removed_can_ids=[can.id])
    Q = with_can.robot.random_configurations(np.random.default_rng(102), 2000)
    free_with, free_without = with_can.states_free(Q), without.states_free(Q)
    assert not (free_with & ~free_without).any()  # the can only adds collisions
    only_can = np.flatnonzero(free_without & ~free_with)
    assert len(only_can) >= 5
    # There the held can itself touches the scene or the arm.
    can_part = next(p for p in with_can.parts if p.name == "held_can")
    for m in only_can:
        rows = with_can._state_rows(Q[m])
        obj = with_can._place(with_can.parts.index(can_part), rows)
        others = [o for name, o in with_can.obstacles if name != "plate"]
        arm = [with_can._place(i, rows) for i, p in enumerate(with_can.parts) if p.name.startswith("iiwa_link_") and p.name != "iiwa_link_7"]
        assert any(fcl.collide(obj, o, fcl.CollisionRequest(), fcl.CollisionResult()) for o in others + arm)
    # Drake's scene graph (the plan-mode scene with the can welded in the gripper) agrees on all.
    ds = build_drake_scene(scene, mode="plan", cameras=False, held=held, gripper_opening_m=opening)
    context = ds.diagram.CreateDefaultContext()
    plant_context = ds.plant.GetMyContextFromRoot(context)
    sg_context = ds.scene_graph.GetMyContextFromRoot(context)
    port = ds.scene_graph.get_query_output_port()
    drake_free = []
    for q in Q:
        ds.plant.SetPositions(plant_context, q)
        drake_free.append(not port.Eval(sg_context).HasCollisions())
    np.testing.assert_array_equal(free_with, drake_free)


def test_batched_checks_agree_with_the_single_state_check_everywhere():
    """The batched checks (motions, paths) answer exactly as the single-state check: with a held
    can, for batches of every size, and past the joint limits where no table decides a pair."""
    scene, _, _ = _setup("wall")
    can = scene.cans[0]
    held = HeldCan.from_grasp(can, truth_grasp(scene, can).X_WG)
    world = CollisionWorld(scene, held=held, gripper_opening_m=2 * scene.spec.can.radius_m)
    rng = np.random.default_rng(105)
    lo, hi = world.robot.lower_rad, world.robot.upper_rad
    Q = lo - 0.2 + (hi - lo + 0.4) * rng.random((1500, 7))  # some beyond the limits
    single = np.array([world.is_free(q) for q in Q])
    assert 0.1 < single.mean() < 0.9
    np.testing.assert_array_equal(world.states_free(Q), single)
    for size in (1, 7, 8, 63, 64, 65, 200):
        for start in range(0, 600, size):
            batch = Q[start : start + size]
            bad = np.flatnonzero(~single[start : start + size])
            assert world.first_collision(batch) == (int(bad[0]) if len(bad) else -1)


@pytest.mark.parametrize("variant", ["wall", "shelf"])
def test_the_planners_motion_check_answers_as_every_sample_does(variant):
    """`motion_samples_free` skips samples its distance bounds prove free: its answer is still
    that of checking every sample, on long and short motions, free and blocked, with a held can,
    and it evaluates fewer states."""
    scene = generate_scene(load_spec(variant=variant).with_can_count(5), seed=1)
    can = scene.cans[0]
    held = HeldCan.from_grasp(can, truth_grasp(scene, can).X_WG)
    rng = np.random.default_rng(106)
    evaluated = every = 0
    answers = []
    for world in (CollisionWorld(scene), CollisionWorld(scene, held=held, gripper_opening_m=2 * scene.spec.can.radius_m)):
        Q = world.robot.random_configurations(rng, 600)
        starts = Q[world.states_free(Q)][:120]
        for i, q0 in enumerate(starts):
            for scale in (0.05, 0.3, 1.5):
                q1 = np.clip(q0 + scale * rng.standard_normal(7), world.robot.lower_rad, world.robot.upper_rad)
                samples = world.interpolate(np.array([q0, q1]), 0.01)[1:]
                truth = world.first_collision(samples) < 0
                c0 = world.checks
                got = world.motion_samples_free(q0, q1, resolution_rad=0.01)
                assert got == truth, (variant, i, scale)
                answers.append(truth)
                if truth:
                    evaluated += world.checks - c0
                    every += len(samples)
    assert 0.2 < np.mean(answers) < 0.8  # both answers, often
    print(f"{variant}: {evaluated} of {every} samples of the free motions evaluated")
    assert evaluated < 0.8 * every  # and fewer states than every sample on the free motions


def test_a_motion_is_checked_end_first_and_its_samples_cover_it():
    """`check_order`: the motion's samples as `motion_samples_free` takes them, the end first."""
    q0, q1 = np.zeros(7), np.linspace(-0.3, 0.7, 7)
    n = 14  # ceil(0.7 / 0.05): the last joint moves most
    order = motion.check_order(n)
    Q = q0 + (order / n)[:, None] * (q1 - q0)
    assert np.array_equal(Q[0], q1)
    steps = np.sort(Q[:, -1])
    assert len(Q) == 14 and np.max(np.abs(np.diff(np.vstack([q0, Q[np.argsort(Q[:, -1])]]), axis=0))) <= 0.05 + 1e-12
    assert steps[-1] == pytest.approx(0.7)


def test_joint_tables_are_sound():
    """Wherever a table decides a self pair without an exact query, FCL agrees: apart cells are
    apart, touching cells collide."""
    _, world, _ = _setup("open")
    assert world._tables, "the wrist pairs should have tables"
    Q = world.robot.random_configurations(np.random.default_rng(103), 1500)
    req = fcl.DistanceRequest(enable_signed_distance=True)
    decided = {joint_tables.APART: 0, joint_tables.TOUCHING: 0}
    for q in Q:
        ql = q.tolist()
        rows = world._state_rows(q)
        for j, lo, inv, n, cells, k in world._tables:
            x = (ql[j] - lo) * inv
            c = cells[int(x)] if 0.0 <= x < n else joint_tables.UNKNOWN
            if c == joint_tables.UNKNOWN:
                continue
            a = world._place(world._pp_part[k], rows)
            b = world._place(world._pp_other[k][0], rows)
            if c == joint_tables.APART:
                assert fcl.distance(a, b, req, fcl.DistanceResult()) > 0
            else:
                assert fcl.collide(a, b, fcl.CollisionRequest(), fcl.CollisionResult())
            decided[c] += 1
    assert decided[joint_tables.APART] > len(Q) and decided[joint_tables.TOUCHING] > 20


@pytest.mark.parametrize("kind,dims", [("box", (0.146, 0.0725, 0.05)), ("box", (0.012, 0.082, 0.02)),
                                       ("capsule", (0.095, 0.2155)), ("cylinder", (0.065, 0.05)),
                                       ("cylinder", (0.033, 0.122)), ("sphere", (0.05,))])
@pytest.mark.parametrize("spacing", [build.ENV_SPACING, build.SELF_SPACING])
def test_cover_spheres_enclose_and_inner_balls_lie_inside(kind, dims, spacing):
    centres, outer, inner = shapes.cover_spheres(kind, dims, spacing)
    rng = np.random.default_rng(104)

    def inside(p):  # points (N, 3) in the shape frame
        if kind == "box":
            return np.all(np.abs(p) <= np.asarray(dims) / 2 + 1e-12, axis=1)
        if kind == "sphere":
            return np.linalg.norm(p, axis=1) <= dims[0] + 1e-12
        r, length = dims
        radial = np.hypot(p[:, 0], p[:, 1])
        if kind == "cylinder":
            return (radial <= r + 1e-12) & (np.abs(p[:, 2]) <= length / 2 + 1e-12)
        z = np.clip(p[:, 2], -length / 2, length / 2)
        return np.hypot(radial, p[:, 2] - z) <= r + 1e-12

    if kind == "box":
        half = np.asarray(dims) / 2
    elif kind == "sphere":
        half = np.full(3, dims[0])
    else:
        half = np.array([dims[0], dims[0], dims[1] / 2 + (dims[0] if kind == "capsule" else 0.0)])
    pts = rng.uniform(-half, half, size=(20000, 3))
    pts = pts[inside(pts)]
    assert len(pts) > 1000
    d = np.linalg.norm(pts[:, None, :] - centres[None], axis=2)
    assert np.all((d <= outer[None] + 1e-12).any(axis=1))  # every point of the shape is covered
    for c, rho in zip(centres, inner):
        u = rng.normal(size=(500, 3))
        ball = c + rho * u / np.linalg.norm(u, axis=1, keepdims=True) * rng.uniform(0, 1, (500, 1)) ** (1 / 3)
        assert inside(ball).all()  # every inner ball lies in the shape
