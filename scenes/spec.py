"""The scene specification: typed, validated, loaded from YAML.

A spec describes the static world (table, plate, bin, optional wall, further obstacles), the can
model, the can generator's settings, the grasp rule's offsets, the task waypoints and the cameras.
Variants (`open`, `wall`) are overrides merged into the base spec before it is parsed. Families
(`station`, `shelf`, `window`, `clutter`, see `scenes.families`) carry ranges instead: the scene
generator draws a concrete station from them with the scene's seed.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import pydantic
import yaml
from pydantic import Field

from scenes.errors import SuiteError

DEFAULT_SPEC_PATH = Path(__file__).parent / "specs" / "default.yaml"


@dataclasses.dataclass(frozen=True)
class Box:
    """An axis-aligned box: centre and full size in metres."""

    center_m: tuple[float, float, float]
    size_m: tuple[float, float, float]
    color_rgba: tuple[float, float, float, float]


#: Shapes an obstacle can have, with the meaning of its `size_m`.
OBSTACLE_SHAPES = {"box": "full size x, y, z", "cylinder": "radius, length along its z", "sphere": "radius"}


@dataclasses.dataclass(frozen=True)
class Obstacle:
    """A static obstacle primitive at a pose in the world.

    Attributes:
        name: unique in its scene (`table`, `plate`, `bin_floor`, `wall`, `shelf_board`,
            `distractor_0`, ...).
        shape: `box`, `cylinder` or `sphere` (see OBSTACLE_SHAPES for `size_m`).
        size_m: box (x, y, z) full size; cylinder (radius, length); sphere (radius,).
        X_WO: the obstacle's frame in the world, 4x4 row-major; a cylinder's axis is its z.
        color_rgba: its colour for rendering.
    """

    name: str
    shape: str
    size_m: tuple[float, ...]
    X_WO: tuple[tuple[float, float, float, float], ...]
    color_rgba: tuple[float, float, float, float]

    def pose(self) -> np.ndarray:
        """X_WO as a (4, 4) array."""
        return np.array(self.X_WO, float)

    @property
    def axis_aligned_box(self) -> bool:
        """True for a box whose axes are the world's (exact bounds for the collision world)."""
        return self.shape == "box" and bool(np.allclose(self.pose()[:3, :3], np.eye(3), atol=1e-12))

    @staticmethod
    def from_box(name: str, box: "Box") -> "Obstacle":
        X = np.eye(4)
        X[:3, 3] = box.center_m
        return Obstacle(name, "box", tuple(box.size_m), pose_tuple(X), tuple(box.color_rgba))

    def to_json(self) -> dict:
        """`{"name", "shape", "size_m", "X_WO"}` as printed by `scene --json`."""
        return {"name": self.name, "shape": self.shape, "size_m": [round(v, 6) for v in self.size_m],
                "X_WO": [[round(v, 9) for v in row] for row in self.X_WO]}


def pose_tuple(X: np.ndarray) -> tuple[tuple[float, float, float, float], ...]:
    """A (4, 4) pose as nested tuples of floats (hashable, JSON-able)."""
    return tuple(tuple(float(v) for v in row) for row in np.asarray(X, float))


@dataclasses.dataclass(frozen=True)
class BinSpec:
    """An open-top bin standing on the table."""

    center_xy_m: tuple[float, float]
    outer_size_m: tuple[float, float, float]
    wall_thickness_m: float
    color_rgba: tuple[float, float, float, float]

    def boxes(self) -> dict[str, Box]:
        """The bin as five boxes (floor and four walls), keyed by part name."""
        cx, cy = self.center_xy_m
        sx, sy, sz = self.outer_size_m
        t = self.wall_thickness_m
        c = self.color_rgba
        return {
            "bin_floor": Box((cx, cy, t / 2), (sx, sy, t), c),
            "bin_wall_xneg": Box((cx - sx / 2 + t / 2, cy, sz / 2), (t, sy, sz), c),
            "bin_wall_xpos": Box((cx + sx / 2 - t / 2, cy, sz / 2), (t, sy, sz), c),
            "bin_wall_yneg": Box((cx, cy - sy / 2 + t / 2, sz / 2), (sx - 2 * t, t, sz), c),
            "bin_wall_ypos": Box((cx, cy + sy / 2 - t / 2, sz / 2), (sx - 2 * t, t, sz), c),
        }


