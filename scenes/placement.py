"""Where cans may stand on the plate: apart from each other by the spec's gap, clear of the
station's obstacles, and with room for the open gripper to come down on them (`pickable` plates).
Seed-driven: every draw comes from the generator it is given (`scenes.generate` owns the seed)."""

from __future__ import annotations

import functools
import math

import numpy as np

from scenes.errors import SuiteError
from scenes.scene import CanPose, Scene
from scenes.spec import SceneSpec

MAX_PLACEMENT_TRIES = 300
MAX_LAYOUT_RESTARTS = 200
LAYOUTS_PER_DRAW = 25
#: Layouts a dense ("pickable") plate may try on one drawn station before the station is drawn
#: again: a station that boxed in 10 random packings is cheaper to redraw than to pack 15 more times.
PICKABLE_LAYOUTS = 10


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

    req = fcl.DistanceRequest(enable_signed_distance=True)
    return float(fcl.distance(_can_object(a, r, h)[0], _can_object(b, r, h)[0], req, fcl.DistanceResult()))


def capacity_bound(spec: SceneSpec) -> int:
    """An upper bound on how many cans fit on the plate with the required gap (area argument)."""
    sx, sy = spec.plate.size_m[:2]
    m = spec.cans.edge_margin_m
    usable = max(sx - 2 * m, 0) * max(sy - 2 * m, 0)
    r = spec.can.radius_m + spec.cans.min_gap_m / 2
    return int(usable / (math.pi * r * r))


#: The points outlining an upright can's footprint (see `_footprint_corners`), as unit offsets.
_CIRCLE_T = np.linspace(0, 2 * np.pi, 16, endpoint=False)
_CIRCLE_COS = (float(np.cos(_CIRCLE_T).min()), float(np.cos(_CIRCLE_T).max()))
_CIRCLE_SIN = (float(np.sin(_CIRCLE_T).min()), float(np.sin(_CIRCLE_T).max()))


def _footprint_bounds(x: float, y: float, lying: bool, yaw: float, r: float, h: float) -> tuple[float, ...]:
    """(x min, x max, y min, y max) of `_footprint_corners`, with the same floating-point values:
    scalar arithmetic in numpy's order of operations, without building the arrays (an upright
    outline's extremes are at the extreme unit offsets: rounding is monotonic)."""
    if not lying:
        return (x + r * _CIRCLE_COS[0], x + r * _CIRCLE_COS[1], y + r * _CIRCLE_SIN[0], y + r * _CIRCLE_SIN[1])
    a0, a1 = math.cos(yaw), math.sin(yaw)
    n0, n1 = -a1, a0
    xs, ys = [], []
    for sa in (-1, 1):
        for sn in (-1, 1):
            k, m = sa * h / 2, sn * r
            xs.append(x + k * a0 + m * n0)
            ys.append(y + k * a1 + m * n1)
    return min(xs), max(xs), min(ys), max(ys)


def _sample_can(rng: np.random.Generator, spec: SceneSpec, can_id: int, lying: bool) -> CanPose | None:
    r, h = spec.can.radius_m, spec.can.height_m
    yaw = float(rng.uniform(-math.pi, math.pi))
    cx, cy, _ = spec.plate.center_m
    sx, sy = spec.plate.size_m[:2]
    x = float(rng.uniform(cx - sx / 2, cx + sx / 2))
    y = float(rng.uniform(cy - sy / 2, cy + sy / 2))
    x_lo, x_hi, y_lo, y_hi = _footprint_bounds(x, y, lying, yaw, r, h)
    m = spec.cans.edge_margin_m
    if x_lo < cx - sx / 2 + m or x_hi > cx + sx / 2 - m or y_lo < cy - sy / 2 + m or y_hi > cy + sy / 2 - m:
        return None
    z = spec.plate_top_z_m + (r if lying else h / 2)
    return CanPose(can_id, (x, y, z), lying, yaw)


def place(rng, spec, can_id, others, lying: bool) -> CanPose | None:
    """A can at least min_gap from the others and the drawn obstacles, or None if random draws
    found no room."""
    r, h = spec.can.radius_m, spec.can.height_m
    for _ in range(MAX_PLACEMENT_TRIES):
        can = _sample_can(rng, spec, can_id, lying)
        if can is None:
            continue
        if not (all(_far_enough(can, o, r, h, spec.cans.min_gap_m) for o in others) and _clear_of_extras(can, spec)):
            continue
        if spec.cans.placement == "pickable" and not gripper_clear(can, others, spec):
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


