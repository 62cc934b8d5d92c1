"""The simulated plant and its controllers: execution settings, the Drake diagram, PD gains and grasp contact.

The command stream drives a discrete-time MultibodyPlant built from the same scene in "sim"
mode: the cans are free bodies with contact, the fingers slide on their prismatic joints.

Control (see `ExecutionConfig`):
- iiwa: joint position control by the plant's own PD controllers on the 7 actuators (Drake
  treats them implicitly inside the contact solver, so stiff gains are stable at a 2 ms step),
  plus an inverse-dynamics feedforward M(q_d) qdd_d + C(q_d, v_d) v_d - tau_g(q_d) computed from
  the plant's own model along the desired trajectory. The sum is clamped to each joint's effort
  limit (the URDF's, 40-320 N m), as a real drive would be.
- WSG: each finger under the same kind of PD position controller, clamped to the gripper's force
  limit: closing on a can the fingers push with `grip_force_n` each (a position/force controller).

Contact: Drake's discrete solver with the "lagged" convex approximation of SAP; by default
(`ExecutionConfig.contact_model`, "hydroelastic_with_fallback") hydroelastic contact between the
compliant finger pads and the rigid cans, point contact between the other primitive shapes (boxes,
cylinders, capsules) (docs/execution.md: with point contact only, a grasped can pivots between
the fingers); a room floor 0.75 m below the table catches a can that falls off it. Convex SAP
gives stable stacking and grasping at millisecond steps without the stiffness tuning TAMSI needs.
See `ExecutionConfig` for the time step.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import numpy as np

from scenes.scene import Scene
from suite.execution.config import CONTACT_APPROXIMATIONS, CONTACT_MODELS, ExecutionConfig

if TYPE_CHECKING:
    from suite.execution.commands import CommandStream

@dataclasses.dataclass(frozen=True)
class Simulation:
    """A built simulation and the handles execution and monitoring need.

    Attributes:
        ds: the scene's Drake objects (`scenes.drake_scene.build_drake_scene`: plant, scene graph,
            cameras).
        plant, iiwa, wsg: the MultibodyPlant and the arm's and gripper's model instances.
        diagram, simulator: the built diagram and its Simulator.
        root: the simulator's root context; pc: the plant's context in it.
        commander: the system that turns the command stream into desired states and the arm's
            feedforward; commander_context: its context in root.
        moving_bin: the driven bin's model instance (`scenes.drake_scene.MOVING_BIN_INSTANCE`),
            or None for the static bin.
    """

    ds: Any
    plant: Any
    iiwa: Any
    wsg: Any
    diagram: Any
    simulator: Any
    root: Any
    pc: Any
    commander: Any
    commander_context: Any
    moving_bin: Any = None

    def bin_center_xy(self) -> np.ndarray | None:
        """Where the driven bin's centre is now (2,), m; None for the static bin."""
        if self.moving_bin is None:
            return None
        origin = self.plant.GetFrameByName("bin_origin").GetFixedPoseInBodyFrame().translation()[:2]
        return np.asarray(origin, float) + self.plant.GetPositions(self.pc, self.moving_bin)

    def settle_fallen(self, bodies, height_m: float) -> list[str]:
        """Put every body of `bodies` (free cans, `height_m` tall) whose centre has fallen lower
        than halfway to the room's floor upright at rest on the floor below where it is: out of
        play. A can struck off the table would otherwise fall and roll on, its spin growing in the
        discrete solver's explicit gyroscopic terms until its pose is no longer finite. (Locking
        its joint instead crashed Drake 1.51's SAP solver.) Returns the names of the bodies moved."""
        from pydrake.math import RigidTransform
        from pydrake.multibody.math import SpatialVelocity

        from scenes.drake_scene import ROOM_FLOOR_BELOW_TABLE_M

        floor = -ROOM_FLOOR_BELOW_TABLE_M
        moved = []
        for body in bodies:
            p = self.plant.EvalBodyPoseInWorld(self.pc, body).translation()
            if p[2] >= floor / 2:
                continue
            V = self.plant.EvalBodySpatialVelocityInWorld(self.pc, body)
            rest = [p[0], p[1], floor + height_m / 2]
            if abs(p[2] - rest[2]) > 1e-3 or np.linalg.norm(V.get_coeffs()) > 1e-2:
                self.plant.SetFreeBodyPose(self.pc, body, RigidTransform(rest))
                self.plant.SetFreeBodySpatialVelocity(self.pc, body, SpatialVelocity.Zero())
                moved.append(body.name())
        return moved


#: A bin drive: the desired displacement of the bin centre from the spec's (2,), m, and its
#: velocity (2,), m/s, at a time (s).
BinDrive = "Callable[[float], tuple[np.ndarray, np.ndarray]]"


