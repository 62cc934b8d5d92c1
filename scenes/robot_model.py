"""The robot as data, read from the project's own model files, with fast numpy kinematics.

One source of truth: a robot variant's model files (`ROBOTS`: the project's own
`models/iiwa14.urdf` and `models/wsg50.urdf` by default) are parsed here for the kinematic chain,
the joint limits and the collision primitives; the Drake scene parses the same files. The forward
kinematics below serves the python-fcl world and the metrics, where calling into Drake per
configuration would cost more than the computation itself.

Frames: W world (= robot base link_0), L_i link i, G the gripper frame (WSG body: +y from the
palm towards the finger tips, x the closing axis).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

MODELS_DIR = Path(__file__).parent / "models"
IIWA_URDF = MODELS_DIR / "iiwa14.urdf"
WSG_URDF = MODELS_DIR / "wsg50.urdf"
DRAKE_NS = "{http://drake.mit.edu}"

#: The WSG body frame G in link 7's frame: 0.09 m along z, rpy (90 deg, 0, 90 deg) (facts sheet).
GRIPPER_MOUNT_XYZ = (0.0, 0.0, 0.09)
GRIPPER_MOUNT_RPY = (math.pi / 2, 0.0, math.pi / 2)

#: Robot body pairs that touch in every configuration, filtered in both collision engines
#: (besides the pairs joined by a joint, which are adjacent). Link 6's capsule end cap lies
#: around joint 7 and so inside the gripper body whatever q7 is; the two fingers are allowed
#: to meet when the gripper is closed.
ALWAYS_TOUCHING = (("iiwa_link_6", "body"), ("left_finger", "right_finger"))


@dataclasses.dataclass(frozen=True)
class RobotVariant:
    """A robot's model files and how the gripper is mounted and filtered.

    Attributes:
        name: as a scene spec names it (`robot:`).
        iiwa_urdf, wsg_urdf: the arm's and the gripper's model files.
        mount_xyz, mount_rpy: the gripper frame G (the WSG body) in link 7's frame.
        filtered: body pairs never checked against each other, besides adjacent pairs.
        about: one line: what it is and where its numbers come from.
    """

    name: str
    iiwa_urdf: Path
    wsg_urdf: Path
    mount_xyz: tuple[float, float, float]
    mount_rpy: tuple[float, float, float]
    filtered: tuple[tuple[str, str], ...]
    about: str


DEFAULT_ROBOT = "iiwa14-wsg"
#: The robot variants a scene may use. The GCS paper's (`iiwa14-spheres`): Drake's sphere model of
#: the iiwa 14 and the WSG 50 with welded fingers, welded at [0, 0, 0.114] with roll 90 deg, and
#: Drake's `wrist` group (links 5, 6, 7) filtered (docs/gcs-paper-sources.md sections 1a, 5, 6).
ROBOTS = {
    DEFAULT_ROBOT: RobotVariant(
        DEFAULT_ROBOT, IIWA_URDF, WSG_URDF, GRIPPER_MOUNT_XYZ, GRIPPER_MOUNT_RPY, ALWAYS_TOUCHING,
        "the project's iiwa 14 (capsules) with a WSG 50 whose fingers slide"),
    "iiwa14-spheres": RobotVariant(
        "iiwa14-spheres", MODELS_DIR / "iiwa14_spheres.urdf", MODELS_DIR / "wsg50_welded.urdf",
        (0.0, 0.0, 0.114), (math.pi / 2, 0.0, 0.0),
        (("iiwa_link_5", "iiwa_link_7"),),
        "the GCS paper's: iiwa 14 as a cylinder and 12 spheres, WSG 50 with welded fingers (boxes)"),
}


def robot_variant(name: str) -> RobotVariant:
    """The variant called `name`.

    Raises:
        ValueError: naming the bad name and the allowed ones.
    """
    try:
        return ROBOTS[name]
    except KeyError:
        raise ValueError(f"robot {name!r} is not a robot variant; allowed: {', '.join(ROBOTS)}") from None


def rpy_to_matrix(rpy: tuple[float, float, float] | np.ndarray) -> np.ndarray:
    """Rotation matrix for URDF roll-pitch-yaw (fixed axes x, y, z): R = Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def matrix_to_rpy(R: np.ndarray) -> np.ndarray:
    """Roll-pitch-yaw (URDF convention) of a rotation matrix."""
    pitch = math.atan2(-R[2, 0], math.hypot(R[0, 0], R[1, 0]))
    if abs(math.cos(pitch)) < 1e-9:  # gimbal lock: put everything in yaw
        return np.array([0.0, pitch, math.atan2(-R[0, 1], R[1, 1])])
    return np.array([math.atan2(R[2, 1], R[2, 2]), pitch, math.atan2(R[1, 0], R[0, 0])])