@dataclasses.dataclass(frozen=True)
class CanModel:
    """The can: a solid cylinder of this radius and height (metres), mass (kg) and colour."""

    radius_m: float
    height_m: float
    mass_kg: float
    color_rgba: tuple[float, float, float, float]


@dataclasses.dataclass(frozen=True)
class CanGenerator:
    """How cans are scattered on the plate."""

    count: int
    min_gap_m: float
    edge_margin_m: float
    lying_probability: float
    #: "random": cans anywhere apart from each other (the paper's plate); "pickable": each new can
    #: is placed where the open gripper can descend onto it past the cans already placed, so that
    #: picking in the reverse order of placement is collision-free (dense plates, `clutter`)
    placement: str = "random"


@dataclasses.dataclass(frozen=True)
class GraspSpec:
    """The grasp rule's offsets (metres), and the padding of a carried can in every collision
    model (`held_margin_m`: execution leaves the planned path by a few millimetres)."""

    top_offset_m: float
    pregrasp_height_m: float
    open_width_m: float
    held_margin_m: float


@dataclasses.dataclass(frozen=True)
class Waypoints:
    """Gripper positions of the nominal cycle; the gripper points straight down at each."""

    above_plate_m: tuple[float, float, float]
    middle_m: tuple[float, float, float]
    above_bin_m: tuple[float, float, float]


@dataclasses.dataclass(frozen=True)
class CameraPose:
    """A camera at `p_m` looking at `target_m` (world frame, metres)."""

    p_m: tuple[float, float, float]
    target_m: tuple[float, float, float]


@dataclasses.dataclass(frozen=True)
class CameraSpec:
    """The RGB-D cameras: shared intrinsics and one pose per named camera."""

    width_px: int
    height_px: int
    fov_y_deg: float
    clipping_m: tuple[float, float]
    poses: dict[str, CameraPose]


@dataclasses.dataclass(frozen=True)
class SceneSpec:
    """Everything static about a scene; with a seed it fully determines a `Scene`."""

    variant: str
    table: Box
    plate: Box
    bin: BinSpec
    can: CanModel
    cans: CanGenerator
    grasp: GraspSpec
    waypoints: Waypoints
    cameras: CameraSpec
    wall: Box | None = None
    #: further obstacles drawn by a family's generator (shelf, window frame, distractors, a turned wall)
    extra: tuple[Obstacle, ...] = ()
    #: a family's ranges (a `scenes.families` dataclass) while the station is still to be drawn;
    #: None for a concrete station
    family: Any = None

    @property
    def plate_top_z_m(self) -> float:
        """Height of the plate's top face."""
        return self.plate.center_m[2] + self.plate.size_m[2] / 2

    def static_boxes(self) -> dict[str, Box]:
        """Every static obstacle as a named box (table, plate, bin parts, wall)."""
        table = self.table
        boxes = {"table": table, "plate": self.plate, **self.bin.boxes()}
        if self.wall is not None:
            boxes["wall"] = self.wall
        return boxes

    def obstacles(self) -> tuple[Obstacle, ...]:
        """Every static obstacle as a primitive: the static boxes, then the drawn extras."""
        return tuple(Obstacle.from_box(n, b) for n, b in self.static_boxes().items()) + self.extra

    def with_can_count(self, count: int) -> "SceneSpec":
        """A copy with another number of cans (for a family that draws the count, e.g. `clutter`,
        its range becomes exactly `count`)."""
        family = self.family
        if family is not None and hasattr(family, "cans"):
            family = dataclasses.replace(family, cans=(count, count))
        return dataclasses.replace(self, cans=dataclasses.replace(self.cans, count=count), family=family)

    def with_min_gap(self, min_gap_m: float) -> "SceneSpec":
        """A copy with another minimum gap between cans."""
        return dataclasses.replace(self, cans=dataclasses.replace(self.cans, min_gap_m=min_gap_m))

    def with_can_color(self, color_rgba: tuple[float, float, float, float]) -> "SceneSpec":
        """A copy whose cans have another colour."""
        return dataclasses.replace(self, can=dataclasses.replace(self.can, color_rgba=color_rgba))

    def to_dict(self) -> dict[str, Any]:
        """A plain, JSON-able dict (used for hashing, manifests and datasets). The family fields are
        left out while unused, so the fixed variants hash as they did before families existed."""
        d = dataclasses.asdict(self)
        if not d["extra"]:
            del d["extra"]
        if d["family"] is None:
            del d["family"]
        if d["cans"]["placement"] == "random":
            del d["cans"]["placement"]
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


