"""Seed-driven scene generation: a station (drawn for a family), then N cans on the plate, all apart
from each other and from the obstacles, and all graspable."""

from __future__ import annotations

import dataclasses
import functools
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
MAX_STATION_DRAWS = 30


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
    """A can at least min_gap from the others and the drawn obstacles, or None if random draws
    found no room."""
    r, h = spec.can.radius_m, spec.can.height_m
    for _ in range(MAX_PLACEMENT_TRIES):
        can = _sample_can(rng, spec, can_id, lying)
        if can is None:
            continue
        if not (all(_far_enough(can, o, r, h, spec.cans.min_gap_m) for o in others) and _clear_of_extras(can, spec)):
            continue
        if spec.cans.placement == "pickable" and not _gripper_clear(can, others, spec):
            continue
        return can
    return None


@functools.lru_cache(maxsize=4)
def _gripper_parts(open_width_m: float) -> tuple:
    """The open gripper's primitives and link 7's (rigid with it) in the gripper frame G:
    (kind, dims, X_GS). Parsed once per process, not once per candidate can."""
    from scenes.robot_model import load_robot

    robot = load_robot()
    finger_X = robot.finger_offsets(open_width_m)
    X_G7 = np.linalg.inv(robot.X_7G)  # link 7 is rigid with the gripper; its shapes reach the tall distractors
    return tuple((s.kind, s.dims, (X_G7 if s.body == "iiwa_link_7" else finger_X.get(s.body, np.eye(4))) @ s.X_BS)
                 for s in robot.shapes if s.body in ("iiwa_link_7", "body", "left_finger", "right_finger"))


def _gripper_clear(can: CanPose, others, spec: SceneSpec) -> bool:
    """The open gripper (with link 7, rigid with it) descending from the can's pre-grasp to its
    grasp (the grasp rule's poses) touches neither the other cans nor the drawn obstacles."""
    import fcl

    from scenes.fcl_shapes import fcl_geometry
    from scenes.grasp_rule import truth_grasp

    g = truth_grasp(Scene(spec, 0, (can,)), can)
    parts = _gripper_parts(spec.grasp.open_width_m)
    obstacles = []
    for o in others:
        X = o.X_WC()
        obstacles.append(fcl.CollisionObject(fcl.Cylinder(spec.can.radius_m, spec.can.height_m),
                                             fcl.Transform(X[:3, :3], X[:3, 3])))
    for o in spec.extra:
        X = o.pose()
        obstacles.append(fcl.CollisionObject(fcl_geometry(o.shape, o.size_m), fcl.Transform(X[:3, :3], X[:3, 3])))
    req = fcl.CollisionRequest()
    for s in np.linspace(0.0, 1.0, 4):
        X_WG = g.X_WG.copy()
        X_WG[:3, 3] = (1 - s) * g.X_WG[:3, 3] + s * g.X_WGpre[:3, 3]
        for kind, dims, X_GS in parts:
            X = X_WG @ X_GS
            part = fcl.CollisionObject(fcl_geometry(kind, dims), fcl.Transform(X[:3, :3], X[:3, 3]))
            if any(fcl.collide(part, ob, req, fcl.CollisionResult()) for ob in obstacles):
                return False
    return True


def _clear_of_extras(can: CanPose, spec: SceneSpec) -> bool:
    """The can at least min_gap from every obstacle a family drew (distractors, shelf, walls)."""
    if not spec.extra:
        return True
    import fcl

    from scenes.fcl_shapes import fcl_geometry

    X = can.X_WC()
    obj = fcl.CollisionObject(fcl.Cylinder(spec.can.radius_m, spec.can.height_m), fcl.Transform(X[:3, :3], X[:3, 3]))
    req = fcl.DistanceRequest(enable_signed_distance=True)
    for o in spec.extra:
        Xo = o.pose()
        other = fcl.CollisionObject(fcl_geometry(o.shape, o.size_m), fcl.Transform(Xo[:3, :3], Xo[:3, 3]))
        if float(fcl.distance(obj, other, req, fcl.DistanceResult())) < spec.cans.min_gap_m + 1e-4:
            return False
    return True


def station_unreachable(spec: SceneSpec) -> str | None:
    """Why a drawn station is infeasible, or None: the three task waypoints must have
    collision-free IK solutions, reached one from the other (above the plate with the gripper
    open; middle and above the bin also holding an upright can)."""
    from scenes.drake_scene import build_drake_scene
    from scenes.grasp_rule import truth_grasp, waypoint_pose
    from scenes.ik import Q_READY, PoseIk
    from scenes.scene import HeldCan

    empty = Scene(spec, 0, ())
    rng = np.random.default_rng(0)
    ik = PoseIk(build_drake_scene(empty, mode="plan", cameras=False))
    wp = spec.waypoints
    q = ik.solve(waypoint_pose(wp.above_plate_m), q_seed=Q_READY, rng=rng)
    if q is None:
        return "the waypoint above the plate"
    px, py, _ = spec.plate.center_m
    can = CanPose(0, (px, py, spec.plate_top_z_m + spec.can.height_m / 2), False, 0.0)
    held = HeldCan.from_grasp(can, truth_grasp(Scene(spec, 0, (can,)), can).X_WG)
    ik_held = PoseIk(build_drake_scene(empty, mode="plan", cameras=False,
                                       gripper_opening_m=2 * spec.can.radius_m, held=held))
    for name, p in (("middle", wp.middle_m), ("above the bin", wp.above_bin_m)):
        q = ik_held.solve(waypoint_pose(p), q_seed=q, rng=rng)
        if q is None:
            return f"the {name} waypoint holding a can"
    return None