def transform(xyz, rpy) -> np.ndarray:
    """4x4 homogeneous transform from a translation and URDF roll-pitch-yaw."""
    X = np.eye(4)
    X[:3, :3] = rpy_to_matrix(rpy)
    X[:3, 3] = xyz
    return X


@dataclasses.dataclass(frozen=True)
class Shape:
    """A collision primitive fixed to a body.

    kind is "box" (dims = full sizes x, y, z), "cylinder" or "capsule" (dims = radius, length
    along the shape's z), or "sphere" (dims = radius). X_BS is its pose in the body frame.
    """

    body: str
    kind: str
    dims: tuple[float, ...]
    X_BS: np.ndarray


@dataclasses.dataclass(frozen=True)
class Joint:
    """A revolute joint about its own z axis: X_PC(q) = X_origin Rz(q)."""

    name: str
    parent: str
    child: str
    X_origin: np.ndarray
    lower_rad: float
    upper_rad: float
    velocity_rad_s: float
    acceleration_rad_s2: float
    effort_nm: float


def _floats(text: str | None, n: int, default: float = 0.0) -> tuple[float, ...]:
    if text is None:
        return (default,) * n
    vals = tuple(float(v) for v in text.split())
    if len(vals) != n:
        raise ValueError(f"expected {n} numbers, got {text!r}")
    return vals


def _origin(el: ET.Element | None) -> np.ndarray:
    if el is None:
        return np.eye(4)
    return transform(_floats(el.get("xyz"), 3), _floats(el.get("rpy"), 3))


def _shapes(root: ET.Element) -> list[Shape]:
    out = []
    for link in root.findall("link"):
        for col in link.findall("collision"):
            geom = col.find("geometry")
            (g,) = list(geom)
            if g.tag == "box":
                dims = _floats(g.get("size"), 3)
            elif g.tag in ("cylinder", "capsule"):
                dims = (float(g.get("radius")), float(g.get("length")))
            elif g.tag == "sphere":
                dims = (float(g.get("radius")),)
            else:
                raise ValueError(f"unsupported collision geometry <{g.tag}> in link {link.get('name')}")
            out.append(Shape(link.get("name"), g.tag, dims, _origin(col.find("origin"))))
    return out


