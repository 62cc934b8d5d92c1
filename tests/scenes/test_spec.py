"""Scene specs: the default loads; bad specs fail with one line naming the field."""

import pytest
import yaml

from scenes.spec import DEFAULT_SPEC_PATH, load_spec, loads_spec
from scenes.errors import SuiteError


def _default_raw():
    return yaml.safe_load(DEFAULT_SPEC_PATH.read_text())


def test_default_spec_variants():
    open_ = load_spec(variant="open")
    wall = load_spec(variant="wall")
    assert open_.wall is None and wall.wall is not None
    assert wall.waypoints.middle_m[2] > wall.wall.center_m[2] + wall.wall.size_m[2] / 2
    assert open_.cameras.width_px == 640 and open_.cameras.height_px == 480
    assert set(open_.cameras.poses) == {"top", "front", "back"}
    assert open_.plate_top_z_m == pytest.approx(0.02)
    assert (open_.can.radius_m, open_.can.height_m) == (0.033, 0.122)


@pytest.mark.parametrize(
    "mutate, field",
    [
        (lambda r: r["plate"].__setitem__("size_m", [0.3, -0.3, 0.02]), "plate.size_m"),
        (lambda r: r["can"].__setitem__("radius_m", -0.01), "can.radius_m"),
        (lambda r: r["cans"].__setitem__("count", -1), "cans.count"),
        (lambda r: r["plate"].__setitem__("colour", [1, 1, 1, 1]), "plate.colour"),
        (lambda r: r["cameras"].__setitem__("fov_y_deg", "wide"), "cameras.fov_y_deg"),
        (lambda r: r.__setitem__("tabel", {}), "tabel"),
        (lambda r: r["grasp"].pop("top_offset_m"), "grasp.top_offset_m"),
    ],
)
def test_bad_fields_are_named(mutate, field):
    raw = _default_raw()
    mutate(raw)
    with pytest.raises(SuiteError) as err:
        loads_spec(yaml.safe_dump(raw), variant="open")
    msg = str(err.value)
    assert f"'{field}'" in msg and "\n" not in msg


def test_unknown_variant_lists_allowed():
    with pytest.raises(SuiteError, match=r"unknown variant 'hill'.*\['clutter', 'gcs-arm', 'lookalike', 'lookalike-dents', 'open', 'shelf', 'station', 'wall', 'window'\]"):
        load_spec(variant="hill")


def test_malformed_yaml():
    with pytest.raises(SuiteError, match="not valid YAML at line 3"):
        loads_spec("plate:\n  size_m: [1, 2\n", variant="open")


def test_missing_file():
    with pytest.raises(SuiteError, match="cannot read scene spec"):
        load_spec("/nonexistent/spec.yaml")


def test_a_scene_names_its_robot_and_the_default_hashes_as_before():
    """`robot:` picks a robot variant; left at the project's own (and with no hand seeds and the
    bin's floor as thick as its walls), the spec's dict has none of the new fields, so every
    existing scene key and problem id stays as it was."""
    raw = yaml.safe_load(DEFAULT_SPEC_PATH.read_text())
    open_spec = load_spec(variant="open")
    assert open_spec.robot == "iiwa14-wsg"
    d = open_spec.to_dict()
    assert "robot" not in d and "region_seeds" not in d and "floor_thickness_m" not in d["bin"]
    paper = load_spec(variant="gcs-arm")
    assert paper.robot == "iiwa14-spheres" and paper.to_dict()["robot"] == "iiwa14-spheres"
    assert len(paper.region_seeds.poses) == 5 and len(paper.region_seeds.joints_rad) == 3
    assert paper.plate is None and paper.bin is None  # no can station: its bins are obstacles
    assert next(o for o in paper.extra if o.name == "binL_bottom").size_m[2] == 0.015
    raw["variants"]["open"] = {"robot": "ur5"}
    with pytest.raises(SuiteError, match="robot.*'ur5' is not a robot variant; allowed: iiwa14-wsg, iiwa14-spheres"):
        loads_spec(yaml.safe_dump(raw), variant="open")
