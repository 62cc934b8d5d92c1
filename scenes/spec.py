"""The scene specification: typed, validated, loaded from YAML.

A spec describes the static world (table, plate, bin, optional wall, further obstacles), the can
model, the can generator's settings, the grasp rule's offsets, the task waypoints and the cameras.
The plate, the bin, the can model, the cans and the waypoints make a can station; a world that is
none (`gcs-arm`: shelves and bins) leaves them out (`plate: null`), and a consumer that needs one
says so in one line (`SceneSpec.require`).
The sections themselves are `scenes.spec_parts`'s. Variants (`open`, `wall`) are overrides merged into the base spec before it is parsed. Families
(`station`, `shelf`, `window`, `clutter`, see `scenes.families`) carry ranges instead: the scene
generator draws a concrete station from them with the scene's seed.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from scenes.errors import SuiteError
from scenes.robot_model import DEFAULT_ROBOT, ROBOTS
from scenes.schema import FieldError, load
from scenes.spec_parts import (
    BinSpec,
    Box,
    CameraSpec,
    CanGenerator,
    CanModel,
    GraspSpec,
    Obstacle,
    RegionSeeds,
    Table,
    Waypoints,
)

DEFAULT_SPEC_PATH = Path(__file__).parent / "specs" / "default.yaml"


#: The parts of a can station a spec may leave out (a world that is no can station).
OPTIONAL_PARTS = ("plate", "bin", "can", "cans", "waypoints")
#: What a spec with cans must have besides them.
STATION_PARTS = ("plate", "bin", "can", "waypoints")


@dataclasses.dataclass(frozen=True)
class SceneSpec:
    """Everything static about a scene; with a seed it fully determines a `Scene`."""

    variant: str
    table: Box
    #: The parts of a can station, each optional (a world that is no can station leaves them out:
    #: `gcs-arm`); a spec with `cans` must have all of them (`__post_init__`). They are left out of
    #: `to_dict` while None, so a spec that has them all hashes as before they became optional.
    #: The plate the cans lie on.
    plate: Box | None = dataclasses.field(default=None, kw_only=True)
    #: The bin the cans are recycled into.
    bin: BinSpec | None = dataclasses.field(default=None, kw_only=True)
    #: The can model (what is scattered, grasped and held).
    can: CanModel | None = dataclasses.field(default=None, kw_only=True)
    #: How cans are scattered on the plate; None: a world without cans.
    cans: CanGenerator | None = dataclasses.field(default=None, kw_only=True)
    grasp: GraspSpec
    #: The nominal cycle's gripper positions (above the plate, the middle, above the bin).
    waypoints: Waypoints | None = dataclasses.field(default=None, kw_only=True)
    cameras: CameraSpec
    wall: Box | None = None
    #: further obstacles drawn by a family's generator (shelf, window frame, distractors, a turned wall)
    extra: tuple[Obstacle, ...] = ()
    #: a family's ranges (a `scenes.families` dataclass) while the station is still to be drawn;
    #: None for a concrete station
    family: Any = None
    #: the robot variant (`scenes.robot_model.ROBOTS`): the project's own unless a scene reproduces
    #: another's experiment (`gcs-arm`: the GCS paper's sphere model)
    robot: str = DEFAULT_ROBOT
    #: hand-placed seeds of `gcs`'s regions (None: regions grow along the task chain)
    region_seeds: RegionSeeds | None = None

    def __post_init__(self):
        if self.robot not in ROBOTS:
            raise FieldError("robot", f"{self.robot!r} is not a robot variant; allowed: {', '.join(ROBOTS)}")
        if self.cans is not None:  # cans lie on the plate and go to the bin along the waypoints
            for part in STATION_PARTS:
                if getattr(self, part) is None:
                    raise FieldError(part, f"a spec with cans is a can station: it needs a {part} "
                                           f"({', '.join(STATION_PARTS)}), or no cans")

    def require(self, *parts: str, needed_by: str) -> None:
        """Raise a one-line SuiteError naming the first of `parts` (optional fields: plate, bin,
        can, cans, waypoints) this spec leaves out.

        Args:
            parts: the optional fields `needed_by` reads.
            needed_by: what needs them, as the message names it ("perception's plate crop").
        """
        for part in parts:
            if getattr(self, part) is None:
                raise SuiteError(f"scene {self.variant!r} has no {part} (field '{part}'): {needed_by} needs one")

    @property
    def plate_top_z_m(self) -> float:
        """Height of the plate's top face (SuiteError for a spec without a plate)."""
        self.require("plate", needed_by="the plate's top face")
        return self.plate.center_m[2] + self.plate.size_m[2] / 2

    def static_boxes(self) -> dict[str, Box]:
        """Every static obstacle as a named box (table, plate, bin parts, wall; those it has)."""
        boxes = {"table": self.table}
        if self.plate is not None:
            boxes["plate"] = self.plate
        if self.bin is not None:
            boxes.update(self.bin.boxes())
        if self.wall is not None:
            boxes["wall"] = self.wall
        return boxes

    def work_xy_m(self) -> np.ndarray:
        """Where the work is, (K, 2) m in the world's xy (for a camera to look at): the plate's and
        the bin's centres, those the spec has; in a world with neither, the middle of its further
        obstacles (a point ahead of the robot if it has none)."""
        work = [p[:2] for p in (self.plate and self.plate.center_m, self.bin and self.bin.center_xy_m) if p]
        if not work:
            work = [np.mean([o.pose()[:2, 3] for o in self.extra], axis=0) if self.extra else (0.5, 0.0)]
        return np.array(work, float)

    def obstacles(self) -> tuple[Obstacle, ...]:
        """Every static obstacle as a primitive: the static boxes, then the drawn extras."""
        return tuple(Obstacle.from_box(n, b) for n, b in self.static_boxes().items()) + self.extra

    def with_can_count(self, count: int) -> "SceneSpec":
        """A copy with another number of cans (for a family that draws the count, e.g. `clutter`,
        its range becomes exactly `count`)."""
        self.require("cans", needed_by="a can count")
        family = self.family
        if family is not None and hasattr(family, "cans"):
            family = dataclasses.replace(family, cans=(count, count))
        return dataclasses.replace(self, cans=dataclasses.replace(self.cans, count=count), family=family)

    def with_min_gap(self, min_gap_m: float) -> "SceneSpec":
        """A copy with another minimum gap between cans."""
        self.require("cans", needed_by="a gap between cans")
        return dataclasses.replace(self, cans=dataclasses.replace(self.cans, min_gap_m=min_gap_m))

    def with_can_color(self, color_rgba: tuple[float, float, float, float]) -> "SceneSpec":
        """A copy whose cans have another colour."""
        self.require("can", needed_by="a can colour")
        return dataclasses.replace(self, can=dataclasses.replace(self.can, color_rgba=color_rgba))

    def to_dict(self) -> dict[str, Any]:
        """A plain, JSON-able dict (used for hashing, manifests and datasets). The family fields are
        left out while unused, so the fixed variants hash as they did before families existed, and
        so are the parts of a can station a spec leaves out (a spec with all of them hashes as
        before they became optional)."""
        d = dataclasses.asdict(self)
        for part in OPTIONAL_PARTS:
            if d[part] is None:
                del d[part]
        if not d["extra"]:
            del d["extra"]
        if d["family"] is None:
            del d["family"]
        if "cans" in d and d["cans"]["placement"] == "random":
            del d["cans"]["placement"]
        if d["robot"] == DEFAULT_ROBOT:
            del d["robot"]
        if d["region_seeds"] is None:
            del d["region_seeds"]
        if d["cameras"]["sensor"] is None:
            del d["cameras"]["sensor"]
        if "bin" in d and d["bin"]["floor_thickness_m"] is None:
            del d["bin"]["floor_thickness_m"]
        return d


