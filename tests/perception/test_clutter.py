"""Perception among distractors and touching cans (the `clutter` family), and the evaluation's
count of grasps on distractors."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from perception.can_model import lying_strip_fits, top_height_fits
from perception.evaluate import aggregate, distractors_of, match, match_scene, on_distractor
from perception.grasps import CanDetection, PerceptionParams
from perception.pipeline import perceive
from scenes.generate import generate_scene
from scenes.grasp_rule import make_grasp
from scenes.scene import CanPose, Scene
from scenes.spec import load_spec
from scenes.spec_parts import Obstacle, pose_tuple

SPEC = load_spec(variant="open")
R, H = SPEC.can.radius_m, SPEC.can.height_m
TOP = SPEC.plate_top_z_m
CX, CY, _ = SPEC.plate.center_m
SEGMENTATIONS = ("color", "geometric")


def _can(i, x, y, *, lying, yaw=0.0) -> CanPose:
    return CanPose(i, (x, y, TOP + (R if lying else H / 2)), lying, yaw)


def _distractor(i, shape, size, x, y, *, yaw=0.0, color=(0.2, 0.6, 0.3, 1.0)) -> Obstacle:
    height = size[1] if shape == "cylinder" else size[2]
    X = np.eye(4)
    X[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
    X[:3, 3] = (x, y, TOP + height / 2)
    return Obstacle(f"distractor_{i}", shape, tuple(size), pose_tuple(X), color)


def _scene(cans, distractors=()) -> Scene:
    spec = dataclasses.replace(SPEC.with_can_count(len(cans)), extra=tuple(distractors))
    return Scene(spec, 0, tuple(cans))


def _detection(i, x, y) -> CanDetection:
    g = make_grasp(can_id=i, p_xy_m=(x, y), top_z_m=TOP + H, lying=False, axis_yaw_rad=0.0,
                   top_offset_m=SPEC.grasp.top_offset_m, pregrasp_height_m=SPEC.grasp.pregrasp_height_m)
    return CanDetection(i, (x, y, TOP + H / 2), False, 0.0, TOP + H, g, 100, 100)


@pytest.fixture(scope="module")
def clutter_scene():
    # Reachability does not matter to perception: skip the generator's IK check of every grasp.
    return generate_scene(load_spec(variant="clutter").with_can_count(8), seed=4321, check_reachable=False)


@pytest.mark.parametrize("segmentation", SEGMENTATIONS)
def test_clutter_scene_every_can_and_no_distractor(clutter_scene, segmentation):
    assert len(distractors_of(clutter_scene.spec)) >= 2
    res = perceive(clutter_scene, params=PerceptionParams(segmentation=segmentation))
    m = match_scene(res.detections, clutter_scene)
    assert m.distractor_grasps == ()
    assert len(m.pairs) == len(res.detections) == len(clutter_scene.cans) == 8
    assert all(m.kind_correct) and max(m.xy_error_m) < 0.004


@pytest.mark.parametrize("segmentation", SEGMENTATIONS)
def test_distractors_shaped_like_cans_get_no_grasp(segmentation):
    """A bottle as wide as a can, a box as tall as one with a can-sized top, a cup between a lying
    and an upright can's height: none red, so only their shape tells them apart without colour."""
    cans = [_can(0, CX - 0.09, CY - 0.09, lying=False), _can(1, CX + 0.08, CY + 0.09, lying=True, yaw=0.4)]
    distractors = [
        _distractor(0, "cylinder", (R, 0.24), CX - 0.09, CY + 0.06),  # bottle
        _distractor(1, "box", (0.062, 0.058, H), CX + 0.07, CY - 0.08, yaw=0.3),  # box, a can's height
        _distractor(2, "cylinder", (0.045, 0.095), CX + 0.01, CY + 0.01, color=(0.95, 0.95, 0.92, 1.0)),  # cup
    ]
    scene = _scene(cans, distractors)
    res = perceive(scene, params=PerceptionParams(segmentation=segmentation))
    m = match_scene(res.detections, scene)
    assert m.n_distractors == 3 and m.distractor_grasps == ()
    assert len(m.pairs) == len(res.detections) == 2 and all(m.kind_correct)


