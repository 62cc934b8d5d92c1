"""Seed-driven scene generation: scatter N cans on the plate, all apart and all graspable."""

from __future__ import annotations

import logging
import math

import numpy as np

from scenes.scene import CanPose, Scene
from scenes.spec import SceneSpec
from scenes.errors import SuiteError

log = logging.getLogger(__name__)

MAX_PLACEMENT_TRIES = 300
MAX_LAYOUT_RESTARTS = 200
LAYOUTS_PER_DRAW = 25
MAX_REACH_ROUNDS = 20


def _footprint_corners(can: CanPose, r: float, h: float) -> np.ndarray:
    """Outline of the can's footprint on the plate as points (a circle or a rectangle)."""
    x, y = can.p_WC_m[:2]
    if not can.lying:
        t = np.linspace(0, 2 * np.pi, 16, endpoint=False)
        return np.column_stack([x + r * np.cos(t), y + r * np.sin(t)])
    a = np.array([math.cos(can.axis_yaw_rad), math.sin(can.axis_yaw_rad)])
    n = np.array([-a[1], a[0]])
    return np.array([[x, y] + sa * h / 2 * a + sn * r * n for sa in (-1, 1) for sn in (-1, 1)])


def _footprint_distance(a: CanPose, b: CanPose, r: float, h: float) -> float:
    """Distance (metres) between two cans' footprints, via python-fcl on their 3D cylinders."""
    import fcl

    objs = []
    for c in (a, b):
        X = c.X_WC()
        objs.append(fcl.CollisionObject(fcl.Cylinder(r, h), fcl.Transform(X[:3, :3], X[:3, 3])))
    req = fcl.DistanceRequest(enable_signed_distance=True)
    return float(fcl.distance(objs[0], objs[1], req, fcl.DistanceResult()))


def capacity_bound(spec: SceneSpec) -> int:
    """An upper bound on how many cans fit on the plate with the required gap (area argument)."""
    sx, sy = spec.plate.size_m[:2]
    m = spec.cans.edge_margin_m
    usable = max(sx - 2 * m, 0) * max(sy - 2 * m, 0)
    r = spec.can.radius_m + spec.cans.min_gap_m / 2
    return int(usable / (math.pi * r * r))


def _sample_can(rng: np.random.Generator, spec: SceneSpec, can_id: int, lying: bool) -> CanPose | None:
    r, h = spec.can.radius_m, spec.can.height_m
    yaw = float(rng.uniform(-math.pi, math.pi))
    cx, cy, _ = spec.plate.center_m
    sx, sy = spec.plate.size_m[:2]
    x = float(rng.uniform(cx - sx / 2, cx + sx / 2))
    y = float(rng.uniform(cy - sy / 2, cy + sy / 2))
    z = spec.plate_top_z_m + (r if lying else h / 2)
    can = CanPose(can_id, (x, y, z), lying, yaw)
    pts = _footprint_corners(can, r, h)
    m = spec.cans.edge_margin_m
    if (
        pts[:, 0].min() < cx - sx / 2 + m
        or pts[:, 0].max() > cx + sx / 2 - m
        or pts[:, 1].min() < cy - sy / 2 + m
        or pts[:, 1].max() > cy + sy / 2 - m
    ):
        return None
    return can


def _place(rng, spec, can_id, others, lying: bool) -> CanPose | None:
    """A can at least min_gap from the others, or None if random draws found no room."""
    r, h = spec.can.radius_m, spec.can.height_m
    for _ in range(MAX_PLACEMENT_TRIES):
        can = _sample_can(rng, spec, can_id, lying)
        if can is None:
            continue
        if all(_far_enough(can, o, r, h, spec.cans.min_gap_m) for o in others):
            return can
    return None


