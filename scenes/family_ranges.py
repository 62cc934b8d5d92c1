"""The ranges of the scene families as typed data, parsed from the spec YAML's `families:` section.

Each family's generator (in `scenes.families`) draws a concrete station within these ranges.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, ClassVar

from scenes.errors import SuiteError

Range = tuple[float, float]

#: Horizontal distance from the base axis the arm works in comfortably (plate and bin centres).
REACH_M = (0.35, 0.78)


@dataclasses.dataclass(frozen=True)
class _Ranges:
    """Shared validation: every (lo, hi) ordered and inside the field's allowed interval."""

    BOUNDS: ClassVar[dict[str, tuple[float, float]]] = {}

    def check(self, where: str) -> None:
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            lo_ok, hi_ok = self.BOUNDS.get(f.name, (-math.inf, math.inf))
            vals = v if isinstance(v, tuple) else (v,)
            if isinstance(v, tuple) and len(v) == 2 and v[0] > v[1]:
                raise SuiteError(f"scene spec field '{where}.{f.name}' is an empty range {list(v)}: need [low, high] with low <= high")
            for x in vals:
                if isinstance(x, (int, float)) and not lo_ok <= x <= hi_ok:
                    raise SuiteError(f"scene spec field '{where}.{f.name}' = {list(vals) if isinstance(v, tuple) else v} "
                                     f"is infeasible: allowed within [{lo_ok}, {hi_ok}]")


@dataclasses.dataclass(frozen=True)
class StationRanges(_Ranges):
    """Plate and bin around the base; an optional radial wall between them."""

    plate_distance_m: Range = (0.55, 0.64)
    plate_azimuth_deg: Range = (-100.0, 40.0)
    bin_distance_m: Range = (0.45, 0.60)
    bin_turn_deg: Range = (60.0, 170.0)
    wall_probability: float = 0.5
    wall_height_m: Range = (0.15, 0.35)
    wall_span_m: Range = (0.30, 0.80)
    base_clearance_m: float = 0.22
    generator: ClassVar[str] = "station"
    BOUNDS: ClassVar = {"plate_distance_m": REACH_M, "bin_distance_m": REACH_M, "plate_azimuth_deg": (-165, 165),
                        "bin_turn_deg": (30, 180), "wall_probability": (0, 1), "wall_height_m": (0.02, 0.6),
                        "wall_span_m": (0.2, 1.0), "base_clearance_m": (0.0, 0.5)}



@dataclasses.dataclass(frozen=True)
class ShelfRanges(_Ranges):
    """A board over the far part of the plate, held by a back panel behind the plate."""

    board_height_m: Range = (0.45, 0.65)
    board_depth_m: Range = (0.10, 0.22)
    board_thickness_m: float = 0.02
    generator: ClassVar[str] = "shelf"
    BOUNDS: ClassVar = {"board_height_m": (0.25, 1.2), "board_depth_m": (0.05, 0.6), "board_thickness_m": (0.005, 0.1)}



@dataclasses.dataclass(frozen=True)
class WindowRanges(_Ranges):
    """The bin behind a tall, wide wall across the bin's direction: the arm reaches through a window.

    The wall stands `wall_distance_m` from the base axis, square to the bin's direction, and runs
    `wall_half_length_m` to either side: too tall to go over and too long to go around while the
    gripper is over the bin, so every path into the bin threads the forearm, the gripper and the
    carried can through the window (a narrow passage)."""

    bin_azimuth_deg: Range = (80.0, 110.0)
    bin_distance_m: Range = (0.56, 0.64)
    wall_distance_m: Range = (0.31, 0.35)
    wall_half_length_m: float = 1.0
    wall_height_m: Range = (1.15, 1.30)
    window_offset_m: Range = (-0.06, 0.06)
    window_width_m: Range = (0.36, 0.46)
    window_bottom_m: Range = (0.30, 0.40)
    window_height_m: Range = (0.55, 0.65)
    wall_thickness_m: float = 0.02
    generator: ClassVar[str] = "window"
    BOUNDS: ClassVar = {"bin_azimuth_deg": (-165, 165), "bin_distance_m": REACH_M, "wall_distance_m": (0.2, 0.6),
                        "wall_half_length_m": (0.2, 2.0), "wall_height_m": (0.3, 2.0),
                        "window_offset_m": (-0.5, 0.5), "window_width_m": (0.1, 1.0),
                        "window_bottom_m": (0.0, 1.0), "window_height_m": (0.1, 1.0),
                        "wall_thickness_m": (0.005, 0.2)}



@dataclasses.dataclass(frozen=True)
class ClutterRanges(_Ranges):
    """A dense plate: many cans close together and distractors standing among them."""

    cans: tuple[int, int] = (8, 12)
    min_gap_m: Range = (0.0, 0.01)
    distractors: tuple[int, int] = (2, 4)
    generator: ClassVar[str] = "clutter"
    BOUNDS: ClassVar = {"cans": (1, 40), "min_gap_m": (0.0, 0.1), "distractors": (0, 10)}


GENERATORS: dict[str, type[_Ranges]] = {c.generator: c for c in (StationRanges, ShelfRanges, WindowRanges, ClutterRanges)}


def parse_family(raw: Any, *, name: str) -> _Ranges:
    """A family's ranges from its YAML section (`families.NAME`), validated with pydantic.

    Raises:
        SuiteError: one line naming the field, its value and what is allowed.
    """
    import pydantic

    where = f"families.{name}"
    if not isinstance(raw, dict):
        raise SuiteError(f"scene spec field '{where}' must be a mapping")
    gen = raw.get("generator", name)
    if gen not in GENERATORS:
        raise SuiteError(f"scene spec field '{where}.generator' = {gen!r}: allowed: {sorted(GENERATORS)}")
    ranges = raw.get("ranges") or {}
    if not isinstance(ranges, dict):
        raise SuiteError(f"scene spec field '{where}.ranges' must be a mapping")
    allowed = [f.name for f in dataclasses.fields(GENERATORS[gen])]
    unknown = sorted(set(ranges) - set(allowed))
    if unknown:
        raise SuiteError(f"scene spec field '{where}.ranges.{unknown[0]}' is unknown; allowed: {allowed}")
    try:
        parsed = pydantic.TypeAdapter(GENERATORS[gen]).validate_python(ranges)
    except pydantic.ValidationError as exc:
        err = exc.errors(include_url=False)[0]
        field = ".".join(str(x) for x in err["loc"])
        raise SuiteError(f"scene spec field '{where}.ranges.{field}' = {err['input']!r}: {err['msg']}") from None
    parsed.check(f"{where}.ranges")
    return parsed
