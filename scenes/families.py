"""Scene families: stations drawn from a seed within ranges written in the spec YAML.

A family is a generator. Its ranges live in the spec's `families:` section; from one
`np.random.Generator` it draws a concrete station (plate, bin, walls, shelf, window, distractors,
the task waypoints and the cameras derived from that layout), which `scenes.generate` then checks
for feasibility (waypoints reachable by collision-aware IK; redrawn otherwise) and fills with cans.

- `station`: plate and bin anywhere around the base, the bin beside or behind the robot, an
  optional radial wall of random height between them (the paper's "moving bin").
- `shelf`: a board over the far part of the plate at a random height and depth, on a back panel;
  the waypoint above the plate is lowered to fit under it.
- `window`: the bin behind a tall, long wall square to its direction; the arm reaches through a
  window in it with the carried can (a narrow passage: no way over or around).
- `clutter`: a dense plate (8-12 cans, gaps 0-1 cm) with distractors (bottles, boxes, cups) that
  are obstacles and never recyclable.
- `lookalike`: clutter's draw, then the seed paper's look-alikes (`scenes.lookalikes`): red
  hourglasses with a can's radius and height, and dented cans, all obstacles in physics. The
  evaluation counts a dented can as a can (`perception.evaluate.truth_cans`) and a grasped
  hourglass as a false detection. The `lookalike-dents` variant has dented cans only, half of them
  lying with their dents facing any way (`lookalike`'s lying dents face up).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from scenes.errors import SuiteError
from scenes.family_ranges import ClutterRanges, LookalikeRanges, Range, ShelfRanges, StationRanges, WindowRanges
from scenes.spec import SceneSpec
from scenes.spec_parts import CameraPose, Obstacle, pose_tuple

#: Height of the waypoint above the plate over the plate's top face, and above the bin's rim.
ABOVE_PLATE_M = 0.36
ABOVE_BIN_M = 0.22
#: The middle waypoint's height: at least this, and this far above a wall it crosses.
MIDDLE_MIN_Z_M = 0.45
OVER_WALL_M = 0.33
WALL_COLOR = (0.70, 0.72, 0.78, 1.0)
SHELF_COLOR = (0.60, 0.50, 0.38, 1.0)


def _rz(yaw: float, p) -> np.ndarray:
    X = np.eye(4)
    c, s = math.cos(yaw), math.sin(yaw)
    X[:2, :2] = [[c, -s], [s, c]]
    X[:3, 3] = p
    return X


def _u(rng: np.random.Generator, r: Range) -> float:
    return float(rng.uniform(r[0], r[1]))


def _polar(r: float, az: float) -> np.ndarray:
    return np.array([r * math.cos(az), r * math.sin(az)])


def _box(name: str, center, size, color, yaw: float = 0.0) -> Obstacle:
    return Obstacle(name, "box", tuple(float(v) for v in size), pose_tuple(_rz(yaw, center)), tuple(color))


def cameras_about(spec: SceneSpec, plate_xy: np.ndarray) -> dict[str, CameraPose]:
    """The spec's three cameras moved with the plate: the top one above its centre, the front and
    back ones along the line from the base through the plate (outward and inward)."""
    top_z = spec.plate_top_z_m
    target = (float(plate_xy[0]), float(plate_xy[1]), top_z)
    radial = plate_xy / max(float(np.linalg.norm(plate_xy)), 1e-9)
    default_plate = np.asarray(spec.plate.center_m[:2])
    out = {}
    for name, pose in spec.cameras.poses.items():
        off = np.asarray(pose.p_m[:2]) - default_plate
        # the offset along and across the default plate's x axis becomes radial and tangential
        along, across = float(off[0]), float(off[1])
        p_xy = plate_xy + along * radial + across * np.array([-radial[1], radial[0]])
        out[name] = CameraPose((float(p_xy[0]), float(p_xy[1]), float(pose.p_m[2])), target)
    return out


def _with_layout(spec: SceneSpec, *, plate_xy, bin_xy, middle_m, extra=(), above_plate_m=None,
                 **changes) -> SceneSpec:
    """A concrete station: plate and bin moved, waypoints and cameras derived, extras added.
    The waypoint above the plate is ABOVE_PLATE_M over the plate's centre unless `above_plate_m`
    gives it."""
    plate = dataclasses.replace(spec.plate, center_m=(float(plate_xy[0]), float(plate_xy[1]), spec.plate.center_m[2]))
    bin_ = dataclasses.replace(spec.bin, center_xy_m=(float(bin_xy[0]), float(bin_xy[1])))
    moved = dataclasses.replace(spec, plate=plate, bin=bin_)
    if above_plate_m is None:
        above_plate_m = (plate_xy[0], plate_xy[1], moved.plate_top_z_m + ABOVE_PLATE_M)
    waypoints = dataclasses.replace(
        spec.waypoints,
        above_plate_m=tuple(float(v) for v in above_plate_m),
        middle_m=tuple(float(v) for v in middle_m),
        above_bin_m=(float(bin_xy[0]), float(bin_xy[1]), float(spec.bin.outer_size_m[2] + ABOVE_BIN_M)),
    )
    cameras = dataclasses.replace(spec.cameras, poses=cameras_about(spec, np.asarray(plate_xy, float)))
    return dataclasses.replace(moved, waypoints=waypoints, cameras=cameras, extra=tuple(extra), family=None,
                               **changes)


def _footprint(center_xy, size_xy) -> tuple[np.ndarray, np.ndarray]:
    c, h = np.asarray(center_xy, float), np.asarray(size_xy, float) / 2
    return c - h, c + h


def _extent_along(fp, u: np.ndarray) -> tuple[float, float]:
    """(min, max) of a footprint's corners projected on the unit vector `u`."""
    (x0, y0), (x1, y1) = fp
    proj = [float(np.array([x, y]) @ u) for x in (x0, x1) for y in (y0, y1)]
    return min(proj), max(proj)