# The raw YAML sections as pydantic models: every field's type and bounds in one place. Numbers
# are strict (no "3" -> 3, no true -> 1) and finite; unknown fields are refused.
_Num = Annotated[float, Field(strict=True, allow_inf_nan=False)]
_Pos = Annotated[float, Field(strict=True, allow_inf_nan=False, gt=0)]
_NonNeg = Annotated[float, Field(strict=True, allow_inf_nan=False, ge=0)]
_Unit = Annotated[float, Field(strict=True, allow_inf_nan=False, ge=0, le=1)]
_Vec2 = tuple[_Num, _Num]
_Vec3 = tuple[_Num, _Num, _Num]
_PosVec3 = tuple[_Pos, _Pos, _Pos]
_Rgba = tuple[_Unit, _Unit, _Unit, _Unit]


class _Section(pydantic.BaseModel):
    model_config = pydantic.ConfigDict(extra="forbid", frozen=True)


class _TableIn(_Section):
    size_m: _PosVec3
    center_xy_m: _Vec2
    color_rgba: _Rgba


class _BoxIn(_Section):
    center_m: _Vec3
    size_m: _PosVec3
    color_rgba: _Rgba


class _BinIn(_Section):
    center_xy_m: _Vec2
    outer_size_m: _PosVec3
    wall_thickness_m: _Pos
    color_rgba: _Rgba

    @pydantic.field_validator("wall_thickness_m")
    @classmethod
    def _room_inside(cls, v: float, info: pydantic.ValidationInfo) -> float:
        outer = info.data.get("outer_size_m")
        if outer is not None and 2 * v >= min(outer[:2]):
            raise ValueError(f"leaves no room inside the bin: allowed below half of {min(outer[:2])}")
        return v


class _CanIn(_Section):
    radius_m: _Pos
    height_m: _Pos
    mass_kg: _Pos
    color_rgba: _Rgba


class _CansIn(_Section):
    count: Annotated[int, Field(strict=True, ge=0)]
    min_gap_m: _NonNeg
    edge_margin_m: _NonNeg
    lying_probability: _Unit
    placement: Literal["random", "pickable"] = "random"


class _GraspIn(_Section):
    top_offset_m: _NonNeg
    pregrasp_height_m: _Pos
    open_width_m: _Pos
    held_margin_m: _NonNeg


class _WaypointsIn(_Section):
    above_plate_m: _Vec3
    middle_m: _Vec3
    above_bin_m: _Vec3


class _CameraPoseIn(_Section):
    p_m: _Vec3
    target_m: _Vec3

    @pydantic.field_validator("target_m")
    @classmethod
    def _apart(cls, v, info: pydantic.ValidationInfo):
        if info.data.get("p_m") == v:
            raise ValueError("allowed: a target apart from p_m")
        return v


class _CamerasIn(_Section):
    width_px: Annotated[int, Field(strict=True, gt=0)]
    height_px: Annotated[int, Field(strict=True, gt=0)]
    fov_y_deg: Annotated[float, Field(strict=True, allow_inf_nan=False, gt=0, lt=180)]
    clipping_m: tuple[_Pos, _Pos]
    poses: Annotated[dict[str, _CameraPoseIn], Field(min_length=1)]

    @pydantic.field_validator("clipping_m")
    @classmethod
    def _near_far(cls, v):
        if v[0] >= v[1]:
            raise ValueError("allowed: [near, far] with near < far")
        return v


class _SpecIn(_Section):
    table: _TableIn
    plate: _BoxIn
    bin: _BinIn
    can: _CanIn
    cans: _CansIn
    grasp: _GraspIn
    waypoints: _WaypointsIn
    cameras: _CamerasIn
    wall: _BoxIn | None = None


