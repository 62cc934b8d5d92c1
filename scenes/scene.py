"""A concrete scene: a spec plus the cans a seed put on the plate (the ground truth; none for a
world without cans)."""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import math

import numpy as np

from scenes.robot_model import rpy_to_matrix
from scenes.spec import SceneSpec


@dataclasses.dataclass(frozen=True)
class CanPose:
    """Ground truth of one can.

    Attributes:
        id: index of the can in its scene.
        p_WC_m: the can's centre (the middle of its axis) in the world, metres.
        lying: True if the can lies on its side, False if it stands upright.
        axis_yaw_rad: direction of the can's axis in the xy plane, measured from world +x
            (meaningful for lying cans; for upright cans it only turns the cylinder about its axis).
    """

    id: int
    p_WC_m: tuple[float, float, float]
    lying: bool
    axis_yaw_rad: float

    def X_WC(self) -> np.ndarray:
        """The can's pose (4, 4): its frame's z axis is the cylinder axis."""
        X = np.eye(4)
        # Lying: the cylinder axis (z) is turned onto the horizontal direction at axis_yaw.
        rpy = (0.0, math.pi / 2, self.axis_yaw_rad) if self.lying else (0.0, 0.0, self.axis_yaw_rad)
        X[:3, :3] = rpy_to_matrix(rpy)
        X[:3, 3] = self.p_WC_m
        return X

    def top_z_m(self, radius_m: float, height_m: float) -> float:
        """Height of the can's highest point."""
        return self.p_WC_m[2] + (radius_m if self.lying else height_m / 2)

    def to_json(self) -> dict:
        return {
            "id": self.id,
            "p_WC_m": [round(v, 6) for v in self.p_WC_m],
            "lying": self.lying,
            "axis_yaw_rad": round(self.axis_yaw_rad, 6),
        }


@dataclasses.dataclass(frozen=True)
class HeldCan:
    """A can carried in the gripper: the can and its pose in the gripper frame G (4, 4)."""

    can: CanPose
    X_GC: np.ndarray

    @staticmethod
    def from_grasp(can: CanPose, X_WG: np.ndarray) -> "HeldCan":
        """The can as it sits in a gripper that closed on it at X_WG."""
        return HeldCan(can, np.linalg.solve(X_WG, can.X_WC()))


@dataclasses.dataclass(frozen=True)
class Scene:
    """A spec, the seed that scattered its cans, and the cans themselves."""

    spec: SceneSpec
    seed: int
    cans: tuple[CanPose, ...]

    @property
    def variant(self) -> str:
        return self.spec.variant

    def without_cans(self, ids) -> "Scene":
        """The same scene with some cans removed (e.g. already recycled)."""
        ids = set(ids)
        return dataclasses.replace(self, cans=tuple(c for c in self.cans if c.id not in ids))

    def key(self) -> str:
        """A short content hash of the scene (spec and cans): identifies it across processes."""
        return self._key

    @functools.cached_property
    def _key(self) -> str:
        # Computed once per instance (hashing the spec's JSON costs ~2 ms); cached_property writes
        # the instance __dict__ directly, which a frozen dataclass allows.
        truth = {k: v for k, v in self.to_json().items() if k not in ("obstacles", "waypoints_m")}  # in the spec
        blob = json.dumps({"spec": self.spec.to_dict(), "truth": truth}, sort_keys=True, default=list)
        return hashlib.sha1(blob.encode()).hexdigest()[:16]

    def to_json(self) -> dict:
        """The ground truth as printed by `python -m suite scene --json`: the plate, the cans, every
        static obstacle as a primitive (`{"name", "shape", "size_m", "X_WO"}`, X_WO row-major) and
        the task waypoints (gripper positions); a scene without a plate or waypoints has no such
        entry (the entries of a can station are as before they became optional: its key is too)."""
        spec = self.spec
        out: dict = {"seed": self.seed, "variant": self.variant}
        if spec.plate is not None:
            out["plate"] = {
                "center_m": [spec.plate.center_m[0], spec.plate.center_m[1], spec.plate_top_z_m],
                "size_m": [spec.plate.size_m[0], spec.plate.size_m[1]],
            }
        out["cans"] = [c.to_json() for c in self.cans]
        out["obstacles"] = [o.to_json() for o in spec.obstacles()]
        if spec.waypoints is not None:
            out["waypoints_m"] = {k: [round(v, 6) for v in p] for k, p in dataclasses.asdict(spec.waypoints).items()}
        return out