def _apart(a, b, gap: float) -> bool:
    (alo, ahi), (blo, bhi) = a, b
    return bool(np.any(alo > bhi + gap) or np.any(blo > ahi + gap))


def _clear_of_base(fp, radius_m: float) -> bool:
    lo, hi = fp
    nearest = np.clip(np.zeros(2), lo, hi)
    return float(np.linalg.norm(nearest)) >= radius_m


#: Distractor models: shape, size ranges (box: x, y, z; cylinder: radius, height) and colours
#: (none red: colour segmentation must ignore them; geometric segmentation tells them by shape).
DISTRACTORS: dict[str, dict[str, Any]] = {
    "bottle": {"shape": "cylinder", "size": ((0.030, 0.036), (0.20, 0.26)),
               "colors": ((0.15, 0.55, 0.25, 1.0), (0.85, 0.85, 0.90, 1.0), (0.20, 0.35, 0.75, 1.0))},
    "cup": {"shape": "cylinder", "size": ((0.042, 0.048), (0.085, 0.105)),
            "colors": ((0.95, 0.95, 0.92, 1.0), (0.25, 0.45, 0.80, 1.0))},
    "box": {"shape": "box", "size": ((0.05, 0.09), (0.04, 0.07), (0.08, 0.15)),
            "colors": ((0.80, 0.65, 0.35, 1.0), (0.95, 0.85, 0.20, 1.0), (0.20, 0.30, 0.65, 1.0))},
}


