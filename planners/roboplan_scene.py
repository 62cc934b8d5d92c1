"""roboplan's scene of a problem, built from the suite's own models with the python-fcl world's geometry.

`roboplan` (optional extra `peers`) checks collisions with coal on a pinocchio model. This module
gives it exactly the primitives, poses and filtered pairs of `scenes.collision.world.CollisionWorld`:

- The robot is written out as URDF (version 1.1, so that urdfdom reads capsules) from
  `scenes.robot_model.load_robot()`: the iiwa's links and joints, the WSG body welded to link 7 at
  `X_7G`, both fingers welded to the body at the problem's opening (`finger_offsets`), and the
  held can (the world's grown cylinder) welded to the body at `X_GC`. Everything the gripper
  carries is in the URDF, never added with `Scene.add*Geometry` on a frame: roboplan 0.7.0 stores
  an added geometry's `tform` as its placement in the parent *joint*'s frame, so geometry added on
  a frame that is offset from its joint (the gripper body, 0.09 m beyond joint 7) sits silently
  off by that offset (a can 9 cm off). pinocchio's URDF parser composes fixed joints correctly.
- The scene's obstacles (static boxes, the family's extras, the cans left on the plate) are
  added on `universe`, the world frame, which is its own joint frame: their poses are exact.
- The allowed (filtered) pairs are the world's: pairs joined by a joint, `ALWAYS_TOUCHING`, the
  gripper assembly among itself, the base against every obstacle, the held can against the
  plate, and the obstacles among themselves (roboplan checks every pair it is not told to skip).

`tests/planners/test_roboplan_rrt.py` checks the placements with probe spheres against the
python-fcl world; `python -m suite bench agreement` compares both engines' verdicts on many
configurations.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import roboplan.core as rpc

from scenes.collision.shapes import grown_dims
from scenes.collision.world import GRIPPER_ASSEMBLY
from scenes.robot_model import RobotModel, load_robot, matrix_to_rpy

#: The world frame of a pinocchio model (its joint 0).
WORLD_FRAME = "universe"
HELD_CAN = "held_can"
_GREY = np.array([0.6, 0.6, 0.6, 1.0])


def _origin_xml(X: np.ndarray) -> str:
    xyz = " ".join(repr(float(v)) for v in X[:3, 3])
    rpy = " ".join(repr(float(v)) for v in matrix_to_rpy(X[:3, :3]))
    return f'<origin xyz="{xyz}" rpy="{rpy}"/>'


def _geometry_xml(kind: str, dims) -> str:
    if kind == "box":
        return f'<box size="{" ".join(repr(float(v)) for v in dims)}"/>'
    if kind in ("cylinder", "capsule"):
        return f'<{kind} radius="{float(dims[0])!r}" length="{float(dims[1])!r}"/>'
    if kind == "sphere":
        return f'<sphere radius="{float(dims[0])!r}"/>'
    raise ValueError(f"unsupported shape {kind!r}")


def robot_urdf(robot: RobotModel, *, opening_m: float, held_X_GC: np.ndarray | None,
               held_dims: tuple[float, float] | None) -> str:
    """The arm, gripper (fingers welded at `opening_m`) and held can as one URDF (version 1.1)."""
    finger_X = robot.finger_offsets(opening_m)
    shapes: dict[str, list] = {}
    for sh in robot.shapes:
        shapes.setdefault(sh.body, []).append((sh.kind, sh.dims, sh.X_BS))
    if held_X_GC is not None:
        shapes[HELD_CAN] = [("cylinder", held_dims, np.eye(4))]
    links = [*robot.body_names, *([HELD_CAN] if held_X_GC is not None else [])]
    out = ['<?xml version="1.0"?>', '<robot name="iiwa_wsg" version="1.1">']
    for name in links:
        cols = "".join(f"<collision>{_origin_xml(X)}<geometry>{_geometry_xml(kind, dims)}</geometry></collision>"
                       for kind, dims, X in shapes.get(name, []))
        # a unit inertia: pinocchio needs none for kinematics, but a massless leaf link warns
        out.append(f'<link name="{name}"><inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" ixy="0" '
                   f'ixz="0" iyz="0"/></inertial>{cols}</link>')
    for j in robot.joints:
        out.append(f'<joint name="{j.name}" type="revolute"><parent link="{j.parent}"/><child link="{j.child}"/>'
                   f'{_origin_xml(j.X_origin)}<axis xyz="0 0 1"/><limit lower="{j.lower_rad!r}" upper="{j.upper_rad!r}" '
                   f'velocity="{j.velocity_rad_s!r}" effort="{j.effort_nm!r}"/></joint>')
    fixed = [("iiwa_link_7", "body", robot.X_7G)] + [("body", f, X) for f, X in finger_X.items()]
    if held_X_GC is not None:
        fixed.append(("body", HELD_CAN, np.asarray(held_X_GC, float)))
    for parent, child, X in fixed:
        out.append(f'<joint name="{parent}_to_{child}" type="fixed"><parent link="{parent}"/><child link="{child}"/>'
                   f"{_origin_xml(X)}</joint>")
    out.append("</robot>")
    return "\n".join(out)


@dataclasses.dataclass
class RoboplanWorld:
    """roboplan's scene of one collision world, and what it was built from.

    Attributes:
        scene: the `roboplan.core.Scene` (the arm's 7 joints are its whole configuration).
        urdf: the robot's URDF as given to roboplan.
        obstacles: (name, shape, size, X_WO) of every obstacle added on `universe`.
        robot_bodies: the robot's body names (links, gripper body, fingers, held can).
        allowed: the body pairs whose collisions are ignored (as the python-fcl world filters them).
    """

    scene: object
    urdf: str
    obstacles: list[tuple[str, str, tuple, np.ndarray]]
    robot_bodies: tuple[str, ...]
    allowed: list[tuple[str, str]]

    def is_free(self, q: np.ndarray) -> bool:
        """True if roboplan finds no collision at q (7,) rad."""
        return not self.scene.hasCollisions(np.asarray(q, float))


def build_roboplan_world(world, *, robot: RobotModel | None = None) -> RoboplanWorld:
    """roboplan's scene with the geometry of a python-fcl `CollisionWorld` (its robot, opening,
    held can, obstacles and filtered pairs)."""
    robot = robot or world.robot or load_robot()
    spec = world.scene.spec
    held = world.held
    held_dims = None
    if held is not None:
        m = spec.grasp.held_margin_m
        held_dims = (spec.can.radius_m + m, spec.can.height_m + 2 * m)
    urdf = robot_urdf(robot, opening_m=world.gripper_opening_m, held_X_GC=None if held is None else held.X_GC,
                      held_dims=held_dims)
    scene = rpc.Scene("suite", rpc.loadUrdfSceneDescriptionFromXml(urdf))
    bodies = (*robot.body_names, *([HELD_CAN] if held is not None else ()))
    obstacles = []
    for name, obj in world.obstacles:
        shape, size, X = obstacle_primitive(world, name)
        if world.padding_m:
            size = grown_dims(shape, size, world.padding_m)
        _add(scene, name, shape, size, X)
        obstacles.append((name, shape, size, X))
    allowed = allowed_pairs(robot, bodies, [o[0] for o in obstacles])
    scene.setCollisions(allowed, False)
    return RoboplanWorld(scene, urdf, obstacles, bodies, allowed)


def obstacle_primitive(world, name: str) -> tuple[str, tuple, np.ndarray]:
    """An obstacle of the world as (shape, size, X_WO), from the scene spec (as the world built it)."""
    spec = world.scene.spec
    for o in spec.obstacles():
        if o.name == name:
            return o.shape, tuple(o.size_m), o.pose()
    for c in world.scene.cans:
        if name == f"can_{c.id}":
            return "cylinder", (spec.can.radius_m, spec.can.height_m), c.X_WC()
    raise ValueError(f"obstacle {name!r} is neither a spec obstacle nor a can")


def _add(scene, name: str, shape: str, size, X: np.ndarray) -> None:
    X = np.asfortranarray(X, float)
    if shape == "box":
        scene.addBoxGeometry(name, WORLD_FRAME, rpc.Box(*map(float, size)), X, _GREY)
    elif shape == "cylinder":
        scene.addCylinderGeometry(name, WORLD_FRAME, rpc.Cylinder(float(size[0]), float(size[1])), X, _GREY)
    elif shape == "sphere":
        scene.addSphereGeometry(name, WORLD_FRAME, rpc.Sphere(float(size[0])), X, _GREY)
    else:
        raise ValueError(f"unsupported obstacle shape {shape!r} ({name})")


def allowed_pairs(robot: RobotModel, bodies, obstacle_names) -> list[tuple[str, str]]:
    """The pairs the python-fcl world leaves out (`CollisionWorld.__init__`), by body name."""
    out = []
    for a, b in itertools.combinations(bodies, 2):
        if frozenset((a, b)) in robot.filtered_pairs or (a in GRIPPER_ASSEMBLY and b in GRIPPER_ASSEMBLY):
            out.append((a, b))
    out += [("iiwa_link_0", o) for o in obstacle_names]
    out += list(itertools.combinations(obstacle_names, 2))  # the static world never moves
    if HELD_CAN in bodies and "plate" in obstacle_names:
        out.append((HELD_CAN, "plate"))
    return out