def _error_line(exc: pydantic.ValidationError, data: Any, *, where: str) -> str:
    """The first validation error as one line: the field, its value and what is allowed."""
    import re

    err = exc.errors(include_url=False)[0]
    loc = list(err["loc"])
    items = []
    while loc and isinstance(loc[-1], int):  # an element of a list: name the list, show it whole
        items.insert(0, str(loc.pop()))
    field = ".".join(str(x) for x in loc) or "(top level)"
    if err["type"] == "extra_forbidden":
        return f"{where}field '{field}' is unknown; allowed: {_allowed_at(loc[:-1])}"
    if err["type"] == "missing" and not items:
        return f"{where}field '{field}' is missing"
    value = _lookup(data, loc)
    if err["type"] == "missing":
        msg = f"item {items[-1]} is missing: the list is too short"
    else:
        msg = re.sub(r" or instance of \w+", "", err["msg"]).removeprefix("Value error, ")
        msg = msg.replace("a valid tuple", "a list").replace("Tuple should", "the list should")
        msg = msg[0].lower() + msg[1:]
    at = f" (item {'.'.join(items)})" if items and err["type"] != "missing" else ""
    return f"{where}field '{field}' = {value!r}{at}: {msg}"


def _lookup(data: Any, loc: list) -> Any:
    for key in loc:
        if isinstance(data, dict):
            data = data.get(key)
        elif isinstance(data, (list, tuple)) and isinstance(key, int) and key < len(data):
            data = data[key]
        else:
            return None
    return data


def _allowed_at(loc: list) -> list[str]:
    """The field names allowed in the section at `loc` (names of a mapping such as
    cameras.poses are skipped over)."""
    import typing

    model: Any = _SpecIn
    keys = list(loc)
    while keys:
        key = keys.pop(0)
        info = getattr(model, "model_fields", {}).get(key)
        if info is None:
            return []
        ann = info.annotation
        while typing.get_origin(ann) is Annotated:
            ann = typing.get_args(ann)[0]
        if typing.get_origin(ann) is dict:
            ann = typing.get_args(ann)[1]
            if keys:
                keys.pop(0)  # the entry's name
        model = next((a for a in (ann, *typing.get_args(ann)) if isinstance(a, type) and issubclass(a, _Section)), None)
        if model is None:
            return []
    return sorted(model.model_fields)


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
    top = {"table", "plate", "bin", "can", "cans", "grasp", "waypoints", "cameras", "variants", "families"}
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
        family = parse_family(fam, name=variant)
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
    try:
        m = _SpecIn.model_validate(merged)
    except pydantic.ValidationError as exc:
        raise SuiteError(_error_line(exc, merged, where=where)) from None

    t = m.table
    table = Box((t.center_xy_m[0], t.center_xy_m[1], -t.size_m[2] / 2), t.size_m, t.color_rgba)
    b = m.bin
    c = m.can
    g = m.cans
    gr = m.grasp
    w = m.waypoints
    cam = m.cameras
    poses = {str(name): CameraPose(p.p_m, p.target_m) for name, p in cam.poses.items()}
    return SceneSpec(
        variant=variant,
        table=table,
        plate=Box(m.plate.center_m, m.plate.size_m, m.plate.color_rgba),
        bin=BinSpec(b.center_xy_m, b.outer_size_m, b.wall_thickness_m, b.color_rgba),
        can=CanModel(c.radius_m, c.height_m, c.mass_kg, c.color_rgba),
        cans=CanGenerator(g.count, g.min_gap_m, g.edge_margin_m, g.lying_probability, g.placement),
        grasp=GraspSpec(gr.top_offset_m, gr.pregrasp_height_m, gr.open_width_m, gr.held_margin_m),
        waypoints=Waypoints(w.above_plate_m, w.middle_m, w.above_bin_m),
        cameras=CameraSpec(cam.width_px, cam.height_px, cam.fov_y_deg, cam.clipping_m, poses),
        wall=None if m.wall is None else Box(m.wall.center_m, m.wall.size_m, m.wall.color_rgba),
        family=family,
    )


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
    """A concrete SceneSpec from its `to_dict()` (as stored in datasets); validated by pydantic.

    Raises:
        SuiteError: naming the first bad field.
    """
    import pydantic

    if data.get("family") is not None:
        raise SuiteError("a stored scene spec must be a concrete station (field 'family' must be null)")
    try:
        return pydantic.TypeAdapter(SceneSpec).validate_python(data)
    except pydantic.ValidationError as exc:
        err = exc.errors(include_url=False)[0]
        field = ".".join(str(x) for x in err["loc"])
        raise SuiteError(f"stored scene spec field '{field}' = {err['input']!r}: {err['msg']}") from None
