"""The certified segment check: its motion bound holds, and its verdicts agree with a fine check."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from scenes.collision.certify import CERTIFIED, COLLISION, UNPROVED, certifier, point_axis_radii
from scenes.collision.world import CollisionWorld
from scenes.generate import generate_scene
from scenes.grasp_rule import truth_grasp
from scenes.scene import HeldCan
from scenes.spec import load_spec

LAMBDA_SEGMENTS = 10_000
Q_PLATE_SIDE = np.array([-0.6, 0.9, 0.0, -1.2, 0.0, 0.9, 0.0])
Q_BIN_SIDE = np.array([0.6, 0.9, 0.0, -1.2, 0.0, 0.9, 0.0])
Q_READY = np.array([-1.57, 0.1, 0.0, -1.2, 0.0, 1.6, 0.0])
Q_RAISED = np.array([-0.5, -0.2, 0.3, -1.0, 0.2, 1.2, 0.5])


@functools.lru_cache(maxsize=None)
def _holding_world() -> CollisionWorld:
    """A wall scene's world with a can held in the gripper (fingers at the can's width)."""
    scene = generate_scene(load_spec(variant="wall").with_can_count(3), seed=4)
    can = scene.cans[0]
    return CollisionWorld(scene, gripper_opening_m=0.07, held=HeldCan.from_grasp(can, truth_grasp(scene, can).X_WG))


def _surface_points(part, n_per_axis: int = 3) -> np.ndarray:
    """Points (k, 3) on a primitive's boundary, in its link's frame: box corners and face grid,
    cylinder and capsule rims and caps, sphere poles."""
    if part.kind == "box":
        g = [np.linspace(-d / 2, d / 2, n_per_axis) for d in part.dims]
        P = np.array(np.meshgrid(*g, indexing="ij")).reshape(3, -1).T
    else:
        r = part.dims[0]
        half = part.dims[1] / 2 if part.kind != "sphere" else 0.0
        a = np.linspace(0, 2 * np.pi, 12, endpoint=False)
        ring = np.column_stack([r * np.cos(a), r * np.sin(a)])
        P = np.vstack([np.column_stack([ring, np.full(12, z)]) for z in (-half, 0.0, half)])
        if part.kind in ("capsule", "sphere"):
            P = np.vstack([P, [[0, 0, half + r], [0, 0, -half - r]]])
    return P @ part.X_LS[:3, :3].T + part.X_LS[:3, 3]


def _random_segments(robot, rng, n):
    """Half long (uniform ends in the limits), half short (a few hundredths of a rad) segments."""
    lo, hi = robot.lower_rad, robot.upper_rad
    a = rng.uniform(lo, hi, (n, 7))
    b = rng.uniform(lo, hi, (n, 7))
    short = np.arange(n) % 2 == 1
    b[short] = np.clip(a[short] + rng.normal(0, 0.03, (short.sum(), 7)), lo, hi)
    return a, b


def test_point_axis_radii_bound_the_distance_to_every_axis():
    world = _holding_world()
    robot = world.robot
    rng = np.random.default_rng(7)
    Q = robot.random_configurations(rng, 2000)
    X = robot.link_poses(Q)
    for part in world.parts:
        P = _surface_points(part)
        r = np.array([point_axis_radii(robot, p, part.link) for p in P])  # (k, 7)
        X_WL = X[:, part.link]
        p_W = np.einsum("mij,kj->mki", X_WL[:, :3, :3], P) + X_WL[:, None, :3, 3]
        for j in range(1, part.link + 1):
            o, z = X[:, j, :3, 3], X[:, j, :3, 2]
            v = p_W - o[:, None]
            dist = np.linalg.norm(v - np.einsum("mki,mi->mk", v, z)[..., None] * z[:, None], axis=-1)
            assert np.all(dist <= r[None, :, j - 1] + 1e-9), (part.name, j)


def test_lambda_bounds_the_motion_of_every_collision_body():
    """On 10,000 random segments, no sampled point of any body of a counted pair (links, gripper,
    fingers, held can) moves farther than the pair's lambda: relative to the world for a scene
    pair, relative to the lower body's link for a self pair."""
    world = _holding_world()
    cert = certifier(world)
    robot = world.robot
    rng = np.random.default_rng(2024)
    a, b = _random_segments(robot, rng, LAMBDA_SEGMENTS)
    ts = np.linspace(0.0, 1.0, 9)
    _, _, Da = cert._evaluate(a)
    _, _, Db = cert._evaluate(b)
    dq = np.abs(b - a)
    P = cert._reach(dq, Da, Db)
    X = robot.link_poses(a[:, None, :] + ts[None, :, None] * (b - a)[:, None, :])  # (n, T, 9, 4, 4)
    names = {p.name for p in world.parts}
    assert {"held_can", "left_finger", "right_finger", "body"} <= names
    seen, moved_by = set(), {}
    for k in range(len(world._pp_part)):
        i = world._pp_part[k]
        j, other = world._pp_other[k]
        if other is None:
            lo, moving = sorted((i, j), key=lambda x: world.parts[x].link)
            base = world.parts[lo].link
        else:
            moving, base = i, 0
        part = world.parts[moving]
        if (moving, base) not in moved_by:
            pts = _surface_points(part)
            X_BL = np.linalg.inv(X[:, :, base]) @ X[:, :, part.link]  # the moving link in the base link
            p = np.matmul(X_BL[..., :3, :3], pts.T) + X_BL[..., :3, 3:]  # (n, T, 3, k)
            p -= p[:, :1]
            moved_by[(moving, base)] = np.sqrt(np.max(np.sum(p * p, axis=2), axis=(1, 2)))  # (n,)
        moved = moved_by[(moving, base)]
        lam = cert._pair_lambdas(np.arange(len(a)), np.full(len(a), k), dq, P)
        assert np.all(np.isfinite(lam)) and np.all(moved <= lam + 1e-9), (cert._names[k], float(np.max(moved - lam)))
        seen.add(part.name)
    assert {"held_can", "left_finger", "body", "iiwa_link_7"} <= seen