def test_distractor_grasps_are_counted():
    box = _distractor(0, "box", (0.08, 0.04, 0.1), CX, CY, yaw=math.pi / 4)
    bottle = _distractor(1, "cylinder", (0.03, 0.22), CX + 0.1, CY)
    # the box turned 45 degrees: (CX + 0.025, CY + 0.025) lies on its long axis, 0.035 m from its centre;
    # (CX + 0.035, CY - 0.035) lies across it, 0.0295 m beyond its side
    assert on_distractor((CX + 0.025, CY + 0.025), box, margin_m=0.0)
    assert not on_distractor((CX + 0.035, CY - 0.035), box, margin_m=0.029)
    assert on_distractor((CX + 0.035, CY - 0.035), box, margin_m=0.030)
    can_by_bottle = _can(0, CX + 0.1, CY + 0.03 + R, lying=False)  # touching the bottle
    scene = Scene(dataclasses.replace(SPEC.with_can_count(1), extra=(box, bottle)), 0, (can_by_bottle,))
    dets = [
        _detection(0, CX + 0.1, CY + 0.03 + R),  # the can: a radius from the bottle's footprint
        _detection(1, CX + 0.1, CY + 0.005),  # on the bottle
        _detection(2, CX + 0.01, CY + 0.01),  # on the box
        _detection(3, CX - 0.1, CY - 0.1),  # on nothing
    ]
    m = match_scene(dets, scene)
    assert m.pairs == ((0, 0),)
    assert m.n_distractors == 2
    assert m.distractor_grasps == ((1, "distractor_1"), (2, "distractor_0"))
    # with no distractors given, nothing is on one; other obstacles are no distractors
    assert match(dets, scene.cans, gate_m=R, radius_m=R, height_m=H).distractor_grasps == ()
    wall = dataclasses.replace(box, name="wall")
    assert distractors_of(dataclasses.replace(scene.spec, extra=(wall, bottle))) == (bottle,)
    acc = aggregate([m, m])
    assert acc.distractors == 4 and acc.distractor_grasps == 4
    assert acc.to_json()["distractor_grasps"] == 4
    assert any("grasps on distractors: 4" in line for line in acc.lines())
    assert not any("distractors" in line for line in aggregate([match(dets[:1], scene.cans, gate_m=R, radius_m=R,
                                                                        height_m=H)]).lines())


def test_can_model_heights_and_strips():
    # a lying can's top is 2r above the plate, an upright can's h; a cup's (0.085-0.105 m) is neither
    for z, lying, fits in ((2 * R, True, True), (H, False, True), (0.09, True, False), (0.09, False, False),
                           (0.24, False, False)):
        assert top_height_fits(z, lying=lying, spec=SPEC, tolerance_m=0.01) is fits
    along = np.linspace(-0.055, 0.055, 50)
    strip = np.column_stack([along, 0.01 * np.sin(along * 300)])
    kw = dict(xy=(0.0, 0.0), axis_yaw_rad=0.0, spec=SPEC, tolerance_m=0.005, min_length_fraction=0.75)
    assert lying_strip_fits(strip, **kw)
    assert not lying_strip_fits(strip[:25], **kw)  # half a strip: the grasp would miss the middle
    assert not lying_strip_fits(strip * [2.4, 1.0], **kw)  # two cans end to end
    assert not lying_strip_fits(strip * [1.0, 4.0], **kw)  # wider than a can


@pytest.mark.parametrize("segmentation", SEGMENTATIONS)
def test_lying_cans_touching_end_to_end_are_split(segmentation):
    a = math.radians(25)
    u = np.array([math.cos(a), math.sin(a)])
    p0 = np.array([CX - 0.06, CY - 0.04])
    p1 = p0 + H * u
    scene = _scene([_can(0, *p0, lying=True, yaw=a), _can(1, *p1, lying=True, yaw=a)])
    res = perceive(scene, params=PerceptionParams(segmentation=segmentation))
    assert res.frames["top"].components.count == 1  # one component, one long strip
    m = match_scene(res.detections, scene)
    assert len(m.pairs) == len(res.detections) == 2 and all(m.kind_correct)
    assert max(m.xy_error_m) < 0.005 and max(m.yaw_error_rad) < math.radians(3.0)