def _draw_station(ranges: StationRanges, spec: SceneSpec, rng: np.random.Generator) -> SceneSpec:
    for _ in range(200):
        r_p, az_p = _u(rng, ranges.plate_distance_m), math.radians(_u(rng, ranges.plate_azimuth_deg))
        turn = math.radians(_u(rng, ranges.bin_turn_deg)) * (1 if rng.random() < 0.5 else -1)
        r_b, az_b = _u(rng, ranges.bin_distance_m), az_p + turn
        if abs(math.degrees(math.atan2(math.sin(az_b), math.cos(az_b)))) > 165:
            continue  # joint 1 cannot face it
        plate_xy, bin_xy = _polar(r_p, az_p), _polar(r_b, az_b)
        fp_p = _footprint(plate_xy, spec.plate.size_m[:2])
        fp_b = _footprint(bin_xy, spec.bin.outer_size_m[:2])
        if not (_apart(fp_p, fp_b, 0.05) and _clear_of_base(fp_p, ranges.base_clearance_m)
                and _clear_of_base(fp_b, ranges.base_clearance_m)):
            continue
        az_mid = az_p + turn / 2
        extra, z_mid = [], MIDDLE_MIN_Z_M
        if rng.random() < ranges.wall_probability:
            h = _u(rng, ranges.wall_height_m)
            r0, r1 = ranges.wall_span_m
            center = (*_polar((r0 + r1) / 2, az_mid), h / 2)
            extra.append(_box("wall", center, ((r1 - r0), 0.02, h), WALL_COLOR, yaw=az_mid))
            z_mid = max(z_mid, h + OVER_WALL_M)
        middle = (*_polar((r_p + r_b) / 2, az_mid), z_mid)
        return _with_layout(spec, plate_xy=plate_xy, bin_xy=bin_xy, middle_m=middle, extra=extra)
    raise SuiteError("station family: no plate/bin layout fits the ranges in 200 draws; widen them")


def _draw_shelf(ranges: ShelfRanges, spec: SceneSpec, rng: np.random.Generator) -> SceneSpec:
    plate_xy = np.asarray(spec.plate.center_m[:2], float)
    radial = plate_xy / np.linalg.norm(plate_xy)
    yaw = math.atan2(radial[1], radial[0])
    half = spec.plate.size_m[0] / 2
    top = spec.plate_top_z_m
    h, d, t = _u(rng, ranges.board_height_m), _u(rng, ranges.board_depth_m), ranges.board_thickness_m
    width = spec.plate.size_m[1] + 0.20
    far = half + 0.03  # the back panel stands just beyond the plate's far edge
    board_c = (*(plate_xy + (far - d / 2) * radial), top + h + t / 2)
    panel_c = (*(plate_xy + (far + 0.01) * radial), (top + h + t) / 2)
    extra = [_box("shelf_board", board_c, (d, width, t), SHELF_COLOR, yaw=yaw),
             _box("shelf_back", panel_c, (0.02, width, top + h + t), SHELF_COLOR, yaw=yaw)]
    z_plate = min(top + ABOVE_PLATE_M, top + h - 0.08)
    # the waypoint above the plate moves out from under the board, towards the robot
    p_above = plate_xy - 0.5 * d * radial
    wp = spec.waypoints
    moved = _with_layout(spec, plate_xy=plate_xy, bin_xy=spec.bin.center_xy_m, middle_m=wp.middle_m,
                         extra=extra, above_plate_m=(p_above[0], p_above[1], z_plate))
    # the top camera hangs under the board (above it, the board would hide the plate)
    poses = dict(moved.cameras.poses)
    if "top" in poses:
        p = poses["top"].p_m
        poses["top"] = CameraPose((p[0], p[1], min(p[2], top + h - 0.03)), poses["top"].target_m)
    return dataclasses.replace(moved, cameras=dataclasses.replace(moved.cameras, poses=poses))


