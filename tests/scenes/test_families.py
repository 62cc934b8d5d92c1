"""Scene families: drawn stations are deterministic, feasible and within their ranges."""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from scenes.errors import SuiteError
from scenes.generate import generate_scene, picking_order, station_unreachable
from scenes.spec import load_spec, loads_spec, spec_from_dict
from scenes.spec import DEFAULT_SPEC_PATH

FAMILIES = ("station", "shelf", "window", "clutter", "lookalike")


@functools.lru_cache(maxsize=None)
def family_scene(family: str, seed: int):
    spec = load_spec(variant=family)
    if family in ("clutter", "lookalike"):
        spec = spec.with_can_count(6)  # dense, but fewer cans keep the test fast
    return generate_scene(spec.with_can_count(spec.cans.count if family in ("clutter", "lookalike") else 3), seed=seed)


@pytest.mark.parametrize("family", FAMILIES)
def test_same_seed_same_station(family):
    a = family_scene(family, 4242)
    spec = load_spec(variant=family)
    b = generate_scene(spec.with_can_count(6 if family in ("clutter", "lookalike") else 3), seed=4242)
    assert a.key() == b.key() and a.to_json() == b.to_json()


@pytest.mark.parametrize("family", FAMILIES)
def test_station_is_feasible_and_cans_pickable_in_id_order(family):
    scene = family_scene(family, 4243)
    assert scene.spec.family is None and scene.variant == family
    assert station_unreachable(scene.spec) is None
    order, bad = picking_order(scene)
    assert bad == [] and order == sorted(order)


@pytest.mark.parametrize("family", FAMILIES)
def test_everything_on_the_table_and_cans_apart_from_obstacles(family):
    import fcl

    from scenes.collision.shapes import fcl_geometry

    scene = family_scene(family, 4244)
    spec = scene.spec
    tx, ty, _ = spec.table.center_m
    sx, sy, _ = spec.table.size_m
    for o in spec.obstacles():
        p = o.pose()[:3, 3]
        assert abs(p[0] - tx) <= sx / 2 and abs(p[1] - ty) <= sy / 2, o.name
    cx, cy, _ = spec.plate.center_m
    for can in scene.cans:
        assert abs(can.p_WC_m[0] - cx) < spec.plate.size_m[0] / 2 and abs(can.p_WC_m[1] - cy) < spec.plate.size_m[1] / 2
        X = can.X_WC()
        a = fcl.CollisionObject(fcl.Cylinder(spec.can.radius_m, spec.can.height_m), fcl.Transform(X[:3, :3], X[:3, 3]))
        for o in spec.extra:
            Xo = o.pose()
            b = fcl.CollisionObject(fcl_geometry(o.shape, o.size_m), fcl.Transform(Xo[:3, :3], Xo[:3, 3]))
            d = fcl.distance(a, b, fcl.DistanceRequest(enable_signed_distance=True), fcl.DistanceResult())
            assert d >= spec.cans.min_gap_m - 1e-6, (can.id, o.name)


def test_station_draws_the_bin_beside_or_behind_within_ranges():
    r = load_spec(variant="station").family
    turns = []
    for seed in range(5000, 5012):
        from scenes.families import draw_station

        s = draw_station(load_spec(variant="station"), np.random.default_rng(seed))
        p, b = np.asarray(s.plate.center_m[:2]), np.asarray(s.bin.center_xy_m)
        assert r.plate_distance_m[0] - 1e-9 <= np.linalg.norm(p) <= r.plate_distance_m[1] + 1e-9
        assert r.bin_distance_m[0] - 1e-9 <= np.linalg.norm(b) <= r.bin_distance_m[1] + 1e-9
        turn = abs(math.degrees(math.atan2(p[0] * b[1] - p[1] * b[0], p @ b)))
        assert r.bin_turn_deg[0] - 1e-6 <= turn <= 180.0
        turns.append(turn)
        assert s.waypoints.above_plate_m[:2] == s.plate.center_m[:2]
        assert s.cameras.poses["top"].target_m[:2] == s.plate.center_m[:2]
    assert max(turns) > 120  # behind the robot too, not only beside it


def test_clutter_has_distractors_and_dense_cans():
    scene = family_scene("clutter", 4245)
    names = [o.name for o in scene.spec.extra]
    assert sum(n.startswith("distractor_") for n in names) >= 2
    assert scene.spec.cans.min_gap_m <= 0.01 and len(scene.cans) == 6