#: Two shapes whose bounding boxes are this far apart (metres) are decided without FCL: far above
#: FCL's numerical error, so a skipped query could only have given the same answer.
_AABB_SLACK_M = 1e-3


#: The last stations' obstacle data, by the identity of their `extra` tuple (hashing the tuple of
#: obstacles costs more than the checks themselves); each entry keeps its tuple alive.
_EXTRAS_BY_ID: dict[int, tuple] = {}


def _extras(spec: SceneSpec) -> tuple:
    """(FCL objects with boxes, float boxes) of the spec's drawn obstacles, made once per station."""
    hit = _EXTRAS_BY_ID.get(id(spec.extra))
    if hit is None or hit[0] is not spec.extra:
        if len(_EXTRAS_BY_ID) >= 64:
            _EXTRAS_BY_ID.clear()
        hit = (spec.extra, _extra_objects(spec.extra), _extra_boxes(spec.extra))
        _EXTRAS_BY_ID[id(spec.extra)] = hit
    return hit[1], hit[2]


def _extra_objects(extra: tuple) -> tuple:
    """The drawn obstacles as (FCL object, box centre, box half extents)."""
    import fcl

    from scenes.collision.shapes import aabb_half_extents, fcl_geometry

    out = []
    for o in extra:
        X = o.pose()
        obj = fcl.CollisionObject(fcl_geometry(o.shape, o.size_m), fcl.Transform(X[:3, :3], X[:3, 3]))
        out.append((obj, X[:3, 3].copy(), aabb_half_extents(o.shape, o.size_m, X[:3, :3])))
    return tuple(out)


@functools.lru_cache(maxsize=4096)
def _can_object(can: CanPose, r: float, h: float) -> tuple:
    """A can as (FCL object, box centre, box half extents); cached, as a placed can is checked
    against every candidate after it (FCL objects are not changed by queries)."""
    import fcl

    X = can.X_WC()
    obj = fcl.CollisionObject(fcl.Cylinder(r, h), fcl.Transform(X[:3, :3], X[:3, 3]))
    return obj, X[:3, 3].copy(), _can_half_extents(can, r, h)


def _can_half_extents(can: CanPose, r: float, h: float) -> np.ndarray:
    """Half extents of the world-axis-aligned box around a can (its axis vertical or horizontal)."""
    if not can.lying:
        return np.array([r, r, h / 2])
    c, s = abs(math.cos(can.axis_yaw_rad)), abs(math.sin(can.axis_yaw_rad))
    return np.array([c * h / 2 + s * r, s * h / 2 + c * r, r])


@functools.lru_cache(maxsize=4)
def _gripper_geometry(open_width_m: float) -> tuple:
    """`_gripper_parts` with each part's FCL geometry, made once."""
    from scenes.collision.shapes import fcl_geometry

    return tuple((kind, dims, X_GS, fcl_geometry(kind, dims)) for kind, dims, X_GS in _gripper_parts(open_width_m))


def gripper_clear(can: CanPose, others, spec: SceneSpec) -> bool:
    """The open gripper (with link 7, rigid with it) descending from the can's pre-grasp to its
    grasp (the grasp rule's poses) touches neither the other cans nor the drawn obstacles.

    The descent is a vertical translation: a (part, obstacle) pair whose bounding boxes stay
    clearly apart over the whole descent cannot touch, and FCL is asked only about the others
    (the same answer, fewer queries)."""
    import fcl

    from scenes.collision.shapes import aabb_half_extents
    from scenes.grasp_rule import truth_grasp

    r, h = spec.can.radius_m, spec.can.height_m
    obstacles = [_can_object(o, r, h) for o in others] + list(_extras(spec)[0])
    if not obstacles:
        return True
    g = truth_grasp(Scene(spec, 0, (can,)), can)
    centres = np.array([c for _, c, _ in obstacles])
    halves = np.array([hh for _, _, hh in obstacles])
    rise = g.X_WGpre[:3, 3] - g.X_WG[:3, 3]
    req = fcl.CollisionRequest()
    poses = []
    for s in np.linspace(0.0, 1.0, 4):
        X_WG = g.X_WG.copy()
        X_WG[:3, 3] = (1 - s) * g.X_WG[:3, 3] + s * g.X_WGpre[:3, 3]
        poses.append(X_WG)
    for kind, dims, X_GS, geometry in _gripper_geometry(spec.grasp.open_width_m):
        X0 = g.X_WG @ X_GS
        half = aabb_half_extents(kind, dims, X0[:3, :3]) + np.abs(rise) / 2  # the box swept by the descent
        near = ~np.any(np.abs(centres - (X0[:3, 3] + rise / 2)) - halves - half > _AABB_SLACK_M, axis=1)
        for k in np.flatnonzero(near):
            for X_WG in poses:
                X = X_WG @ X_GS
                part = fcl.CollisionObject(geometry, fcl.Transform(X[:3, :3], X[:3, 3]))
                if fcl.collide(part, obstacles[k][0], req, fcl.CollisionResult()):
                    return False
    return True