def _draw_window(ranges: WindowRanges, spec: SceneSpec, rng: np.random.Generator) -> SceneSpec:
    fp_p = _footprint(spec.plate.center_m[:2], spec.plate.size_m[:2])
    L, t = ranges.wall_half_length_m, ranges.wall_thickness_m
    for _ in range(200):
        az = math.radians(_u(rng, ranges.bin_azimuth_deg))
        r_b, d = _u(rng, ranges.bin_distance_m), _u(rng, ranges.wall_distance_m)
        H, off = _u(rng, ranges.wall_height_m), _u(rng, ranges.window_offset_m)
        w, zb, hw = _u(rng, ranges.window_width_m), _u(rng, ranges.window_bottom_m), _u(rng, ranges.window_height_m)
        u = np.array([math.cos(az), math.sin(az)])  # towards the bin
        v = np.array([-u[1], u[0]])  # along the wall
        bin_xy = r_b * u
        # plate and bin footprints on their sides of the wall, 5 cm and 2 cm clear of it
        plate_far = _extent_along(fp_p, u)[1]
        bin_near = _extent_along(_footprint(bin_xy, spec.bin.outer_size_m[:2]), u)[0]
        if plate_far <= d - t / 2 - 0.05 and bin_near >= d + t / 2 + 0.02:
            break
    else:
        raise SuiteError("window family: no draw of 'families.window.ranges' (bin_azimuth_deg, bin_distance_m, "
                         "wall_distance_m) leaves the plate and the bin on their sides of the wall in 200 draws")
    zt = min(zb + hw, H - 0.02)
    a, b = off - w / 2, off + w / 2  # the window's sides, along the wall from the bin's line
    parts = {  # name: (centre along the wall, length, bottom, top)
        "wall_left": ((-L + a) / 2, a + L, 0.0, H),
        "wall_right": ((b + L) / 2, L - b, 0.0, H),
        "wall_sill": (off, w, 0.0, zb),
        "wall_lintel": (off, w, zt, H),
    }
    yaw = az + math.pi / 2
    extra = [_box(n, (*(d * u + c * v), (z0 + z1) / 2), (sx, t, z1 - z0), WALL_COLOR, yaw=yaw)
             for n, (c, sx, z0, z1) in parts.items() if z1 - z0 > 1e-6 and sx > 1e-6]
    # the middle waypoint is in the window: the held can's bottom hangs about 0.14 m below the
    # gripper frame and the wrist stands about 0.33 m above it; the stack is centred in the opening
    z_mid = zb + 0.14 + max(0.0, (zt - zb - 0.47) / 2)
    middle = (*(d * u + off * v), z_mid)
    return _with_layout(spec, plate_xy=spec.plate.center_m[:2], bin_xy=bin_xy, middle_m=middle, extra=extra)


def _footprint_radius(shape: str, size) -> float:
    """The bounding radius in the floor plane of an upright cylinder (radius, length) or a box."""
    return size[0] if shape == "cylinder" else 0.5 * math.hypot(size[0], size[1])


def _place_on_plate(spec: SceneSpec, radius: float, placed: list[tuple[np.ndarray, float]],
                    rng: np.random.Generator) -> np.ndarray | None:
    """A footprint centre on the plate, `radius` plus the edge margin inside its edges and 1 cm
    clear of every placed footprint (centre, radius): up to 200 uniform draws; None if none fits."""
    cx, cy, _ = spec.plate.center_m
    sx, sy = spec.plate.size_m[:2]
    m = radius + spec.cans.edge_margin_m
    for _ in range(200):
        p = np.array([rng.uniform(cx - sx / 2 + m, cx + sx / 2 - m), rng.uniform(cy - sy / 2 + m, cy + sy / 2 - m)])
        if all(np.linalg.norm(p - q) >= radius + r + 0.01 for q, r in placed):
            return p
    return None