def test_a_sweep_through_the_wall_is_a_collision_with_its_pair_and_depth():
    world = _holding_world()
    c = certifier(world).certify(np.array([Q_PLATE_SIDE, Q_BIN_SIDE]))
    assert c.verdict == COLLISION
    d = c.detail
    assert d["segment"] == 0 and 0.0 < d["t"] < 1.0
    assert "wall" in d["pair"][1] and d["penetration_m"] >= 0.0
    assert not world.is_free(np.array(d["q"]))


def test_a_motion_in_free_space_is_certified_with_fewer_states_than_the_fixed_step():
    world = _holding_world()
    path = np.array([Q_READY, Q_RAISED])
    assert world.path_free(path, resolution_rad=0.01) < 0
    c = certifier(world).certify(path)
    assert c.verdict == CERTIFIED
    assert c.states < len(world.interpolate(path, 0.01))


def test_a_repeated_waypoint_is_a_zero_length_segment_proved_free():
    world = _holding_world()
    cert = certifier(world)
    c = cert.certify(np.array([Q_READY, Q_READY, Q_RAISED, Q_RAISED]))
    assert c.verdict == CERTIFIED and c.segments == 3
    # a zero-length segment moves nothing: every pair's lambda is exactly 0 (not NaN)
    _, _, D = cert._evaluate(Q_READY[None])
    P = cert._reach(np.zeros((1, 7)), D, D)
    n_pp = len(world._pp_part)
    lam = cert._pair_lambdas(np.zeros(n_pp, int), np.arange(n_pp), np.zeros((1, 7)), P)
    assert np.array_equal(lam, np.zeros(n_pp))


def test_a_spent_state_budget_is_unproved_never_certified():
    world = _holding_world()
    c = certifier(world).certify(np.array([Q_READY, Q_RAISED]), max_states=2)
    assert c.verdict == UNPROVED and "budget" in c.detail["why"]


@pytest.fixture(scope="module")
def quick_references():
    from suite.problems.dataset import load_dataset

    ds = load_dataset("recycle-v2:quick")
    return [(p, ds.references[pid]) for pid, p in zip(ds.ids, ds.problems) if not ds.meta[pid]["trivial"]]


def test_verdicts_agree_with_a_ten_times_finer_fixed_step(quick_references):
    """recycle-v2's quick references all pass the 0.01 rad rule; some cut corners between its
    samples. No certified path collides at 0.001 rad, and every one that does is found."""
    from planners.worlds import collision_world

    verdicts = []
    for problem, path in quick_references:
        world = collision_world(problem)
        assert world.path_free(path, resolution_rad=0.01) < 0
        c = certifier(world).certify(path)
        fine_collides = world.path_free(path, resolution_rad=0.001) >= 0
        if c.verdict == CERTIFIED:
            assert not fine_collides
        if fine_collides:
            assert c.verdict == COLLISION
        if c.verdict == COLLISION:
            assert c.detail["penetration_m"] == 0.0 or not world.is_free(np.array(c.detail["q"]))
        verdicts.append(c.verdict)
    assert verdicts.count(COLLISION) >= 5 and verdicts.count(CERTIFIED) >= 30


def test_every_reference_of_the_default_tier_is_certified():
    from planners.worlds import collision_world
    from suite.problems import DEFAULT_TIER
    from suite.problems.dataset import load_dataset

    ds = load_dataset(DEFAULT_TIER)
    bad = [pid for pid, p in zip(ds.ids, ds.problems)
           if certifier(collision_world(p)).certify(ds.references[pid]).verdict != CERTIFIED]
    assert not bad, f"{len(bad)} of {len(ds.ids)} references of {DEFAULT_TIER} are not certified: {bad[:3]}"