def test_lookalike_adds_hourglasses_and_dented_cans_and_clutter_keeps_its_scenes():
    from scenes.lookalikes import DENTED_PREFIX, HOURGLASS_PREFIX, HOURGLASS_SECTIONS, groups

    scene = family_scene("lookalike", 4245)
    spec = scene.spec
    r, h, top = spec.can.radius_m, spec.can.height_m, spec.plate_top_z_m
    hours, dents = groups(spec.extra, HOURGLASS_PREFIX), groups(spec.extra, DENTED_PREFIX)
    assert 1 <= len(hours) <= 2 and 1 <= len(dents) <= 2
    for parts in hours.values():
        assert len(parts) == HOURGLASS_SECTIONS and all(o.color_rgba == spec.can.color_rgba for o in parts)
        zs = [(o.pose()[2, 3] - o.size_m[1] / 2, o.pose()[2, 3] + o.size_m[1] / 2) for o in parts]
        assert min(z for z, _ in zs) == pytest.approx(top) and max(z for _, z in zs) == pytest.approx(top + h)
        radii = [o.size_m[0] for o in parts]
        assert radii[0] == radii[-1] == r and min(radii) < 0.6 * r  # a can from above, a waist from the side
    for parts in dents.values():
        assert sum(o.size_m[1] for o in parts) == pytest.approx(h) and max(o.size_m[0] for o in parts) == r
    assert generate_scene(load_spec(variant="clutter"), seed=9318).key() == "36d944ae1a3bdadb"  # as before the lookalike family


def test_scene_json_lists_obstacles_and_waypoints():
    scene = family_scene("window", 4246)
    d = scene.to_json()
    names = {o["name"] for o in d["obstacles"]}
    assert {"table", "plate", "bin_floor", "wall_left", "wall_right", "wall_sill", "wall_lintel"} <= names
    for o in d["obstacles"]:
        assert o["shape"] in ("box", "cylinder", "sphere") and np.asarray(o["X_WO"]).shape == (4, 4)
    assert set(d["waypoints_m"]) == {"above_plate_m", "middle_m", "above_bin_m"}


def test_drawn_spec_round_trips_through_a_dict():
    spec = family_scene("station", 4247).spec
    assert spec_from_dict(spec.to_dict()) == spec


def test_open_and_wall_keep_their_scenes():
    # the fixed variants draw no station: same cans as before families existed (seed 3, wall)
    scene = generate_scene(load_spec(variant="wall"), seed=3, check_reachable=False)
    assert scene.key() == "09abb10890bacd9a"
    # with the reachability check too (a can unreachable among the others is redrawn); the grasp
    # checks' IK changed with recycle-v3 (one random restart, 60 iterations), and this seed with it
    assert generate_scene(load_spec(variant="open"), seed=0).key() == "ddecab0c22573e88"


@pytest.mark.parametrize("edit, field", [
    ("plate_distance_m: [0.55, 0.64]", "plate_distance_m"),
    ("bin_turn_deg: [60, 170]", "bin_turn_deg"),
])
def test_infeasible_range_is_one_line_naming_the_field(edit, field):
    text = DEFAULT_SPEC_PATH.read_text()
    bad = {"plate_distance_m": "plate_distance_m: [0.55, 1.40]", "bin_turn_deg": "bin_turn_deg: [170, 60]"}[field]
    assert edit in text
    with pytest.raises(SuiteError, match=rf"families\.station\.ranges\.{field}") as exc:
        loads_spec(text.replace(edit, bad), variant="station")
    assert "\n" not in str(exc.value)


def test_unknown_range_field_is_named():
    text = DEFAULT_SPEC_PATH.read_text().replace("wall_probability: 0.5", "wall_probability: 0.5\n      wall_colour: 3")
    with pytest.raises(SuiteError, match=r"families\.station\.ranges\.wall_colour' is unknown"):
        loads_spec(text, variant="station")


def _clutter_with(**ranges):
    import dataclasses

    spec = load_spec(variant="clutter")
    return dataclasses.replace(spec, family=dataclasses.replace(spec.family, **ranges))


def test_sometimes_infeasible_range_is_redrawn_deterministically(caplog):
    # gaps above ~0.18 m leave no room for 3 cans on the clutter plate: such draws are drawn again
    spec = _clutter_with(cans=(3, 3), min_gap_m=(0.0, 0.4))
    redrawn = []
    for seed in range(3):
        caplog.clear()
        with caplog.at_level("DEBUG", logger="scenes.generate"):
            scene = generate_scene(spec, seed=seed)
        assert len(scene.cans) == 3 and scene.spec.cans.min_gap_m <= 0.4
        if any("drawn again" in r.getMessage() for r in caplog.records):
            redrawn.append(scene)
    assert redrawn  # the range is sometimes infeasible, and those seeds still give a scene
    assert generate_scene(spec, seed=redrawn[0].seed).key() == redrawn[0].key()  # same seed, same scene