@pytest.mark.parametrize("segmentation", SEGMENTATIONS)
def test_upright_can_against_a_box_as_tall_and_behind_a_bottle(segmentation):
    """Tops that merge with a box's at the same height, or are partly hidden by a taller bottle in
    front of them, are no single can's flat top; their rims still give the cans."""
    d = np.array([1.0, 1.0]) / math.sqrt(2)  # away from the camera's axis, above the plate's centre
    p0 = np.array([CX, CY]) + 0.1 * d
    bottle = _distractor(0, "cylinder", (0.032, 0.25), *(p0 - (R + 0.032) * d))  # hides part of can 0's top
    p1 = np.array([CX - 0.08, CY - 0.06])
    box = _distractor(1, "box", (0.07, 0.05, H), p1[0] + R + 0.035, p1[1])  # touching can 1, as tall
    scene = _scene([_can(0, *p0, lying=False), _can(1, *p1, lying=False)], [bottle, box])
    res = perceive(scene, params=PerceptionParams(segmentation=segmentation))
    m = match_scene(res.detections, scene)
    assert m.distractor_grasps == ()
    assert len(m.pairs) == len(res.detections) == 2
    assert max(m.xy_error_m) < 0.004


def _touching(config: str, rng: np.random.Generator) -> Scene:
    """A scene with one touching configuration at a random place and angle on the plate."""
    while True:
        p = np.array([CX + rng.uniform(-0.09, 0.09), CY + rng.uniform(-0.09, 0.09)])
        a = rng.uniform(-math.pi, math.pi)
        u = np.array([math.cos(a), math.sin(a)])
        n = np.array([-u[1], u[0]])
        if config == "upright_pair":
            cans, extra = [_can(0, *p, lying=False), _can(1, *(p + 2 * R * u), lying=False)], []
        elif config == "lying_side_by_side":
            cans, extra = [_can(0, *p, lying=True, yaw=a), _can(1, *(p + 2 * R * n), lying=True, yaw=a)], []
        elif config == "lying_end_to_end":
            cans, extra = [_can(0, *p, lying=True, yaw=a), _can(1, *(p + H * u), lying=True, yaw=a)], []
        elif config == "lying_and_upright":
            cans, extra = [_can(0, *p, lying=True, yaw=a), _can(1, *(p + (H / 2 + R) * u), lying=False)], []
        elif config == "upright_and_box_as_tall":
            sx = rng.uniform(0.05, 0.09)
            cans = [_can(0, *p, lying=False)]
            extra = [_distractor(0, "box", (sx, rng.uniform(0.04, 0.07), H), *(p + (R + sx / 2) * u), yaw=a)]
        elif config == "upright_and_bottle":
            cans, extra = [_can(0, *p, lying=False)], [_distractor(0, "cylinder", (0.033, 0.24), *(p + 2 * R * u))]
        else:
            raise ValueError(config)
        spec = dataclasses.replace(SPEC.with_can_count(len(cans)), extra=tuple(extra))
        pts = np.vstack([np.array(c.p_WC_m[:2]) for c in cans])
        if np.all(np.abs(pts - [CX, CY]) < SPEC.plate.size_m[0] / 2 - H / 2 - 0.01):
            return Scene(spec, 0, tuple(cans))


@pytest.mark.slow
@pytest.mark.parametrize("segmentation", SEGMENTATIONS)
@pytest.mark.parametrize("config", ["upright_pair", "lying_side_by_side", "lying_end_to_end", "lying_and_upright",
                                    "upright_and_box_as_tall", "upright_and_bottle"])
def test_touching_configurations(config, segmentation):
    """Cans touching each other or a distractor (gap 0), 10 random placements each: every can found
    once, near its centre, and nothing else."""
    rng = np.random.default_rng(31)
    for _ in range(10):
        scene = _touching(config, rng)
        res = perceive(scene, params=PerceptionParams(segmentation=segmentation))
        m = match_scene(res.detections, scene)
        assert m.distractor_grasps == ()
        assert len(m.pairs) == len(res.detections) == len(scene.cans)
        assert all(m.kind_correct) and max(m.xy_error_m) < 0.005
