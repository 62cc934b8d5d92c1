"""The Drake scene built from a `Scene`: plant, scene graph, and the RGB-D cameras.

Two modes share one builder:
- "sim": the cans are free bodies and the gripper fingers slide on their prismatic joints
  (physics, rendering); every arm and finger joint has an actuator with the URDF's effort limit
  (the execution module gives them PD gains);
- "plan": everything but the arm is fixed, so the plant's positions are exactly the 7 arm
  joints: cans welded where they stand, fingers welded at a given opening, and a held can welded
  into the gripper. IK, trajectory optimization and Drake's collision checker use this mode.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from pydrake.geometry import (
    Box as DrakeBox,
    ClippingRange,
    CollisionFilterDeclaration,
    Cylinder,
    DepthRange,
    MakeRenderEngineVtk,
    RenderCameraCore,
    RenderEngineVtkParams,
    ColorRenderCamera,
    DepthRenderCamera,
    SceneGraph,
    Sphere,
)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, AddMultibodyPlantSceneGraph, CoulombFriction, MultibodyPlant
from pydrake.multibody.tree import SpatialInertia, UnitInertia
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.sensors import CameraInfo, RgbdSensor

from scenes.robot_model import effort_limits, load_robot, robot_variant
from scenes.scene import HeldCan, Scene

RENDERER = "vtk"
WELDED_GRIPPER_BODIES = ("iiwa_link_7", "body", "left_finger", "right_finger")


@dataclasses.dataclass
class DrakeScene:
    """Handles to a built diagram. `cameras` maps camera name to its RgbdSensor."""

    diagram: Diagram
    plant: MultibodyPlant
    scene_graph: SceneGraph
    iiwa: object
    wsg: object
    cameras: dict[str, RgbdSensor]
    X_WCameras: dict[str, RigidTransform]
    mode: str


def look_at(p_m, target_m) -> RigidTransform:
    """Pose of a camera at p looking at target in Drake's camera convention.

    Drake's camera frame: +z along the optical axis, +x right, +y down in the image. Image "down"
    is the world's -z projected onto the image plane; for a camera looking straight down (no
    such projection) image down is world -x, so the robot side of the plate is at the bottom.
    """
    p = np.asarray(p_m, float)
    z = np.asarray(target_m, float) - p
    z /= np.linalg.norm(z)
    down = np.array([0.0, 0.0, -1.0])
    y = down - z * (down @ z)
    if np.linalg.norm(y) < 1e-6:
        y = np.array([-1.0, 0.0, 0.0]) - z * (-z[0])
    y /= np.linalg.norm(y)
    x = np.cross(y, z)
    return RigidTransform(RotationMatrix(np.column_stack([x, y, z])), p)


def _add_obstacle(plant, obstacle, friction, body=None):
    """One static obstacle primitive (box, cylinder or sphere) on `body` (the world by default)."""
    X = RigidTransform(obstacle.pose())
    s = obstacle.size_m
    shape = {"box": lambda: DrakeBox(*s), "cylinder": lambda: Cylinder(s[0], s[1]),
             "sphere": lambda: Sphere(s[0])}[obstacle.shape]()
    body = body or plant.world_body()
    plant.RegisterVisualGeometry(body, X, shape, obstacle.name, np.asarray(obstacle.color_rgba))
    return plant.RegisterCollisionGeometry(body, X, shape, obstacle.name, friction)


def _can_inertia(spec) -> SpatialInertia:
    r, h, m = spec.can.radius_m, spec.can.height_m, spec.can.mass_kg
    return SpatialInertia(m, np.zeros(3), UnitInertia.SolidCylinder(r, h, [0, 0, 1]))


def add_scene_to_plant(
    plant: MultibodyPlant,
    scene_graph: SceneGraph,
    scene: Scene,
    *,
    mode: str,
    gripper_opening_m: float | None = None,
    held: HeldCan | None = None,
    couple_fingers: bool = False,
    moving_bin=None,
) -> tuple[object, object]:
    """Add robot, gripper, static world and cans to an unfinalized plant.

    Args:
        plant: the plant, registered with `scene_graph`.
        scene_graph: receives the collision filters shared with the python-fcl world.
        scene: the scene to build.
        mode: "sim" or "plan" (see the module docstring).
        gripper_opening_m: in "plan" mode, the finger opening to weld the fingers at.
        held: in "plan" mode, a can welded into the gripper (it is then not on the plate).
        couple_fingers: in "sim" mode, tie the fingers together (left = -right) as the WSG's
            single drive does; needs a discrete plant with Drake's SAP solver.
        moving_bin: in "sim" mode, a `scenes.moving_bin.MovingBinScenario`: the bin and the person
            holding it become one driven body (`_add_moving_bin`) instead of welded boxes.

    Returns:
        The iiwa and WSG model instances.
    """
    if mode not in ("sim", "plan"):
        raise ValueError(f"mode must be 'sim' or 'plan', got {mode!r}")
    spec = scene.spec
    robot = load_robot(spec.robot)
    variant = robot_variant(spec.robot)
    parser = Parser(plant)
    (iiwa,) = parser.AddModels(str(variant.iiwa_urdf))
    (wsg,) = parser.AddModels(str(variant.wsg_urdf))
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("iiwa_link_0", iiwa))
    plant.WeldFrames(
        plant.GetFrameByName("iiwa_link_7", iiwa),
        plant.GetFrameByName("body", wsg),
        RigidTransform(robot.X_7G),
    )
    if mode == "plan" and not robot.welded_fingers:  # a welded gripper's model file welds them already
        opening = spec.grasp.open_width_m if gripper_opening_m is None else gripper_opening_m
        body_frame = plant.GetFrameByName("body", wsg)
        for name, X_GF in robot.finger_offsets(opening).items():
            plant.RemoveJoint(plant.GetJointByName(f"{name}_sliding_joint", wsg))
            plant.WeldFrames(body_frame, plant.GetFrameByName(name, wsg), RigidTransform(X_GF))

    if mode == "sim":
        efforts = effort_limits(spec.robot)
        for instance in (iiwa, wsg):
            for index in plant.GetJointIndices(instance):
                joint = plant.get_joint(index)
                if joint.name() in efforts:
                    plant.AddJointActuator(f"{joint.name()}_actuator", joint, efforts[joint.name()])
        if couple_fingers:
            plant.AddCouplerConstraint(
                joint0=plant.GetJointByName("left_finger_sliding_joint", wsg),
                joint1=plant.GetJointByName("right_finger_sliding_joint", wsg),
                gear_ratio=-1.0, offset=0.0)

    friction = CoulombFriction(0.9, 0.8)
    # The plate is a body of its own (welded to the world) so that the held-can-vs-plate filter
    # is a filter between two bodies, which Drake's collision checker requires.
    scene_instance = plant.AddModelInstance("scene")
    plate_body = plant.AddRigidBody("plate", scene_instance, SpatialInertia.Zero())
    plant.WeldFrames(plant.world_frame(), plate_body.body_frame())
    if moving_bin is not None and mode != "sim":
        raise ValueError("a moving bin is only modelled in 'sim' mode")
    if moving_bin is not None:
        spec.require("bin", needed_by="a moving bin")
    moving_bodies = _add_moving_bin(plant, spec, moving_bin, friction) if moving_bin is not None else None
    for obstacle in spec.obstacles():
        if moving_bodies is not None and obstacle.name in spec.bin.boxes():
            continue  # on the driven body
        _add_obstacle(plant, obstacle, friction, plate_body if obstacle.name == "plate" else None)

    if mode == "sim":
        # The room's floor (40 m square): a can that falls off the table comes to rest on it, instead of falling
        # for ever (a free body spinning in free fall grows its spin in the discrete solver's
        # explicit gyroscopic terms until its pose is no longer finite). No planner sees it.
        plant.RegisterCollisionGeometry(plant.world_body(), RigidTransform([0.0, 0.0, -ROOM_FLOOR_BELOW_TABLE_M - 0.5]),
                                        DrakeBox(40.0, 40.0, 1.0), "room_floor", friction)

    if scene.cans or held is not None:
        spec.require("can", needed_by="a can in the Drake scene")
        can_shape = Cylinder(spec.can.radius_m, spec.can.height_m)
        color = np.asarray(spec.can.color_rgba)
    held_id = held.can.id if held is not None else None
    cans_instance = plant.AddModelInstance("cans")
    for can in scene.cans:
        if can.id == held_id:
            continue
        body = plant.AddRigidBody(f"can_{can.id}", cans_instance, _can_inertia(spec))
        plant.RegisterVisualGeometry(body, RigidTransform(), can_shape, f"can_{can.id}", color)
        plant.RegisterCollisionGeometry(body, RigidTransform(), can_shape, f"can_{can.id}", friction)
        if mode == "plan":
            plant.WeldFrames(plant.world_frame(), body.body_frame(), RigidTransform(can.X_WC()))
        else:
            plant.SetDefaultFloatingBaseBodyPose(body, RigidTransform(can.X_WC()))
    held_body = None
    if held is not None:
        if mode != "plan":
            raise ValueError("a held can is only modelled in 'plan' mode")
        # In the gripper's model instance: the can is part of the robot for collision checkers
        # that split robot from environment by model instance.
        body = plant.AddRigidBody("held_can", wsg, _can_inertia(spec))
        plant.RegisterVisualGeometry(body, RigidTransform(), can_shape, "held_can", color)
        m = spec.grasp.held_margin_m  # padded as in the python-fcl world
        padded = Cylinder(spec.can.radius_m + m, spec.can.height_m + 2 * m)
        plant.RegisterCollisionGeometry(body, RigidTransform(), padded, "held_can", friction)
        plant.WeldFrames(plant.GetFrameByName("body", wsg), body.body_frame(), RigidTransform(held.X_GC))
        held_body = body

    plant.Finalize()
    scene_graph.collision_filter_manager().Apply(
        _filters(plant, iiwa, wsg, plate_body, held_body, variant.filtered)
    )
    if moving_bodies is not None:
        # The driven bin slides over the table top it stands on (and past nothing else static:
        # its region is clear of the plate and the wall, `scenes.moving_bin_check.check_scenario`).
        decl = CollisionFilterDeclaration()
        decl.ExcludeBetween(plant.CollectRegisteredGeometries(list(moving_bodies)),
                            plant.CollectRegisteredGeometries([plant.world_body(), plate_body]))
        scene_graph.collision_filter_manager().Apply(decl)
    return iiwa, wsg


#: How far below the table top the room's floor is ("sim" mode only): a common table's height.
ROOM_FLOOR_BELOW_TABLE_M = 0.75

#: The model instance of a driven bin, its two prismatic joints (displacements from the spec's
#: bin centre, m) and its bodies.
MOVING_BIN_INSTANCE = "moving_bin"
MOVING_BIN_JOINTS = ("bin_x", "bin_y")


def _add_moving_bin(plant, spec, scenario, friction):
    """The bin (floor and walls as the static one's) and the person holding it as one body
    driven in x and y: world -> prismatic x -> a light carriage -> prismatic y -> bin, the person
    welded to the bin. Both joints are actuated (the execution gives them stiff PD gains and
    drives them along the bin's path). Returns the bin and person bodies."""
    from pydrake.multibody.tree import FixedOffsetFrame, PrismaticJoint

    from scenes.moving_bin import person_offset_m

    instance = plant.AddModelInstance(MOVING_BIN_INSTANCE)
    cx, cy = spec.bin.center_xy_m
    sx, sy, sz = spec.bin.outer_size_m
    carriage = plant.AddRigidBody("bin_carriage", instance,
                                  SpatialInertia(1.0, np.zeros(3), UnitInertia.SolidBox(0.1, 0.1, 0.1)))
    bin_body = plant.AddRigidBody("bin", instance, SpatialInertia(
        scenario.bin_mass_kg, np.zeros(3), UnitInertia.SolidBox(sx, sy, sz)))
    r, h = scenario.person_radius_m, scenario.person_height_m
    person = plant.AddRigidBody("person", instance, SpatialInertia(
        scenario.person_mass_kg, np.zeros(3), UnitInertia.SolidCylinder(r, h, [0, 0, 1])))
    origin = plant.AddFrame(FixedOffsetFrame("bin_origin", plant.world_frame(), RigidTransform([cx, cy, 0.0])))
    for name, parent, child, axis in (("bin_x", origin, carriage.body_frame(), [1.0, 0, 0]),
                                      ("bin_y", carriage.body_frame(), bin_body.body_frame(), [0, 1.0, 0])):
        joint = plant.AddJoint(PrismaticJoint(name, parent, child, axis))
        plant.AddJointActuator(f"{name}_actuator", joint, 1e6)
    off = person_offset_m(scenario, spec)
    plant.WeldFrames(bin_body.body_frame(), person.body_frame(), RigidTransform([off[0], off[1], h / 2]))
    for name, box in spec.bin.boxes().items():
        X = RigidTransform([box.center_m[0] - cx, box.center_m[1] - cy, box.center_m[2]])
        plant.RegisterVisualGeometry(bin_body, X, DrakeBox(*box.size_m), name, np.asarray(box.color_rgba))
        plant.RegisterCollisionGeometry(bin_body, X, DrakeBox(*box.size_m), name, friction)
    plant.RegisterVisualGeometry(person, RigidTransform(), Cylinder(r, h), "person", np.array([0.80, 0.60, 0.45, 1.0]))
    plant.RegisterCollisionGeometry(person, RigidTransform(), Cylinder(r, h), "person", friction)
    return bin_body, person


def _filters(plant, iiwa, wsg, plate_body, held_body, filtered) -> CollisionFilterDeclaration:
    """The filters shared with the python-fcl world (see `scenes.collision.world`).

    Drake itself already filters bodies joined by a joint and bodies welded into one rigid
    assembly (link 7, gripper, fingers, held can in "plan" mode).
    """
    decl = CollisionFilterDeclaration()

    def body_set(name):
        instance = iiwa if name.startswith("iiwa_") else wsg
        return plant.CollectRegisteredGeometries([plant.GetBodyByName(name, instance)])

    for a, b in filtered:  # the robot variant's filtered pairs
        decl.ExcludeBetween(body_set(a), body_set(b))
    if held_body is not None:
        # The held can rests on the plate at the grasp: that contact is allowed (as MoveIt allows
        # an attached object to touch its support surface).
        decl.ExcludeBetween(plant.CollectRegisteredGeometries([held_body]),
                            plant.CollectRegisteredGeometries([plate_body]))
    return decl


def _camera_core(spec) -> RenderCameraCore:
    cam = spec.cameras
    info = CameraInfo(cam.width_px, cam.height_px, math.radians(cam.fov_y_deg))
    return RenderCameraCore(RENDERER, info, ClippingRange(*cam.clipping_m), RigidTransform())


def build_drake_scene(
    scene: Scene,
    *,
    mode: str = "sim",
    cameras: bool = True,
    time_step_s: float = 0.0,
    gripper_opening_m: float | None = None,
    held: HeldCan | None = None,
    builder: DiagramBuilder | None = None,
    build: bool = True,
    plant_config=None,
    couple_fingers: bool = False,
    moving_bin=None,
):
    """Build the scene's diagram.

    Args:
        scene: what to build.
        mode: "sim" or "plan".
        cameras: add the spec's RGB-D cameras (rendered by RenderEngineVtk).
        time_step_s: the plant's discrete time step (0 for a continuous plant).
        gripper_opening_m, held: see `add_scene_to_plant` ("plan" mode).
        builder: an existing builder to add to (then `build=False` leaves it unbuilt).
        build: build the diagram.
        plant_config: a `MultibodyPlantConfig` (time step, contact model and approximation);
            it replaces `time_step_s` when given.
        couple_fingers, moving_bin: see `add_scene_to_plant`.

    Returns:
        A `DrakeScene` (its diagram is None when `build` is False).
    """
    builder = builder or DiagramBuilder()
    if plant_config is not None:
        plant, scene_graph = AddMultibodyPlant(plant_config, builder)
    else:
        plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step_s)
    iiwa, wsg = add_scene_to_plant(
        plant, scene_graph, scene, mode=mode, gripper_opening_m=gripper_opening_m, held=held,
        couple_fingers=couple_fingers, moving_bin=moving_bin,
    )
    sensors: dict[str, RgbdSensor] = {}
    poses: dict[str, RigidTransform] = {}
    if cameras:
        scene_graph.AddRenderer(RENDERER, MakeRenderEngineVtk(RenderEngineVtkParams()))
        core = _camera_core(scene.spec)
        depth_range = DepthRange(scene.spec.cameras.clipping_m[0] + 1e-3, scene.spec.cameras.clipping_m[1] - 1e-3)
        for name, pose in scene.spec.cameras.poses.items():
            X_WB = look_at(pose.p_m, pose.target_m)
            sensor = builder.AddNamedSystem(
                f"camera_{name}",
                RgbdSensor(
                    scene_graph.world_frame_id(),
                    X_WB,
                    ColorRenderCamera(core, False),
                    DepthRenderCamera(core, depth_range),
                ),
            )
            builder.Connect(scene_graph.get_query_output_port(), sensor.query_object_input_port())
            sensors[name], poses[name] = sensor, X_WB
    diagram = builder.Build() if build else None
    return DrakeScene(diagram, plant, scene_graph, iiwa, wsg, sensors, poses, mode)
