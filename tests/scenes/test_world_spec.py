"""A scene that is no can station: the plate, the bin, the can model, the cans and the waypoints are
optional in a spec. A spec that has them all hashes exactly as before they became optional; every
consumer that needs one either works without it or says in one line what is missing."""

import dataclasses
import hashlib
import json

import numpy as np
import pytest
import yaml

from scenes.errors import SuiteError
from scenes.scene import CanPose, Scene
from scenes.spec import DEFAULT_SPEC_PATH, OPTIONAL_PARTS, available_variants, load_spec, loads_spec

#: Each variant's and family's spec dict hash and the key of a scene with two given cans, as they
#: were before the parts became optional (gcs-arm is no can station any more: its shipped dataset
#: keeps its stored specs and keys, `tests/suite/problems/test_shipped_ids.py`).
PINNED = {
    "clutter": ("8b9f5db2d609ad69", "335b6c840e151aac"),
    "lookalike": ("459242ab4808a9e0", "c3a9ee0c22879b85"),
    "lookalike-dents": ("772014df4c61b87e", "dce7f13e0511a572"),
    "open": ("3693afe8518d460e", "bad5b4b8fed09d35"),
    "shelf": ("83982976464b91c5", "2b291f9df0b8c32b"),
    "station": ("e4af0cc1e84abbc6", "39f9e69e9d6232e8"),
    "wall": ("d6336afbaf73d900", "73a19a5b64fcc7a7"),
    "window": ("c27c1b5c8474dff7", "e85d53404c8bf9a9"),
}
CANS = (CanPose(0, (0.6, -0.1, 0.08), False, 0.2), CanPose(1, (0.55, -0.15, 0.05), True, 1.0))


def _world_yaml(**parts) -> str:
    """The default spec with a variant `world` that leaves out the parts set to None here."""
    raw = yaml.safe_load(DEFAULT_SPEC_PATH.read_text())
    raw["variants"]["world"] = parts
    return yaml.safe_dump(raw)


@pytest.mark.parametrize("variant", sorted(PINNED))
def test_a_spec_with_every_part_hashes_as_before(variant):
    spec = load_spec(variant=variant)
    h = hashlib.sha256(json.dumps(spec.to_dict(), sort_keys=True, default=list).encode()).hexdigest()[:16]
    assert (h, Scene(spec, 3, CANS).key()) == PINNED[variant]


def test_every_variant_but_the_papers_is_a_can_station():
    assert set(available_variants()) == set(PINNED) | {"gcs-arm"}
    for v in PINNED:
        spec = load_spec(variant=v)
        assert all(getattr(spec, part) is not None for part in OPTIONAL_PARTS)


def test_a_world_without_the_station_loads_hashes_and_says_what_is_missing():
    spec = loads_spec(_world_yaml(plate=None, bin=None, can=None, cans=None, waypoints=None), variant="world")
    assert all(getattr(spec, part) is None for part in OPTIONAL_PARTS)
    d = spec.to_dict()
    assert not set(OPTIONAL_PARTS) & set(d)
    assert set(spec.static_boxes()) == {"table"} and [o.name for o in spec.obstacles()] == ["table"]
    scene = Scene(spec, 0, ())
    truth = scene.to_json()
    assert "plate" not in truth and "waypoints_m" not in truth and truth["cans"] == []
    assert len(scene.key()) == 16 and scene.key() != Scene(load_spec(variant="open"), 0, ()).key()
    np.testing.assert_allclose(spec.work_xy_m(), [[0.5, 0.0]])
    for call, part in ((lambda: spec.plate_top_z_m, "plate"), (lambda: spec.with_can_count(2), "cans"),
                       (lambda: spec.with_can_color((0, 0, 1, 1)), "can")):
        with pytest.raises(SuiteError) as err:
            call()
        msg = str(err.value)
        assert f"scene 'world' has no {part} (field '{part}')" in msg and "\n" not in msg


@pytest.mark.parametrize("missing", ["plate", "bin", "can", "waypoints"])
def test_cans_need_the_whole_station(missing):
    with pytest.raises(SuiteError) as err:
        loads_spec(_world_yaml(**{missing: None}), variant="world")
    msg = str(err.value)
    assert f"field '{missing}'" in msg and "a spec with cans is a can station" in msg and "\n" not in msg


def test_a_plate_without_a_bin_is_a_world_too():
    spec = loads_spec(_world_yaml(bin=None, cans=None), variant="world")
    assert spec.plate_top_z_m == pytest.approx(0.02)
    assert "plate" in spec.static_boxes() and not any(n.startswith("bin_") for n in spec.static_boxes())
    np.testing.assert_allclose(spec.work_xy_m(), [spec.plate.center_m[:2]])


def test_the_papers_world_builds_in_both_engines_and_refuses_what_needs_cans():
    """gcs-arm: shelves and two bins, no plate: generated, built by Drake and python-fcl (the same
    free space as the first dataset's stand-in plate and bin), drawn; perception, the cycle, the
    families, execution and the moving bin refuse it in one line naming what is missing."""
    from perception.crop import work_volume_corners_W
    from perception.pipeline import detect
    from scenes.collision.world import CollisionWorld
    from scenes.drake_scene import build_drake_scene
    from scenes.families import draw_station
    from scenes.generate import generate_scene
    from scenes.moving_bin import make_scenario
    from scenes.moving_bin_check import check_scenario
    from suite.problems.cycle import build_problems
    from suite.report.scene_outlines import scene_outlines

    spec = load_spec(variant="gcs-arm")
    scene = generate_scene(spec, seed=0)
    assert scene.cans == () and spec.plate is None and spec.bin is None
    names = [o.name for o in spec.obstacles()]
    assert names[0] == "table" and sum(n.startswith("binL_") for n in names) == 5
    ds = build_drake_scene(scene, mode="plan", cameras=False)
    assert ds.plant.num_positions() == 7
    world = CollisionWorld(scene)
    q0 = np.asarray(spec.region_seeds.q0_rad, float)
    assert world.is_free(q0) and not world.is_free(np.array([0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0]))  # into the table
    kinds = {o.kind for o in scene_outlines(spec, (), dims=(0, 1))}
    assert "plate" not in kinds and "bin" not in kinds and "shelf" in kinds
    refusals = [
        (lambda: detect(None, spec), "plate"),
        (lambda: work_volume_corners_W(spec), "plate"),
        (lambda: build_problems(scene, [], time_limit_s=1.0, seed=0), "waypoints"),
        (lambda: draw_station(dataclasses.replace(spec, family=object()), None), "plate"),
        (lambda: check_scenario(make_scenario(), dataclasses.replace(spec, variant="open")), "bin"),
    ]
    for call, part in refusals:
        with pytest.raises(SuiteError) as err:
            call()
        msg = str(err.value)
        assert f"has no {part} (field '{part}')" in msg and "\n" not in msg


def test_execution_refuses_a_world_without_cans():
    from suite.execution.job_spec import ExecutionJob

    scene = Scene(load_spec(variant="gcs-arm"), 0, ())
    with pytest.raises(SuiteError, match=r"has no cans \(field 'cans'\): execution in physics"):
        ExecutionJob(planner="rrt", planner_config={}, scene=scene, grasps="truth", time_limit_s=1.0, seed=0)


def test_the_overview_looks_at_the_obstacles_of_a_world_without_a_station():
    spec = load_spec(variant="gcs-arm")
    xy = spec.work_xy_m()
    assert xy.shape == (1, 2)
    centres = np.array([o.pose()[:2, 3] for o in spec.extra])
    np.testing.assert_allclose(xy[0], centres.mean(axis=0))