def _extra_boxes(extra: tuple) -> tuple:
    """The drawn obstacles' bounding boxes as float tuples (centre, half extents), and for an
    upright prism (a cylinder with a vertical axis, a box turned about z only) its footprint's
    centre, the radii of the discs around and within the footprint, and its height range."""
    from scenes.collision.shapes import aabb_half_extents

    out = []
    for o in extra:
        X = o.pose()
        box = (*map(float, X[:3, 3]), *map(float, aabb_half_extents(o.shape, o.size_m, X[:3, :3])))
        prism = None
        if abs(abs(X[2, 2]) - 1.0) < 1e-12 and o.shape in ("cylinder", "box"):
            if o.shape == "cylinder":
                r_out = r_in = float(o.size_m[0])
                half_z = float(o.size_m[1]) / 2
            else:
                r_out, r_in = math.hypot(o.size_m[0], o.size_m[1]) / 2, min(o.size_m[0], o.size_m[1]) / 2
                half_z = float(o.size_m[2]) / 2
            prism = (float(X[0, 3]), float(X[1, 3]), r_out, r_in, float(X[2, 3]) - half_z, float(X[2, 3]) + half_z)
        out.append((box, prism))
    return tuple(out)


def _clear_of_extras(can: CanPose, spec: SceneSpec) -> bool:
    """The can at least min_gap from every obstacle a family drew (distractors, shelf, walls).

    FCL measures only what cheaper bounds leave open: an obstacle whose bounding box is clearly
    farther than the gap is far enough; for an upright prism, the distance of the footprints
    (which the 3D distance is at least) is at least that of the stadium around the can's and
    the disc around the obstacle's, and, when both have full cross-sections at one height, the
    3D distance is at most that of the stadium within the can's footprint and the disc within
    the obstacle's. Each bound decides only when clearly (_AABB_SLACK_M) on one side of the gap."""
    if not spec.extra:
        return True
    import fcl

    r, h = spec.can.radius_m, spec.can.height_m
    need = spec.cans.min_gap_m + 1e-4
    x, y, z = can.p_WC_m
    hx, hy, hz = map(float, _can_half_extents(can, r, h))
    # only the cross-section through a lying can's axis is its whole footprint
    z_lo, z_hi = (z, z) if can.lying else (z - h / 2, z + h / 2)
    outer = inner = None
    obj = None
    req = None
    for (other, _, _), ((ox, oy, oz, ohx, ohy, ohz), prism) in zip(*_extras(spec)):
        dx = max(abs(x - ox) - hx - ohx, 0.0)
        dy = max(abs(y - oy) - hy - ohy, 0.0)
        dz = max(abs(z - oz) - hz - ohz, 0.0)
        if math.sqrt(dx * dx + dy * dy + dz * dz) >= need + _AABB_SLACK_M:
            continue  # the boxes are farther apart than needed: so are the shapes
        if prism is not None:
            px, py, r_out, r_in, p_lo, p_hi = prism
            outer = outer or _core(can, r, h, False)
            if _point_segment((px, py), *outer) - r - r_out >= need + _AABB_SLACK_M:
                continue
            if r <= h / 2 and p_lo <= z_hi and z_lo <= p_hi:
                inner = inner or _core(can, r, h, True)
                if _point_segment((px, py), *inner) - r - r_in < need - _AABB_SLACK_M:
                    return False
        if obj is None:
            obj = _can_object(can, r, h)[0]
            req = fcl.DistanceRequest(enable_signed_distance=True)
        if float(fcl.distance(obj, other, req, fcl.DistanceResult())) < need:
            return False
    return True


