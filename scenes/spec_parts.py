"""The sections of a scene spec, each a typed dataclass that validates itself (`scenes.schema`):
boxes and obstacles, the plate's and the bin's geometry, the can model and generator, the grasp
offsets, the task waypoints, the cameras and the hand-placed region seeds. `scenes.spec.SceneSpec`
puts them together."""

from __future__ import annotations

import dataclasses
from typing import Annotated, Literal

import numpy as np
from pydantic import Field

from scenes.schema import FieldError, NonNeg, NonNegInt, Pos, PosInt, PosVec3, Rgba, Unit, Vec2, Vec3
from scenes.sensor import SensorSpec


@dataclasses.dataclass(frozen=True)
class Box:
    """An axis-aligned box: centre and full size in metres."""

    center_m: Vec3
    size_m: PosVec3
    color_rgba: Rgba


@dataclasses.dataclass(frozen=True)
class Table:
    """The table as a spec file gives it: a box whose top face is the plane z = 0."""

    size_m: PosVec3
    center_xy_m: Vec2
    color_rgba: Rgba

    def box(self) -> Box:
        return Box((self.center_xy_m[0], self.center_xy_m[1], -self.size_m[2] / 2), self.size_m, self.color_rgba)


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
    shape: Literal["box", "cylinder", "sphere"]
    size_m: tuple[Pos, ...]
    X_WO: tuple[tuple[float, float, float, float], ...]
    color_rgba: Rgba

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

    center_xy_m: Vec2
    outer_size_m: PosVec3
    wall_thickness_m: Pos
    color_rgba: Rgba
    #: the floor's thickness when it is not the walls' (the GCS paper's bins: 0.015 under 0.05 walls)
    floor_thickness_m: Pos | None = None

    def __post_init__(self):
        inner = min(self.outer_size_m[:2])
        if 2 * self.wall_thickness_m >= inner:
            raise FieldError("wall_thickness_m", f"leaves no room inside the bin: allowed below half of {inner}")
        if self.floor_thickness_m is not None and self.floor_thickness_m >= self.outer_size_m[2]:
            raise FieldError("floor_thickness_m", f"{self.floor_thickness_m}: allowed below the bin's height {self.outer_size_m[2]}")

    @property
    def floor_m(self) -> float:
        """The floor's thickness (the walls' unless given)."""
        return self.wall_thickness_m if self.floor_thickness_m is None else self.floor_thickness_m

    def boxes(self) -> dict[str, Box]:
        """The bin as five boxes (floor and four walls), keyed by part name."""
        cx, cy = self.center_xy_m
        sx, sy, sz = self.outer_size_m
        t = self.wall_thickness_m
        c = self.color_rgba
        return {
            "bin_floor": Box((cx, cy, self.floor_m / 2), (sx, sy, self.floor_m), c),
            "bin_wall_xneg": Box((cx - sx / 2 + t / 2, cy, sz / 2), (t, sy, sz), c),
            "bin_wall_xpos": Box((cx + sx / 2 - t / 2, cy, sz / 2), (t, sy, sz), c),
            "bin_wall_yneg": Box((cx, cy - sy / 2 + t / 2, sz / 2), (sx - 2 * t, t, sz), c),
            "bin_wall_ypos": Box((cx, cy + sy / 2 - t / 2, sz / 2), (sx - 2 * t, t, sz), c),
        }


@dataclasses.dataclass(frozen=True)
class CanModel:
    """The can: a solid cylinder of this radius and height (metres), mass (kg) and colour."""

    radius_m: Pos
    height_m: Pos
    mass_kg: Pos
    color_rgba: Rgba


@dataclasses.dataclass(frozen=True)
class CanGenerator:
    """How cans are scattered on the plate."""

    count: NonNegInt
    min_gap_m: NonNeg
    edge_margin_m: NonNeg
    lying_probability: Unit
    #: "random": cans anywhere apart from each other (the paper's plate); "pickable": each new can
    #: is placed where the open gripper can descend onto it past the cans already placed, so that
    #: picking in the reverse order of placement is collision-free (dense plates, `clutter`)
    placement: Literal["random", "pickable"] = "random"


@dataclasses.dataclass(frozen=True)
class GraspSpec:
    """The grasp rule's offsets (metres), and the padding of a carried can in every collision
    model (`held_margin_m`: execution leaves the planned path by a few millimetres)."""

    top_offset_m: NonNeg
    pregrasp_height_m: Pos
    open_width_m: Pos
    held_margin_m: NonNeg


@dataclasses.dataclass(frozen=True)
class Waypoints:
    """Gripper positions of the nominal cycle; the gripper points straight down at each."""

    above_plate_m: Vec3
    middle_m: Vec3
    above_bin_m: Vec3


@dataclasses.dataclass(frozen=True)
class CameraPose:
    """A camera at `p_m` looking at `target_m` (world frame, metres)."""

    p_m: Vec3
    target_m: Vec3

    def __post_init__(self):
        if tuple(self.p_m) == tuple(self.target_m):
            raise FieldError("target_m", "allowed: a target apart from p_m")


@dataclasses.dataclass(frozen=True)
class CameraSpec:
    """The RGB-D cameras: shared intrinsics and one pose per named camera."""

    width_px: PosInt
    height_px: PosInt
    fov_y_deg: Annotated[float, Field(gt=0, lt=180)]
    clipping_m: tuple[Pos, Pos]
    poses: Annotated[dict[str, CameraPose], Field(min_length=1)]
    #: what a real sensor does to the rendered frames (`scenes.sensor`); None: a perfect sensor.
    #: Left out of `SceneSpec.to_dict` while None, so scene keys do not change.
    sensor: SensorSpec | None = None

    def __post_init__(self):
        if self.clipping_m[0] >= self.clipping_m[1]:
            raise FieldError("clipping_m", "allowed: [near, far] with near < far")


Vec7 = tuple[float, float, float, float, float, float, float]


@dataclasses.dataclass(frozen=True)
class SeedPose:
    """A gripper pose: position (m) and roll-pitch-yaw (rad, fixed axes x, y, z) of the gripper
    frame G in the world."""

    p_m: Vec3
    rpy_rad: Vec3


@dataclasses.dataclass(frozen=True)
class RegionSeeds:
    """A scene's own seeds for `gcs`'s regions, placed by hand as the GCS paper placed its eight:
    gripper poses (solved by the paper's IK recipe, `scenes.ik.paper_ik`: exact position,
    orientation within 1 mrad, nearest to `q0_rad`) and joint-space configurations. They belong
    to the scene, like its task waypoints, not to any problem.
    """

    q0_rad: Vec7
    poses: dict[str, SeedPose]
    joints_rad: dict[str, Vec7]