# --- parsing -------------------------------------------------------------------------------------


def _merge(base: dict, override: dict) -> dict:
    out = dict(base)
    for key, value in override.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _merge(out[key], value)
        else:
            out[key] = value
    return out


def parse_spec(raw: Any, *, variant: str, source: str | None = None) -> SceneSpec:
    """Build a validated `SceneSpec` from a parsed YAML mapping.

    Args:
        raw: the YAML document as Python objects.
        variant: the name of one entry of `variants` to apply.
        source: the file it came from (named in error messages).

    Raises:
        SuiteError: one line naming the file, the first bad field, its value and what is allowed.
    """
    where = f"scene spec {source}: " if source else "scene spec "
    if not isinstance(raw, dict):
        raise SuiteError(f"{where}must be a YAML mapping at the top level")
    top = {"table", "plate", "bin", "can", "cans", "grasp", "waypoints", "cameras", "variants", "families",
           "extra", "robot", "region_seeds"}
    unknown = set(raw) - top
    if unknown:
        raise SuiteError(f"{where}field '{sorted(unknown)[0]}' is unknown; allowed: {sorted(top)}")
    variants = raw.get("variants") or {}
    if not isinstance(variants, dict):
        raise SuiteError(f"{where}field 'variants' must be a mapping of name -> overrides")
    families = raw.get("families") or {}
    if not isinstance(families, dict):
        raise SuiteError(f"{where}field 'families' must be a mapping of name -> family")
    family = None
    if variant in families:
        from scenes.family_ranges import parse_family

        fam = families[variant]
        family = parse_family(fam, name=variant, where=where)
        base = fam.get("base", "open")
        if base not in variants:
            raise SuiteError(f"{where}field 'families.{variant}.base' = {base!r}: allowed: {sorted(variants)}")
        fam_over = fam.get("overrides") or {}
        if not isinstance(fam_over, dict):
            raise SuiteError(f"{where}field 'families.{variant}.overrides' must be a mapping")
        override = _merge(variants[base] or {}, fam_over)
    elif variant in variants:
        override = variants[variant] or {}
    else:
        raise SuiteError(f"unknown variant {variant!r}; allowed: {sorted([*variants, *families])}")
    if not isinstance(override, dict):
        raise SuiteError(f"{where}field 'variants.{variant}' must be a mapping")
    merged = _merge({k: v for k, v in raw.items() if k not in ("variants", "families")}, override)
    if isinstance(merged.get("table"), dict):  # the table as the file gives it, then as the box it is
        merged["table"] = dataclasses.asdict(load(Table, merged["table"], where=where, at="table").box())
    return load(SceneSpec, {**merged, "variant": variant, "family": family}, where=where)