def test_always_infeasible_range_fails_after_bounded_redraws_in_one_line():
    spec = _clutter_with(cans=(3, 3), min_gap_m=(0.3, 0.4))
    with pytest.raises(SuiteError, match=r"clutter seed 0: none of \d+ drawn stations .*families\.clutter\.ranges") as exc:
        generate_scene(spec, seed=0)
    assert "\n" not in str(exc.value)


def test_placement_shortcuts_give_the_plain_answers():
    # bounding-box culling and scalar footprint bounds decide exactly as plain FCL queries on
    # every candidate (cans near the distractors included)
    import fcl

    from scenes.collision.shapes import fcl_geometry
    from scenes.placement import (_clear_of_extras, _far_enough, _footprint_bounds, _footprint_corners,
                                 _footprint_distance, gripper_clear, _gripper_parts, _sample_can)
    from scenes.grasp_rule import truth_grasp
    from scenes.scene import Scene

    spec = family_scene("clutter", 4245).spec
    r, h = spec.can.radius_m, spec.can.height_m

    def obj(kind, dims, X):
        return fcl.CollisionObject(fcl_geometry(kind, dims), fcl.Transform(X[:3, :3], X[:3, 3]))

    def plain_clear_of_extras_in(can, spec):
        req = fcl.DistanceRequest(enable_signed_distance=True)
        return all(fcl.distance(obj("cylinder", (r, h), can.X_WC()), obj(o.shape, o.size_m, o.pose()), req,
                                fcl.DistanceResult()) >= spec.cans.min_gap_m + 1e-4 for o in spec.extra)

    def plain_clear_of_extras(can):
        return plain_clear_of_extras_in(can, spec)

    def plain_gripper_clear(can, others):
        g = truth_grasp(Scene(spec, 0, (can,)), can)
        obstacles = [obj("cylinder", (r, h), o.X_WC()) for o in others]
        obstacles += [obj(o.shape, o.size_m, o.pose()) for o in spec.extra]
        for s in np.linspace(0.0, 1.0, 4):
            X_WG = g.X_WG.copy()
            X_WG[:3, 3] = (1 - s) * g.X_WG[:3, 3] + s * g.X_WGpre[:3, 3]
            for kind, dims, X_GS in _gripper_parts(spec.grasp.open_width_m):
                part = obj(kind, dims, X_WG @ X_GS)
                if any(fcl.collide(part, o, fcl.CollisionRequest(), fcl.CollisionResult()) for o in obstacles):
                    return False
        return True

    rng = np.random.default_rng(7)
    cans = [c for c in (_sample_can(rng, spec, i, bool(rng.random() < 0.5)) for i in range(400)) if c is not None]
    outcomes = set()
    for k, can in enumerate(cans[:150]):
        pts = _footprint_corners(can, r, h)
        assert _footprint_bounds(*can.p_WC_m[:2], can.lying, can.axis_yaw_rad, r, h) == (
            pts[:, 0].min(), pts[:, 0].max(), pts[:, 1].min(), pts[:, 1].max())
        clear = _clear_of_extras(can, spec)
        assert clear == plain_clear_of_extras(can)
        others = cans[k + 1:k + 4]
        free = gripper_clear(can, others, spec)
        assert free == plain_gripper_clear(can, others)
        outcomes.add((clear, free))
    assert len(outcomes) >= 3  # both answers of both checks occurred
    # the footprint bounds against upright prisms, and a board above the plate (shelf)
    for other in (spec, family_scene("shelf", 4244).spec):
        answers = [_clear_of_extras(c, other) for c in cans]
        assert answers == [plain_clear_of_extras_in(c, other) for c in cans]
        assert 0 < sum(answers) < len(answers)
    # can pairs: the stadium bounds decide as the circle bounds and the FCL distance do
    def plain_far_enough(a, b, gap):
        d = math.dist(a.p_WC_m[:2], b.p_WC_m[:2])
        if d >= sum(math.hypot(h / 2, r) if c.lying else r for c in (a, b)) + gap:
            return True
        return d >= 2 * r + gap and _footprint_distance(a, b, r, h) >= gap

    gaps = {}
    for a in cans[:60]:
        for b in cans[60:120]:
            for gap in (0.0, 0.005, 0.03):
                far = plain_far_enough(a, b, gap)
                assert _far_enough(a, b, r, h, gap) == far
                gaps[far] = gaps.get(far, 0) + 1
    assert min(gaps.values()) > 100