def _draw_clutter(ranges: ClutterRanges, spec: SceneSpec, rng: np.random.Generator) -> SceneSpec:
    n_cans = int(rng.integers(ranges.cans[0], ranges.cans[1] + 1))
    gap = _u(rng, ranges.min_gap_m)
    n_dis = int(rng.integers(ranges.distractors[0], ranges.distractors[1] + 1))
    top = spec.plate_top_z_m
    extra: list[Obstacle] = []
    placed: list[tuple[np.ndarray, float]] = []  # footprint centre, bounding radius
    kinds = sorted(DISTRACTORS)
    for i in range(n_dis):
        model = DISTRACTORS[kinds[int(rng.integers(len(kinds)))]]
        size = tuple(_u(rng, r) for r in model["size"])
        color = model["colors"][int(rng.integers(len(model["colors"])))]
        yaw = float(rng.uniform(-math.pi, math.pi))
        radius = _footprint_radius(model["shape"], size)
        height = size[1] if model["shape"] == "cylinder" else size[2]
        p = _place_on_plate(spec, radius, placed, rng)
        if p is None:
            continue
        placed.append((p, radius))
        X = _rz(yaw, (p[0], p[1], top + height / 2))
        extra.append(Obstacle(f"distractor_{i}", model["shape"], size, pose_tuple(X), tuple(color)))
    cans = dataclasses.replace(spec.cans, count=n_cans, min_gap_m=gap)
    wp = spec.waypoints
    return _with_layout(spec, plate_xy=spec.plate.center_m[:2], bin_xy=spec.bin.center_xy_m,
                        middle_m=wp.middle_m, extra=extra, cans=cans)

def _draw_lookalike(ranges: LookalikeRanges, spec: SceneSpec, rng: np.random.Generator) -> SceneSpec:
    """Clutter's draw, then hourglasses and dented cans (upright or lying, with the cans' lying
    probability) placed clear of the distractors and of each other, 1 cm apart at least."""
    from scenes import lookalikes as la

    drawn = _draw_clutter(ranges, spec, rng)
    r, h, top = spec.can.radius_m, spec.can.height_m, spec.plate_top_z_m
    placed = [(o.pose()[:2, 3], _footprint_radius(o.shape, o.size_m)) for o in drawn.extra]
    extra = list(drawn.extra)
    n_hour = int(rng.integers(ranges.hourglasses[0], ranges.hourglasses[1] + 1))
    n_dent = int(rng.integers(ranges.dented[0], ranges.dented[1] + 1))
    for i, kind in enumerate(["hourglass"] * n_hour + ["dented"] * n_dent):
        lying = kind == "dented" and rng.random() < spec.cans.lying_probability
        radius = h / 2 if lying else r
        p = _place_on_plate(spec, radius, placed, rng)
        if p is None:
            continue
        placed.append((p, radius))
        yaw = float(rng.uniform(-math.pi, math.pi))
        band = float(rng.uniform(-0.15, 0.15)) * h
        if kind == "hourglass":
            extra += la.hourglass(i, p_xy_m=p, plate_top_z_m=top, radius_m=r, height_m=h, color_rgba=spec.can.color_rgba,
                                  waist_fraction=ranges.hourglass_waist)
        elif lying:  # the dent faces up, within 60 degrees (what the top camera sees of it), or any way
            X = la.lying_frame(p_xy_m=p, yaw_rad=yaw, plate_top_z_m=top, radius_m=r, roll_rad=0.0)
            u = float(rng.uniform(-1.0, 1.0))
            turn = u * math.pi / 3 if ranges.lying_dent == "up" else u * math.pi
            extra += la.dented_can(i, X_WC=X, dent_dir_rad=math.pi + turn,
                                   band_center_m=band, radius_m=r, height_m=h, color_rgba=spec.can.color_rgba)
        else:
            X = _rz(0.0, (p[0], p[1], top + h / 2))
            extra += la.dented_can(i, X_WC=X, dent_dir_rad=yaw, band_center_m=band, radius_m=r, height_m=h,
                                   color_rgba=spec.can.color_rgba)
    return dataclasses.replace(drawn, extra=tuple(extra))


DRAWERS = {StationRanges: _draw_station, ShelfRanges: _draw_shelf, WindowRanges: _draw_window, ClutterRanges: _draw_clutter,
           LookalikeRanges: _draw_lookalike}


def draw_station(spec: SceneSpec, rng: np.random.Generator) -> SceneSpec:
    """The concrete station of a family spec (spec.family set), drawn from `rng`."""
    if spec.family is None:
        return spec
    spec.require("plate", "bin", "can", "cans", "waypoints", needed_by=f"family {spec.variant!r} (a drawn can station)")
    return DRAWERS[type(spec.family)](spec.family, spec, rng)