def load_spec(path: str | Path | None = None, *, variant: str = "open") -> SceneSpec:
    """Load and validate a scene spec from a YAML file (the default spec if `path` is None)."""
    path = Path(path) if path is not None else DEFAULT_SPEC_PATH
    try:
        text = path.read_text()
    except OSError as exc:
        raise SuiteError(f"cannot read scene spec {str(path)!r}: {exc.strerror}") from None
    return loads_spec(text, variant=variant, source=str(path))


def loads_spec(text: str, *, variant: str = "open", source: str = "<string>") -> SceneSpec:
    """Parse a scene spec from YAML text."""
    try:
        raw = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        raise SuiteError(f"scene spec {source} is not valid YAML{where}") from None
    return parse_spec(raw, variant=variant, source=None if source == "<string>" else source)


def available_variants(path: str | Path | None = None) -> list[str]:
    """The variant names a spec file defines.

    Raises:
        SuiteError: the file cannot be read or is not a YAML mapping.
    """
    path = Path(path) if path is not None else DEFAULT_SPEC_PATH
    try:
        raw = yaml.safe_load(path.read_text()) or {}
    except OSError as exc:
        raise SuiteError(f"cannot read scene spec {str(path)!r}: {exc.strerror}") from None
    except yaml.YAMLError:
        raise SuiteError(f"scene spec {path} is not valid YAML") from None
    if not isinstance(raw, dict):
        raise SuiteError(f"scene spec {path}: must be a YAML mapping at the top level")
    names = []
    for key in ("variants", "families"):
        section = raw.get(key) or {}
        if not isinstance(section, dict):
            raise SuiteError(f"scene spec {path}: field '{key}' must be a mapping of name -> settings")
        names += [str(n) for n in section]
    return sorted(names)


def spec_from_dict(data: dict[str, Any]) -> SceneSpec:
    """A concrete SceneSpec from its `to_dict()` (as stored in datasets), validated by its schema.

    Raises:
        SuiteError: naming the first bad field.
    """
    if data.get("family") is not None:
        raise SuiteError("a stored scene spec must be a concrete station (field 'family' must be null)")
    return load(SceneSpec, data, where="stored scene spec ")
