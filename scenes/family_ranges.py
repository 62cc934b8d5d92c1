"""The ranges of the scene families as typed data, parsed from the spec YAML's `families:` section.

Each family's generator (in `scenes.families`) draws a concrete station within these ranges.
"""

from __future__ import annotations

import dataclasses
from typing import Annotated, Any, ClassVar, Literal

from pydantic import Field

from scenes.errors import SuiteError
from scenes.schema import FieldError, load

Range = tuple[float, float]

#: Horizontal distance from the base axis the arm works in comfortably (plate and bin centres).
REACH_M = (0.35, 0.78)


def within(lo: float, hi: float) -> Any:
    """A number allowed within [lo, hi]."""
    return Annotated[float, Field(ge=lo, le=hi)]


def range_within(lo: float, hi: float) -> Any:
    """A range [low, high] whose ends are allowed within [lo, hi]."""
    return tuple[within(lo, hi), within(lo, hi)]


def count_range_within(lo: int, hi: int) -> Any:
    """A range of counts [low, high] whose ends are allowed within [lo, hi]."""
    end = Annotated[int, Field(ge=lo, le=hi)]
    return tuple[end, end]


@dataclasses.dataclass(frozen=True)
class _Ranges:
    """A family's ranges: each field's annotation says where its values are allowed; every
    [low, high] must be ordered."""

    def __post_init__(self):
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if isinstance(v, tuple) and len(v) == 2 and v[0] > v[1]:
                raise FieldError(f.name, "an empty range: need [low, high] with low <= high")


@dataclasses.dataclass(frozen=True)
class StationRanges(_Ranges):
    """Plate and bin around the base; an optional radial wall between them."""

    plate_distance_m: range_within(*REACH_M) = (0.55, 0.64)
    plate_azimuth_deg: range_within(-165, 165) = (-100.0, 40.0)
    bin_distance_m: range_within(*REACH_M) = (0.45, 0.60)
    bin_turn_deg: range_within(30, 180) = (60.0, 170.0)
    wall_probability: within(0, 1) = 0.5
    wall_height_m: range_within(0.02, 0.6) = (0.15, 0.35)
    wall_span_m: range_within(0.2, 1.0) = (0.30, 0.80)
    base_clearance_m: within(0.0, 0.5) = 0.22
    generator: ClassVar[str] = "station"


@dataclasses.dataclass(frozen=True)
class ShelfRanges(_Ranges):
    """A board over the far part of the plate, held by a back panel behind the plate."""

    board_height_m: range_within(0.25, 1.2) = (0.45, 0.65)
    board_depth_m: range_within(0.05, 0.6) = (0.10, 0.22)
    board_thickness_m: within(0.005, 0.1) = 0.02
    generator: ClassVar[str] = "shelf"


@dataclasses.dataclass(frozen=True)
class WindowRanges(_Ranges):
    """The bin behind a tall, wide wall across the bin's direction: the arm reaches through a window.

    The wall stands `wall_distance_m` from the base axis, square to the bin's direction, and runs
    `wall_half_length_m` to either side: too tall to go over and too long to go around while the
    gripper is over the bin, so every path into the bin threads the forearm, the gripper and the
    carried can through the window (a narrow passage)."""

    bin_azimuth_deg: range_within(-165, 165) = (80.0, 110.0)
    bin_distance_m: range_within(*REACH_M) = (0.56, 0.64)
    wall_distance_m: range_within(0.2, 0.6) = (0.31, 0.35)
    wall_half_length_m: within(0.2, 2.0) = 1.0
    wall_height_m: range_within(0.3, 2.0) = (1.15, 1.30)
    window_offset_m: range_within(-0.5, 0.5) = (-0.06, 0.06)
    window_width_m: range_within(0.1, 1.0) = (0.36, 0.46)
    window_bottom_m: range_within(0.0, 1.0) = (0.30, 0.40)
    window_height_m: range_within(0.1, 1.0) = (0.55, 0.65)
    wall_thickness_m: within(0.005, 0.2) = 0.02
    generator: ClassVar[str] = "window"


@dataclasses.dataclass(frozen=True)
class ClutterRanges(_Ranges):
    """A dense plate: many cans close together and distractors standing among them."""

    cans: count_range_within(1, 40) = (8, 12)
    min_gap_m: range_within(0.0, 0.1) = (0.0, 0.01)
    distractors: count_range_within(0, 10) = (2, 4)
    generator: ClassVar[str] = "clutter"


@dataclasses.dataclass(frozen=True)
class LookalikeRanges(ClutterRanges):
    """Clutter's plate with the seed paper's look-alikes (`scenes.lookalikes`): red hourglasses that
    match a can from above, and dented cans (upright or lying, as the cans are). `hourglass_waist`
    is the hourglasses' waist over the can's radius (a value, not a range: it draws nothing, so a
    scene's draw is the same at any waist). `lying_dent` is where a lying dented can's dent faces:
    `up` (within 60 degrees of it, what the top camera sees) or `any` (any turn about its axis:
    up, sideways or down); both draw the same numbers."""

    hourglasses: count_range_within(0, 6) = (1, 2)
    dented: count_range_within(0, 6) = (1, 2)
    hourglass_waist: within(0.05, 1.0) = 0.55
    lying_dent: Literal["up", "any"] = "up"
    generator: ClassVar[str] = "lookalike"


GENERATORS: dict[str, type[_Ranges]] = {c.generator: c for c in (StationRanges, ShelfRanges, WindowRanges, ClutterRanges,
                                                                LookalikeRanges)}


def parse_family(raw: Any, *, name: str, where: str = "scene spec ") -> _Ranges:
    """A family's ranges from its YAML section (`families.NAME`), validated by their schema.

    Raises:
        SuiteError: one line naming the field, its value and what is allowed.
    """
    at = f"families.{name}"
    if not isinstance(raw, dict):
        raise SuiteError(f"{where}field '{at}' must be a mapping")
    gen = raw.get("generator", name)
    if gen not in GENERATORS:
        raise SuiteError(f"{where}field '{at}.generator' = {gen!r}: allowed: {sorted(GENERATORS)}")
    return load(GENERATORS[gen], raw.get("ranges") or {}, where=where, at=f"{at}.ranges")