def _core(can: CanPose, r: float, h: float, shrink: bool) -> tuple:
    """The 2D segment (two points) whose r-neighbourhood bounds the can's footprint: from outside
    (the axis, for a lying can; the centre, for an upright one), or from inside with `shrink`
    (the axis shortened by r at each end: the footprint rectangle holds that stadium)."""
    x, y = can.p_WC_m[0], can.p_WC_m[1]
    if not can.lying:
        return (x, y), (x, y)
    k = h / 2 - (r if shrink else 0.0)
    c, s = math.cos(can.axis_yaw_rad), math.sin(can.axis_yaw_rad)
    return (x - k * c, y - k * s), (x + k * c, y + k * s)


def _point_segment(p, a, b) -> float:
    ux, uy = b[0] - a[0], b[1] - a[1]
    L2 = ux * ux + uy * uy
    t = 0.0 if L2 == 0.0 else min(1.0, max(0.0, ((p[0] - a[0]) * ux + (p[1] - a[1]) * uy) / L2))
    return math.hypot(p[0] - a[0] - t * ux, p[1] - a[1] - t * uy)


def _segment_distance(a, b, c, d) -> float:
    """Distance between the 2D segments ab and cd."""
    def cross(o, p, q):
        return (p[0] - o[0]) * (q[1] - o[1]) - (p[1] - o[1]) * (q[0] - o[0])

    d1, d2, d3, d4 = cross(c, d, a), cross(c, d, b), cross(a, b, c), cross(a, b, d)
    if ((d1 > 0 > d2) or (d1 < 0 < d2)) and ((d3 > 0 > d4) or (d3 < 0 < d4)):
        return 0.0  # they cross
    return min(_point_segment(a, c, d), _point_segment(b, c, d), _point_segment(c, a, b), _point_segment(d, a, b))


def _far_enough(a: CanPose, b: CanPose, r: float, h: float, gap: float) -> bool:
    """Footprints at least `gap` apart; circle bounds settle most pairs without FCL, and bounds
    from the stadiums around and within each footprint most others (their distance, the 3D one
    for cans on one plane, is taken to FCL only when the bounds are within _AABB_SLACK_M of the gap)."""
    d = math.dist(a.p_WC_m[:2], b.p_WC_m[:2])
    outer = [math.hypot(h / 2, r) if c.lying else r for c in (a, b)]
    if d >= outer[0] + outer[1] + gap:
        return True
    if d < 2 * r + gap:  # each footprint contains the disc of radius r about its centre
        return False
    # the 3D distance is at least the footprints' (projection), which is at least the outer stadiums'
    if _segment_distance(*_core(a, r, h, False), *_core(b, r, h, False)) - 2 * r >= gap + _AABB_SLACK_M:
        return True
    bottoms = [c.p_WC_m[2] - (r if c.lying else h / 2) for c in (a, b)]
    # on one plane, it is at most the distance of the cross-sections at the lying axes' height,
    # the footprints, which is at most the inner stadiums'
    if r <= h / 2 and abs(bottoms[0] - bottoms[1]) < 1e-9 and \
            _segment_distance(*_core(a, r, h, True), *_core(b, r, h, True)) - 2 * r < gap - _AABB_SLACK_M:
        return False
    return _footprint_distance(a, b, r, h) >= gap


def _cannot_place(spec) -> SuiteError:
    return SuiteError(
        f"cannot place {spec.cans.count} cans on the plate {spec.plate.size_m[:2]} m at least "
        f"{spec.cans.min_gap_m} m apart (field 'cans.count'); try fewer cans or a smaller gap"
    )


def layout(rng, spec) -> list[CanPose]:
    """All cans placed one after another; a layout that boxes itself in is drawn again.

    Which cans lie is drawn before any position: redrawing it with every rejected position would
    favour upright cans, whose smaller footprints are rejected less often. Lying cans (the larger
    footprints) are placed first. Only when random packing fails LAYOUTS_PER_DRAW times in a row
    for one draw (many lying cans on a small plate) is it drawn again.
    """
    n = spec.cans.count
    # a dense pickable plate that boxes itself in is better drawn anew with its station
    restarts = MAX_LAYOUT_RESTARTS if spec.cans.placement == "random" else PICKABLE_LAYOUTS
    for attempt in range(restarts):
        if attempt % LAYOUTS_PER_DRAW == 0:
            lying = rng.random(n) < spec.cans.lying_probability
            order = sorted(range(n), key=lambda i: not lying[i])
        placed: dict[int, CanPose] = {}
        for i in order:
            can = place(rng, spec, i, list(placed.values()), bool(lying[i]))
            if can is None:
                break
            placed[i] = can
        else:
            return [placed[i] for i in range(n)]
    raise _cannot_place(spec)