def build_simulation(
    scene: Scene,
    stream: CommandStream,
    *,
    q_home: np.ndarray,
    config: ExecutionConfig,
    meshcat=None,
    cameras: bool = False,
    moving_bin=None,
    bin_drive=None,
) -> Simulation:
    """The scene's plant with its controllers driven by `stream`, the arm at `q_home` and the
    gripper open (see the module docstring); recorded into `meshcat` if given.

    With `moving_bin` (a `scenes.moving_bin.MovingBinScenario`) the bin and the person holding it
    are one body on two actuated prismatic joints, under the plant's implicit PD control (kp =
    m w^2, kd = 2 m w on each axis, m the driven mass, w the scenario's drive bandwidth) toward
    `bin_drive(t)`: heavy and stiff, so the arm can hit it without moving it far."""
    from pydrake.multibody.plant import MultibodyPlantConfig
    from pydrake.multibody.tree import MultibodyForces
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import BasicVector, DiagramBuilder, LeafSystem

    from scenes.drake_scene import build_drake_scene

    spec = scene.spec
    builder = DiagramBuilder()
    _check_choice("contact model", config.contact_model, CONTACT_MODELS)
    _check_choice("contact approximation", config.contact_approximation, CONTACT_APPROXIMATIONS)
    plant_config = MultibodyPlantConfig(
        time_step=config.time_step_s, contact_model=config.contact_model,
        discrete_contact_approximation=config.contact_approximation)
    ds = build_drake_scene(scene, mode="sim", cameras=cameras, builder=builder, build=False,
                           plant_config=plant_config, couple_fingers=True, moving_bin=moving_bin)
    plant, iiwa, wsg = ds.plant, ds.iiwa, ds.wsg
    bin_instance = None
    if moving_bin is not None:
        from scenes.drake_scene import MOVING_BIN_INSTANCE

        bin_instance = plant.GetModelInstanceByName(MOVING_BIN_INSTANCE)
    if config.contact_model != "point":
        _make_compliant(plant, ds.scene_graph, wsg, scene, config)
    scratch = plant.CreateDefaultContext()
    plant.SetPositions(scratch, iiwa, q_home)
    _set_gains(plant, iiwa, wsg, scratch, config)
    if bin_instance is not None:
        _set_bin_gains(plant, bin_instance, scratch, moving_bin.drive_bandwidth_rad_s)
    forces = MultibodyForces(plant)
    finger_signs = _finger_signs(plant, wsg)  # looked up once: the commander runs every step
    nv = plant.num_velocities()

    class Commander(LeafSystem):
        """Desired arm and finger states, and the arm's inverse-dynamics feedforward."""

        def __init__(self):
            super().__init__()
            self.DeclareVectorOutputPort("arm_desired_state", 14, self._arm_state)
            self.DeclareVectorOutputPort("wsg_desired_state", 4, self._wsg_state)
            self.DeclareVectorOutputPort("arm_feedforward", 7, self._feedforward)
            if bin_instance is not None:
                self.DeclareVectorOutputPort("bin_desired_state", 4, self._bin_state)
            self._cached_t, self._cached = None, None

        def _bin_state(self, context, output: BasicVector):
            xy, v = bin_drive(context.get_time())
            output.SetFromVector(np.concatenate([xy, v]))

        def _arm(self, t: float):
            # Both outputs need the same sample in every step: evaluate the trajectory once.
            if self._cached_t != t:
                self._cached_t, self._cached = t, stream.at(t).arm(t)
            return self._cached

        def _arm_state(self, context, output: BasicVector):
            q, v, _ = self._arm(context.get_time())
            output.SetFromVector(np.concatenate([q, v]))

        def _wsg_state(self, context, output: BasicVector):
            t = context.get_time()
            output.SetFromVector(_finger_targets(finger_signs, *stream.at(t).width(t)))

        def _feedforward(self, context, output: BasicVector):
            q, v, a = self._arm(context.get_time())
            plant.SetPositions(scratch, iiwa, q)
            plant.SetVelocities(scratch, iiwa, v)
            vdot = np.zeros(nv)
            plant.SetVelocitiesInArray(iiwa, a, vdot)
            plant.CalcForceElementsContribution(scratch, forces)
            tau = plant.CalcInverseDynamics(scratch, vdot, forces)
            output.SetFromVector(plant.GetVelocitiesFromArray(iiwa, tau))

    commander = builder.AddNamedSystem("commander", Commander())
    builder.Connect(commander.GetOutputPort("arm_desired_state"), plant.get_desired_state_input_port(iiwa))
    builder.Connect(commander.GetOutputPort("wsg_desired_state"), plant.get_desired_state_input_port(wsg))
    builder.Connect(commander.GetOutputPort("arm_feedforward"), plant.get_actuation_input_port(iiwa))
    if bin_instance is not None:
        builder.Connect(commander.GetOutputPort("bin_desired_state"), plant.get_desired_state_input_port(bin_instance))
    if meshcat is not None:
        from pydrake.geometry import MeshcatVisualizer, MeshcatVisualizerParams, Role

        MeshcatVisualizer.AddToBuilder(builder, ds.scene_graph, meshcat, MeshcatVisualizerParams(
            role=Role.kIllustration, publish_period=1.0 / config.publish_hz))
    diagram = builder.Build()

    simulator = Simulator(diagram)
    root = simulator.get_mutable_context()
    pc = plant.GetMyMutableContextFromRoot(root)
    plant.SetPositions(pc, iiwa, q_home)
    plant.SetPositions(pc, wsg, _finger_targets(finger_signs, spec.grasp.open_width_m, 0.0)[:2])
    plant.get_actuation_input_port(wsg).FixValue(pc, np.zeros(2))
    if bin_instance is not None:
        plant.SetPositions(pc, bin_instance, np.asarray(bin_drive(0.0)[0], float))
        plant.get_actuation_input_port(bin_instance).FixValue(pc, np.zeros(2))
    commander_context = commander.GetMyContextFromRoot(root)
    return Simulation(ds=ds, plant=plant, iiwa=iiwa, wsg=wsg, diagram=diagram, simulator=simulator,
                      root=root, pc=pc, commander=commander, commander_context=commander_context,
                      moving_bin=bin_instance)