def draw_feasible_station(spec: SceneSpec, rng: np.random.Generator) -> SceneSpec:
    """A family's concrete station whose waypoints are reachable (drawn again otherwise)."""
    from scenes.families import draw_station

    if spec.family is None:
        return spec
    for _ in range(MAX_STATION_DRAWS):
        drawn = draw_station(spec, rng)
        why = station_unreachable(drawn)
        if why is None:
            return drawn
        log.debug("%s station redrawn: no IK for %s", spec.variant, why)
    raise SuiteError(f"{spec.variant}: no feasible station in {MAX_STATION_DRAWS} draws; widen the family's ranges")


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
    # a dense pickable plate that boxes itself in is better drawn anew with its station
    restarts = MAX_LAYOUT_RESTARTS if spec.cans.placement == "random" else LAYOUTS_PER_DRAW
    for attempt in range(restarts):
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


def unreachable_cans(scene: Scene, *, ids=None) -> list[int]:
    """Ids of cans (of `ids`, all by default) with no collision-free IK solution for their grasp
    or pre-grasp while every can of the scene is on the plate, or whose gripper would touch
    another can or obstacle on the way down from the pre-grasp to the grasp."""
    from scenes.drake_scene import build_drake_scene
    from scenes.grasp_rule import truth_grasp
    from scenes.ik import Q_READY, PoseIk

    ik = None
    bad = []
    for can in scene.cans:
        if ids is not None and can.id not in ids:
            continue
        if not _gripper_clear(can, [c for c in scene.cans if c.id != can.id], scene.spec):
            # the open gripper cannot even reach the grasp from the pre-grasp without touching a
            # neighbour or an obstacle: no IK needed (and a failing IK costs all of its restarts)
            bad.append(can.id)
            continue
        ik = ik or PoseIk(build_drake_scene(scene, mode="plan", cameras=False))
        grasp = truth_grasp(scene, can)
        rng = np.random.default_rng([scene.seed, can.id])
        q_pre = ik.solve(grasp.X_WGpre, q_seed=Q_READY, rng=rng)
        if q_pre is None or ik.solve(grasp.X_WG, q_seed=q_pre, rng=rng) is None:
            bad.append(can.id)
    return bad


def picking_order(scene: Scene) -> tuple[list[int], list[int]]:
    """A picking order in which every can is graspable when its turn comes, and the cans that
    are not graspable in any order.

    Removing a can only frees room, so a can graspable now stays graspable: the cans graspable
    with all others present come first (in id order), then those freed by their removal, and so
    on. On a sparse plate that is simply every can in id order; in clutter a can boxed in by its
    neighbours comes after them.
    """
    order: list[int] = []
    pending = [c.id for c in scene.cans]
    while pending:
        current = scene.without_cans(order)
        bad = unreachable_cans(current, ids=set(pending))
        free = [i for i in pending if i not in bad]
        if not free:
            return order, pending
        order += free
        pending = bad
    return order, []


def generate_scene(spec: SceneSpec, *, seed: int, check_reachable: bool = True) -> Scene:
    """Draw the station (for a family spec) and scatter `spec.cans.count` cans on the plate.

    Every can lies wholly on the plate (with the edge margin), at least `min_gap_m` from every
    other can and from the drawn obstacles, upright or lying with a random yaw; with
    `check_reachable`, every grasp and pre-grasp has a collision-free IK solution (unreachable cans
    are drawn again): with all other cans present for "random" placement (the paper's plate, as
    before families existed), or when the can's turn comes in the order of the ids for "pickable"
    placement (dense plates; see `picking_order`).

    The same seed gives the same scene: all randomness comes from one PCG64 generator.
    """
    rng = np.random.default_rng(seed)
    family = spec
    for draw in range(MAX_STATION_DRAWS):
        spec = draw_feasible_station(family, rng)
        n = spec.cans.count
        bound = capacity_bound(spec)
        if n > bound:
            raise SuiteError(
                f"cans.count = {n} cannot fit on the plate with min_gap_m = {spec.cans.min_gap_m}: "
                f"at most {bound} cans fit"
            )
        try:
            cans = _layout(rng, spec)
            break
        except SuiteError:
            if family.family is None or draw == MAX_STATION_DRAWS - 1:
                raise
            log.debug("seed %d: no room for the cans on drawn station %d; drawn again", seed, draw)
    scene = Scene(spec, seed, tuple(cans))
    if not check_reachable:
        return scene
    for round_ in range(MAX_REACH_ROUNDS):
        if spec.cans.placement == "pickable":
            order, bad = picking_order(scene)
        else:  # the paper's plate: every can graspable with all the others present, in any order
            bad = unreachable_cans(scene)
            order = [c.id for c in scene.cans]
        if not bad:
            # ids follow the picking order, so every user of the scene picks in a feasible order
            return Scene(spec, seed, tuple(dataclasses.replace(cans[i], id=k) for k, i in enumerate(order)))
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