def _far_enough(a: CanPose, b: CanPose, r: float, h: float, gap: float) -> bool:
    """Footprints at least `gap` apart; circle bounds settle most pairs without FCL."""
    d = math.dist(a.p_WC_m[:2], b.p_WC_m[:2])
    outer = [math.hypot(h / 2, r) if c.lying else r for c in (a, b)]
    if d >= outer[0] + outer[1] + gap:
        return True
    if d < 2 * r + gap:  # each footprint contains the disc of radius r about its centre
        return False
    return _footprint_distance(a, b, r, h) >= gap


def _cannot_place(spec) -> SuiteError:
    return SuiteError(
        f"cannot place {spec.cans.count} cans on the plate {spec.plate.size_m[:2]} m at least "
        f"{spec.cans.min_gap_m} m apart (field 'cans.count'); try fewer cans or a smaller gap"
    )


def _layout(rng, spec) -> list[CanPose]:
    """All cans placed one after another; a layout that boxes itself in is drawn again.

    Which cans lie is drawn before any position: redrawing it with every rejected position would
    favour upright cans, whose smaller footprints are rejected less often. Lying cans (the larger
    footprints) are placed first. Only when random packing fails LAYOUTS_PER_DRAW times in a row
    for one draw (many lying cans on a small plate) is it drawn again.
    """
    n = spec.cans.count
    for attempt in range(MAX_LAYOUT_RESTARTS):
        if attempt % LAYOUTS_PER_DRAW == 0:
            lying = rng.random(n) < spec.cans.lying_probability
            order = sorted(range(n), key=lambda i: not lying[i])
        placed: dict[int, CanPose] = {}
        for i in order:
            can = _place(rng, spec, i, list(placed.values()), bool(lying[i]))
            if can is None:
                break
            placed[i] = can
        else:
            return [placed[i] for i in range(n)]
    raise _cannot_place(spec)


def unreachable_cans(scene: Scene) -> list[int]:
    """Ids of cans with no collision-free IK solution for their grasp or pre-grasp."""
    from scenes.drake_scene import build_drake_scene
    from scenes.grasp_rule import truth_grasp
    from scenes.ik import Q_READY, PoseIk

    ds = build_drake_scene(scene, mode="plan", cameras=False)
    ik = PoseIk(ds)
    bad = []
    for can in scene.cans:
        grasp = truth_grasp(scene, can)
        rng = np.random.default_rng([scene.seed, can.id])
        q_pre = ik.solve(grasp.X_WGpre, q_seed=Q_READY, rng=rng)
        if q_pre is None or ik.solve(grasp.X_WG, q_seed=q_pre, rng=rng) is None:
            bad.append(can.id)
    return bad


def generate_scene(spec: SceneSpec, *, seed: int, check_reachable: bool = True) -> Scene:
    """Scatter `spec.cans.count` cans on the plate.

    Every can lies wholly on the plate (with the edge margin), at least `min_gap_m` from every
    other can, upright or lying with a random yaw; with `check_reachable`, every grasp and
    pre-grasp has a collision-free IK solution (unreachable cans are drawn again).

    The same seed gives the same scene: all randomness comes from one PCG64 generator.
    """
    n = spec.cans.count
    bound = capacity_bound(spec)
    if n > bound:
        raise SuiteError(
            f"cans.count = {n} cannot fit on the plate with min_gap_m = {spec.cans.min_gap_m}: "
            f"at most {bound} cans fit"
        )
    rng = np.random.default_rng(seed)
    cans = _layout(rng, spec)
    scene = Scene(spec, seed, tuple(cans))
    if not check_reachable:
        return scene
    for round_ in range(MAX_REACH_ROUNDS):
        bad = unreachable_cans(scene)
        if not bad:
            return scene
        log.debug("seed %d round %d: redrawing unreachable cans %s", seed, round_, bad)
        for i in bad:
            others = [c for c in cans if c.id != i]
            can = _place(rng, spec, i, others, cans[i].lying)
            if can is None:
                cans = _layout(rng, spec)
                break
            cans[i] = can
        scene = Scene(spec, seed, tuple(cans))
    raise SuiteError(f"seed {seed}: could not draw {n} reachable cans in {MAX_REACH_ROUNDS} rounds")
