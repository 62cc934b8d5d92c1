"""The scene specification: typed, validated, loaded from YAML.

A spec describes the static world (table, plate, bin, optional wall, further obstacles), the can
model, the can generator's settings, the grasp rule's offsets, the task waypoints and the cameras.
Variants (`open`, `wall`) are overrides merged into the base spec before it is parsed. Families
(`station`, `shelf`, `window`, `clutter`, see `scenes.families`) carry ranges instead: the scene
generator draws a concrete station from them with the scene's seed.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np
import yaml

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


def _vec(raw: Any, n: int, field: str, *, positive: bool = False) -> tuple[float, ...]:
    if not isinstance(raw, (list, tuple)) or len(raw) != n:
        raise SuiteError(f"scene spec field '{field}' must be a list of {n} numbers, got {raw!r}")
    out = []
    for v in raw:
        x = _num(v, field)
        if positive and not x > 0:
            raise SuiteError(f"scene spec field '{field}' must be positive, got {raw!r}")
        out.append(x)
    return tuple(out)


def _num(raw: Any, field: str, *, positive: bool = False, nonneg: bool = False) -> float:
    if isinstance(raw, bool) or not isinstance(raw, (int, float)) or not math.isfinite(raw):
        raise SuiteError(f"scene spec field '{field}' must be a finite number, got {raw!r}")
    if positive and not raw > 0:
        raise SuiteError(f"scene spec field '{field}' must be positive, got {raw!r}")
    if nonneg and raw < 0:
        raise SuiteError(f"scene spec field '{field}' must be >= 0, got {raw!r}")
    return float(raw)


def _rgba(raw: Any, field: str) -> tuple[float, float, float, float]:
    v = _vec(raw, 4, field)
    if any(not 0 <= c <= 1 for c in v):
        raise SuiteError(f"scene spec field '{field}' must hold 4 values in [0, 1], got {raw!r}")
    return v  # type: ignore[return-value]


def _section(raw: dict, key: str, allowed: set[str], prefix: str = "", optional: frozenset = frozenset()) -> dict:
    name = f"{prefix}{key}"
    sec = raw.get(key)
    if not isinstance(sec, dict):
        raise SuiteError(f"scene spec field '{name}' is missing or not a mapping")
    unknown = set(sec) - allowed
    if unknown:
        raise SuiteError(
            f"scene spec field '{name}.{sorted(unknown)[0]}' is unknown; allowed: {sorted(allowed)}"
        )
    missing = allowed - set(sec) - optional
    if missing:
        raise SuiteError(f"scene spec field '{name}.{sorted(missing)[0]}' is missing")
    return sec


def _box(raw: dict, key: str) -> Box:
    s = _section(raw, key, {"center_m", "size_m", "color_rgba"})
    return Box(
        _vec(s["center_m"], 3, f"{key}.center_m"),  # type: ignore[arg-type]
        _vec(s["size_m"], 3, f"{key}.size_m", positive=True),  # type: ignore[arg-type]
        _rgba(s["color_rgba"], f"{key}.color_rgba"),
    )


def parse_spec(raw: Any, *, variant: str) -> SceneSpec:
    """Build a validated `SceneSpec` from a parsed YAML mapping.

    Args:
        raw: the YAML document as Python objects.
        variant: the name of one entry of `variants` to apply.

    Raises:
        SuiteError: naming the first bad field.
    """
    if not isinstance(raw, dict):
        raise SuiteError("scene spec must be a YAML mapping at the top level")
    top = {"table", "plate", "bin", "can", "cans", "grasp", "waypoints", "cameras", "variants", "families"}
    unknown = set(raw) - top
    if unknown:
        raise SuiteError(f"scene spec field '{sorted(unknown)[0]}' is unknown; allowed: {sorted(top)}")
    variants = raw.get("variants") or {}
    if not isinstance(variants, dict):
        raise SuiteError("scene spec field 'variants' must be a mapping of name -> overrides")
    families = raw.get("families") or {}
    if not isinstance(families, dict):
        raise SuiteError("scene spec field 'families' must be a mapping of name -> family")
    family = None
    if variant in families:
        from scenes.family_ranges import parse_family

        fam = families[variant]
        family = parse_family(fam, name=variant)
        base = fam.get("base", "open")
        if base not in variants:
            raise SuiteError(f"scene spec field 'families.{variant}.base' = {base!r}: allowed: {sorted(variants)}")
        fam_over = fam.get("overrides") or {}
        if not isinstance(fam_over, dict):
            raise SuiteError(f"scene spec field 'families.{variant}.overrides' must be a mapping")
        override = _merge(variants[base] or {}, fam_over)
    elif variant in variants:
        override = variants[variant] or {}
    else:
        raise SuiteError(f"unknown variant {variant!r}; allowed: {sorted([*variants, *families])}")
    if not isinstance(override, dict):
        raise SuiteError(f"scene spec field 'variants.{variant}' must be a mapping")
    wall_raw = override.get("wall")
    merged = _merge({k: v for k, v in raw.items() if k not in ("variants", "families")},
                    {k: v for k, v in override.items() if k != "wall"})

    t = _section(merged, "table", {"size_m", "center_xy_m", "color_rgba"})
    size = _vec(t["size_m"], 3, "table.size_m", positive=True)
    cxy = _vec(t["center_xy_m"], 2, "table.center_xy_m")
    table = Box((cxy[0], cxy[1], -size[2] / 2), size, _rgba(t["color_rgba"], "table.color_rgba"))  # type: ignore[arg-type]

    b = _section(merged, "bin", {"center_xy_m", "outer_size_m", "wall_thickness_m", "color_rgba"})
    bin_spec = BinSpec(
        _vec(b["center_xy_m"], 2, "bin.center_xy_m"),  # type: ignore[arg-type]
        _vec(b["outer_size_m"], 3, "bin.outer_size_m", positive=True),  # type: ignore[arg-type]
        _num(b["wall_thickness_m"], "bin.wall_thickness_m", positive=True),
        _rgba(b["color_rgba"], "bin.color_rgba"),
    )
    if 2 * bin_spec.wall_thickness_m >= min(bin_spec.outer_size_m[:2]):
        raise SuiteError("scene spec field 'bin.wall_thickness_m' leaves no room inside the bin")

    c = _section(merged, "can", {"radius_m", "height_m", "mass_kg", "color_rgba"})
    can = CanModel(
        _num(c["radius_m"], "can.radius_m", positive=True),
        _num(c["height_m"], "can.height_m", positive=True),
        _num(c["mass_kg"], "can.mass_kg", positive=True),
        _rgba(c["color_rgba"], "can.color_rgba"),
    )
    g = _section(merged, "cans", {"count", "min_gap_m", "edge_margin_m", "lying_probability", "placement"},
                 optional=frozenset({"placement"}))
    placement = g.get("placement", "random")
    if placement not in ("random", "pickable"):
        raise SuiteError(f"scene spec field 'cans.placement' = {placement!r}: allowed: ['pickable', 'random']")
    count = g["count"]
    if isinstance(count, bool) or not isinstance(count, int) or count < 0:
        raise SuiteError(f"scene spec field 'cans.count' must be an integer >= 0, got {count!r}")
    lying_p = _num(g["lying_probability"], "cans.lying_probability")
    if not 0 <= lying_p <= 1:
        raise SuiteError(f"scene spec field 'cans.lying_probability' must be in [0, 1], got {lying_p}")
    gen = CanGenerator(
        count,
        _num(g["min_gap_m"], "cans.min_gap_m", nonneg=True),
        _num(g["edge_margin_m"], "cans.edge_margin_m", nonneg=True),
        lying_p,
        placement,
    )
    gr = _section(merged, "grasp", {"top_offset_m", "pregrasp_height_m", "open_width_m", "held_margin_m"})
    grasp = GraspSpec(
        _num(gr["top_offset_m"], "grasp.top_offset_m", nonneg=True),
        _num(gr["pregrasp_height_m"], "grasp.pregrasp_height_m", positive=True),
        _num(gr["open_width_m"], "grasp.open_width_m", positive=True),
        _num(gr["held_margin_m"], "grasp.held_margin_m", nonneg=True),
    )
    w = _section(merged, "waypoints", {"above_plate_m", "middle_m", "above_bin_m"})
    waypoints = Waypoints(*(_vec(w[k], 3, f"waypoints.{k}") for k in ("above_plate_m", "middle_m", "above_bin_m")))  # type: ignore[arg-type]

    cam = _section(merged, "cameras", {"width_px", "height_px", "fov_y_deg", "clipping_m", "poses"})
    for key in ("width_px", "height_px"):
        v = cam[key]
        if isinstance(v, bool) or not isinstance(v, int) or v <= 0:
            raise SuiteError(f"scene spec field 'cameras.{key}' must be a positive integer, got {v!r}")
    fov = _num(cam["fov_y_deg"], "cameras.fov_y_deg", positive=True)
    if fov >= 180:
        raise SuiteError(f"scene spec field 'cameras.fov_y_deg' must be below 180, got {fov}")
    clip = _vec(cam["clipping_m"], 2, "cameras.clipping_m", positive=True)
    if clip[0] >= clip[1]:
        raise SuiteError(f"scene spec field 'cameras.clipping_m' must be [near, far] with near < far, got {list(clip)}")
    if not isinstance(cam["poses"], dict) or not cam["poses"]:
        raise SuiteError("scene spec field 'cameras.poses' must map camera names to poses")
    poses = {}
    for name, pose in cam["poses"].items():
        p = _section(cam["poses"], name, {"p_m", "target_m"}, prefix="cameras.poses.")
        poses[str(name)] = CameraPose(
            _vec(p["p_m"], 3, f"cameras.poses.{name}.p_m"),  # type: ignore[arg-type]
            _vec(p["target_m"], 3, f"cameras.poses.{name}.target_m"),  # type: ignore[arg-type]
        )
        if poses[str(name)].p_m == poses[str(name)].target_m:
            raise SuiteError(f"scene spec field 'cameras.poses.{name}' has p_m equal to target_m")
    cameras = CameraSpec(int(cam["width_px"]), int(cam["height_px"]), fov, clip, poses)  # type: ignore[arg-type]

    wall = _box({"wall": wall_raw}, "wall") if wall_raw is not None else None
    return SceneSpec(
        variant=variant,
        table=table,
        plate=_box(merged, "plate"),
        bin=bin_spec,
        can=can,
        cans=gen,
        grasp=grasp,
        waypoints=waypoints,
        cameras=cameras,
        wall=wall,
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
    return parse_spec(raw, variant=variant)


def available_variants(path: str | Path | None = None) -> list[str]:
    """The variant names a spec file defines."""
    path = Path(path) if path is not None else DEFAULT_SPEC_PATH
    raw = yaml.safe_load(path.read_text()) or {}
    return sorted([*(raw.get("variants") or {}), *(raw.get("families") or {})])


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