def _check_choice(what: str, value: str, allowed: tuple[str, ...]) -> None:
    if value not in allowed:
        from scenes.errors import SuiteError

        raise SuiteError(f"unknown {what} {value!r}; allowed: {', '.join(allowed)}")


def _set_gains(plant, iiwa, wsg, context, config: ExecutionConfig) -> None:
    """PD gains for every actuator: arm from the joint inertias at `context`, fingers fixed."""
    from pydrake.multibody.tree import PdControllerGains

    M = plant.CalcMassMatrix(context)
    w, zeta = config.arm_bandwidth_rad_s, config.damping_ratio
    for index in plant.GetJointActuatorIndices(iiwa):
        actuator = plant.get_joint_actuator(index)
        m = float(M[actuator.joint().velocity_start(), actuator.joint().velocity_start()])
        actuator.set_controller_gains(PdControllerGains(p=m * w * w, d=2 * zeta * m * w))
    for index in plant.GetJointActuatorIndices(wsg):
        actuator = plant.get_joint_actuator(index)
        actuator.set_controller_gains(PdControllerGains(p=config.finger_kp_n_m, d=config.finger_kd_n_s_m))
        actuator.set_effort_limit(config.grip_force_n)


def _set_bin_gains(plant, instance, context, bandwidth_rad_s: float) -> None:
    """Stiff PD gains on the driven bin's two axes from the mass each moves."""
    from pydrake.multibody.tree import PdControllerGains

    M = plant.CalcMassMatrix(context)
    w = bandwidth_rad_s
    for index in plant.GetJointActuatorIndices(instance):
        actuator = plant.get_joint_actuator(index)
        m = float(M[actuator.joint().velocity_start(), actuator.joint().velocity_start()])
        actuator.set_controller_gains(PdControllerGains(p=m * w * w, d=2 * m * w))


def _make_compliant(plant, scene_graph, wsg, scene: Scene, config: ExecutionConfig) -> None:
    """Hydroelastic grasp contact: compliant finger pads against rigid-hydroelastic cans.

    Their contact is a pressure patch, which resists the can turning about the line between the
    fingers (two point contacts would let it swing like a pendulum). Every other pair (can on
    plate, can on can, robot on scene) falls back to point contact, which keeps the step cheap.
    """
    from pydrake.geometry import (
        AddCompliantHydroelasticProperties,
        AddRigidHydroelasticProperties,
        ProximityProperties,
        RoleAssign,
    )

    inspector = scene_graph.model_inspector()

    def assign(body, add):
        for gid in plant.GetCollisionGeometriesForBody(body):
            props = ProximityProperties(inspector.GetProximityProperties(gid))
            add(props)
            scene_graph.AssignRole(plant.get_source_id(), gid, props, RoleAssign.kReplace)

    for name in ("left_finger", "right_finger"):
        assign(plant.GetBodyByName(name, wsg), lambda p: AddCompliantHydroelasticProperties(
            config.hydroelastic_resolution_m, config.hydroelastic_modulus_pa, p))
    for can in scene.cans:
        assign(plant.GetBodyByName(f"can_{can.id}"),
               lambda p: AddRigidHydroelasticProperties(config.hydroelastic_resolution_m, p))


def _finger_signs(plant, wsg) -> np.ndarray:
    """Per WSG actuator, in actuator order: -1 for the left finger (inner face at -w/2), +1 right."""
    return np.array([-1.0 if plant.get_joint_actuator(i).joint().name().startswith("left") else 1.0
                     for i in plant.GetJointActuatorIndices(wsg)])


def _finger_targets(signs: np.ndarray, width_m: float, rate_m_s: float) -> np.ndarray:
    """Desired [q, v] of the WSG's actuated joints for a finger opening and its rate."""
    return np.concatenate([signs * width_m / 2, signs * rate_m_s / 2])