@dataclasses.dataclass(frozen=True)
class RobotModel:
    """The iiwa 14 with the WSG 50 on its flange.

    Bodies are ordered: iiwa_link_0 .. iiwa_link_7, body (gripper frame G), left_finger,
    right_finger. The fingers' poses depend on the gripper opening, not on q.
    """

    joints: tuple[Joint, ...]
    shapes: tuple[Shape, ...]
    body_names: tuple[str, ...]
    X_7G: np.ndarray
    X_7F: np.ndarray  # the tool flange in link 7
    filtered_pairs: frozenset[frozenset[str]]
    #: the variant's name (`ROBOTS`)
    name: str = DEFAULT_ROBOT
    #: X_GF of each finger when the fingers are welded (then the opening changes nothing)
    welded_fingers: tuple[tuple[str, np.ndarray], ...] = ()

    @property
    def lower_rad(self) -> np.ndarray:
        return np.array([j.lower_rad for j in self.joints])

    @property
    def upper_rad(self) -> np.ndarray:
        return np.array([j.upper_rad for j in self.joints])

    @property
    def velocity_limits_rad_s(self) -> np.ndarray:
        return np.array([j.velocity_rad_s for j in self.joints])

    @property
    def acceleration_limits_rad_s2(self) -> np.ndarray:
        return np.array([j.acceleration_rad_s2 for j in self.joints])

    def body_index(self, name: str) -> int:
        return self.body_names.index(name)

    @functools.cached_property
    def _fk_terms(self) -> np.ndarray:
        # X_origin Rz(q) = A cos q + B sin q + C: stacked per joint as (7, 3, 16) so that one
        # matmul with [cos q, sin q, 1] builds all seven local transforms.
        Ec = np.diag([1.0, 1.0, 0.0, 0.0])
        Es = np.zeros((4, 4))
        Es[0, 1], Es[1, 0] = -1.0, 1.0
        E1 = np.diag([0.0, 0.0, 1.0, 1.0])
        O = np.stack([j.X_origin for j in self.joints])
        return np.stack([(O @ E).reshape(7, 16) for E in (Ec, Es, E1)], axis=1)

    def link_poses(self, q: np.ndarray) -> np.ndarray:
        """Poses of link_0..link_7 and the gripper body G in the world.

        Args:
            q: joint positions (7,) in rad, or a batch (M, 7).

        Returns:
            X_WB as (9, 4, 4), or (M, 9, 4, 4) for a batch.
        """
        q = np.asarray(q, dtype=float)
        w = np.empty(q.shape + (1, 3))
        w[..., 0, 0] = np.cos(q)
        w[..., 0, 1] = np.sin(q)
        w[..., 0, 2] = 1.0
        local = (w @ self._fk_terms).reshape(q.shape + (4, 4))  # (..., 7, 4, 4)
        out = np.empty(q.shape[:-1] + (9, 4, 4))
        out[..., 0, :, :] = np.eye(4)
        out[..., 1, :, :] = local[..., 0, :, :]
        for i in range(1, 7):
            np.matmul(out[..., i, :, :], local[..., i, :, :], out=out[..., i + 1, :, :])
        np.matmul(out[..., 7, :, :], self.X_7G, out=out[..., 8, :, :])
        return out

    def gripper_pose(self, q: np.ndarray) -> np.ndarray:
        """X_WG (4, 4) for one configuration, or (M, 4, 4) for a batch."""
        return self.link_poses(q)[..., 8, :, :]

    def flange_pose(self, q: np.ndarray) -> np.ndarray:
        """X_WF, the tool flange (4, 4) for one configuration, or (M, 4, 4) for a batch."""
        return self.link_poses(q)[..., 7, :, :] @ self.X_7F

    def finger_offsets(self, opening_m: float) -> dict[str, np.ndarray]:
        """X_GF for each finger at a given opening (finger inner faces at x = -+opening/2); a
        welded gripper's fixed poses whatever the opening."""
        if self.welded_fingers:
            return {name: X.copy() for name, X in self.welded_fingers}
        out = {}
        for name, sign in (("left_finger", -1.0), ("right_finger", 1.0)):
            X = np.eye(4)
            X[0, 3] = sign * opening_m / 2
            out[name] = X
        return out

    def random_configurations(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """n configurations uniform within the joint limits, (n, 7) rad."""
        return rng.uniform(self.lower_rad, self.upper_rad, size=(n, 7))


@functools.lru_cache(maxsize=None)
def effort_limits(robot: str = DEFAULT_ROBOT) -> dict[str, float]:
    """Every actuated joint's effort limit (N m or N) from a robot variant's model files."""
    v = robot_variant(robot)
    out = {}
    for path in (v.iiwa_urdf, v.wsg_urdf):
        for j in ET.parse(path).getroot().findall("joint"):
            lim = j.find("limit")
            if j.get("type") != "fixed" and lim is not None and lim.get("effort") is not None:
                out[j.get("name")] = float(lim.get("effort"))
    return out


@functools.lru_cache(maxsize=None)
def load_robot(name: str = DEFAULT_ROBOT) -> RobotModel:
    """Parse a robot variant's iiwa 14 and WSG 50 model files (`ROBOTS`; the project's own by
    default). One model per variant and process (it is immutable).

    Raises:
        ValueError: `name` is not a variant.
    """
    v = robot_variant(name)
    iiwa = ET.parse(v.iiwa_urdf).getroot()
    wsg = ET.parse(v.wsg_urdf).getroot()
    joints = []
    fixed = {}
    for j in iiwa.findall("joint"):
        X = _origin(j.find("origin"))
        parent, child = j.find("parent").get("link"), j.find("child").get("link")
        if j.get("type") == "fixed":
            fixed[child] = (parent, X)
            continue
        axis = _floats(j.find("axis").get("xyz"), 3)
        if axis != (0.0, 0.0, 1.0):
            raise ValueError(f"joint {j.get('name')}: only z-axis revolute joints are supported")
        lim = j.find("limit")
        joints.append(
            Joint(
                name=j.get("name"),
                parent=parent,
                child=child,
                X_origin=X,
                lower_rad=float(lim.get("lower")),
                upper_rad=float(lim.get("upper")),
                velocity_rad_s=float(lim.get("velocity")),
                acceleration_rad_s2=float(lim.get(f"{DRAKE_NS}acceleration")),
                effort_nm=float(lim.get("effort")),
            )
        )
    names = [j.parent for j in joints[:1]] + [j.child for j in joints]
    if names != [f"iiwa_link_{i}" for i in range(8)]:
        raise ValueError(f"unexpected iiwa chain {names}")
    body_names = tuple(names) + ("body", "left_finger", "right_finger")
    adjacent = {frozenset((j.parent, j.child)) for j in joints}
    adjacent.add(frozenset(("iiwa_link_7", "body")))
    welded = []
    for j in wsg.findall("joint"):
        parent, child = j.find("parent").get("link"), j.find("child").get("link")
        adjacent.add(frozenset((parent, child)))
        if j.get("type") == "fixed":
            if parent != "body":
                raise ValueError(f"gripper joint {j.get('name')}: a welded finger must hang on body")
            welded.append((child, _origin(j.find("origin"))))
    filtered = adjacent | {frozenset(p) for p in v.filtered}
    return RobotModel(
        joints=tuple(joints),
        shapes=tuple(_shapes(iiwa) + _shapes(wsg)),
        body_names=body_names,
        X_7G=transform(v.mount_xyz, v.mount_rpy),
        X_7F=fixed["iiwa_link_ee"][1],
        filtered_pairs=frozenset(filtered),
        name=v.name,
        welded_fingers=tuple(welded),
    )
