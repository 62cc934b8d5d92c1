"""Execute planned pick-and-place cycles in a Drake physics simulation: are the cans recycled?

Each can's five timed trajectories (approach, descend, lift, transit, return) are chained into one
command stream with the gripper actions between them: approach, descend, close, lift, transit,
open, return. The stream drives a discrete-time MultibodyPlant built from the same scene in "sim"
mode: the cans are free bodies with contact, the fingers slide on their prismatic joints.

Control (see `ExecutionConfig`):
- iiwa: joint position control by the plant's own PD controllers on the 7 actuators (Drake
  treats them implicitly inside the contact solver, so stiff gains are stable at a 2 ms step),
  plus an inverse-dynamics feedforward M(q_d) qdd_d + C(q_d, v_d) v_d - tau_g(q_d) computed from
  the plant's own model along the desired trajectory. The sum is clamped to each joint's effort
  limit (the URDF's, 40-320 N m), as a real drive would be.
- WSG: each finger under the same kind of PD position controller, clamped to the gripper's force
  limit: closing on a can the fingers push with `grip_force_n` each (a position/force controller).

Contact: Drake's discrete solver with the "lagged" convex approximation of SAP and point contact
between the primitive shapes (boxes, cylinders, capsules). Convex SAP gives stable stacking and
grasping at millisecond steps without the stiffness tuning TAMSI needs; point contact is enough
for a parallel-jaw grasp across a rigid can's diameter and keeps the simulation faster than real
time. See `ExecutionConfig` for the time step.

What is measured (`ExecutionOutcome`): where every can ends (in the bin, back on the plate,
elsewhere), contacts of the robot with the static scene or with cans it is not picking (and of the
carried can with the scene), the peak joint tracking error, and wall and simulated time.
"""

from __future__ import annotations

import bisect
import dataclasses
import logging
import time
from typing import Any, Callable, Sequence

import numpy as np

from scenes.scene import Scene
from suite.scoring.timing import TimedTrajectory

log = logging.getLogger(__name__)

#: The motions of one can's cycle and the gripper actions between them, in execution order.
PHASES = ("approach", "descend", "close", "lift", "transit", "open", "return")


@dataclasses.dataclass(frozen=True)
class ExecutionConfig:
    """How the plans are executed.

    Attributes:
        time_step_s: the plant's discrete step. 2 ms resolves the fingers closing at 0.1 m/s
            (0.2 mm per step) and the cans' free fall into the bin, and keeps SAP well conditioned.
        contact_model: Drake contact model ("point" or "hydroelastic_with_fallback").
        contact_approximation: Drake discrete contact approximation ("lagged", "sap", "similar").
        arm_bandwidth_rad_s: natural frequency of each arm joint's PD loop (kp = M_ii w^2,
            kd = 2 zeta M_ii w, with M_ii the joint's inertia at the start configuration).
        damping_ratio: zeta above.
        grip_force_n: force limit of each finger while closing or holding (the WSG 50 grips
            with up to 80 N).
        finger_kp_n_m: finger position gain (N/m); the force saturates at grip_force_n.
        finger_kd_n_s_m: finger velocity gain (N s/m).
        close_s: time to close the gripper on the can before lifting.
        open_s: time to open the gripper over the bin before returning.
        settle_s: simulated time after the last motion before the cans are counted.
        publish_hz: frame rate of a Meshcat recording.
    """

    time_step_s: float = 0.002
    contact_model: str = "hydroelastic_with_fallback"
    contact_approximation: str = "lagged"
    hydroelastic_modulus_pa: float = 5e6
    hydroelastic_resolution_m: float = 0.01
    arm_bandwidth_rad_s: float = 30.0
    damping_ratio: float = 1.0
    grip_force_n: float = 40.0
    finger_kp_n_m: float = 2000.0
    finger_kd_n_s_m: float = 40.0
    close_s: float = 0.6
    open_s: float = 0.5
    settle_s: float = 1.0
    publish_hz: float = 30.0


@dataclasses.dataclass(frozen=True)
class Segment:
    """One piece of the command stream.

    Attributes:
        phase: one of PHASES (or "hold" at the end).
        can_id: the can this piece belongs to.
        t0_s: start time in the stream.
        duration_s: its length.
        trajectory: the arm's timed trajectory (motions), or None (the arm holds `q_hold`).
        q_hold: the arm's configuration when holding.
        width_from_m, width_to_m: finger opening commanded at the start and end (linear ramp).
        carrying: the can is meant to be in the gripper.
    """

    phase: str
    can_id: int
    t0_s: float
    duration_s: float
    trajectory: TimedTrajectory | None
    q_hold: np.ndarray
    width_from_m: float
    width_to_m: float
    carrying: bool

    def arm(self, t_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self.trajectory is None:
            z = np.zeros(7)
            return self.q_hold, z, z
        return self.trajectory.sample(min(max(t_s - self.t0_s, 0.0), self.duration_s))

    def width(self, t_s: float) -> tuple[float, float]:
        """Commanded finger opening (m) and its rate (m/s)."""
        if self.duration_s <= 0 or self.width_from_m == self.width_to_m:
            return self.width_to_m, 0.0
        a = min(max((t_s - self.t0_s) / self.duration_s, 0.0), 1.0)
        rate = (self.width_to_m - self.width_from_m) / self.duration_s if 0 < a < 1 else 0.0
        return self.width_from_m + a * (self.width_to_m - self.width_from_m), rate


@dataclasses.dataclass(frozen=True)
class CanCycle:
    """One can's five timed motions, in the order of `planners.base.PROBLEM_KINDS`."""

    can_id: int
    trajectories: tuple[TimedTrajectory, ...]


class CommandStream:
    """The chained segments of a whole execution and their lookup by time; cycles are appended
    as they become known (all at once when planned ahead, one by one in closed loop)."""

    def __init__(self, *, q_home: np.ndarray, open_width_m: float, config: ExecutionConfig):
        self.segments: list[Segment] = []
        self.duration_s = 0.0
        self._q = np.asarray(q_home, float)
        self._open = open_width_m
        self._config = config
        self._starts: list[float] = []

    def _add(self, phase, can_id, duration, traj, w0, w1, carrying):
        self.segments.append(Segment(phase, can_id, self.duration_s, duration, traj, self._q.copy(), w0, w1, carrying))
        self._starts.append(self.duration_s)
        if traj is not None:
            self._q = traj.q[-1].copy()
        self.duration_s += duration

    def append_cycle(self, cycle: CanCycle) -> None:
        approach, descend, lift, transit, ret = cycle.trajectories
        w, closed = self._open, 0.0  # closed: the force limit, not the position, holds the can
        self._add("approach", cycle.can_id, approach.duration_s, approach, w, w, False)
        self._add("descend", cycle.can_id, descend.duration_s, descend, w, w, False)
        self._add("close", cycle.can_id, self._config.close_s, None, w, closed, False)
        self._add("lift", cycle.can_id, lift.duration_s, lift, closed, closed, True)
        self._add("transit", cycle.can_id, transit.duration_s, transit, closed, closed, True)
        self._add("open", cycle.can_id, self._config.open_s, None, closed, w, False)
        self._add("return", cycle.can_id, ret.duration_s, ret, w, w, False)

    @property
    def q_end(self) -> np.ndarray:
        """The arm's commanded configuration at the end of the stream so far."""
        return self._q.copy()

    def finish(self) -> None:
        """Hold still for the settling time at the end."""
        self._add("hold", -1, self._config.settle_s, None, self._open, self._open, False)

    def at(self, t_s: float) -> Segment:
        i = bisect.bisect_right(self._starts, t_s) - 1
        return self.segments[min(max(i, 0), len(self.segments) - 1)]


@dataclasses.dataclass(frozen=True)
class WorldState:
    """What the simulation looks like between two cycles (what a closed-loop planner may use).

    Attributes:
        t_s: simulated time.
        q_arm: the arm's measured joint positions (7,).
        q_command: where the command stream ends (7,): the next cycle must start here.
        X_WCans: every can's pose (4, 4) by id.
        images: the cameras' frames (name -> scenes.render.CameraImage) rendered from the
            simulation right after the last release over the bin, where the arm is out of the
            plate cameras' view; None before the first release or without cameras.
    """

    t_s: float
    q_arm: np.ndarray
    q_command: np.ndarray
    X_WCans: dict[int, np.ndarray]
    images: dict | None


#: Given the world between cycles, the next can's cycle, or None to stop (with a reason).
CycleProvider = Callable[[WorldState], "tuple[CanCycle | None, str]"]


def planned_ahead(cycles: Sequence[CanCycle], stopped: str = "") -> CycleProvider:
    """The open-loop provider: cycles planned before execution, in order."""
    queue = list(cycles)

    def provide(_world: WorldState):
        return (queue.pop(0), "") if queue else (None, stopped)

    return provide


@dataclasses.dataclass
class ContactEvent:
    """A contact the plan did not intend, first seen at `t_s` (one per contact episode)."""

    t_s: float
    phase: str
    can_id: int
    body_a: str
    body_b: str
    p_W_m: tuple[float, float, float]

    def to_json(self) -> dict:
        return {"t_s": round(self.t_s, 4), "phase": self.phase, "can_id": self.can_id,
                "bodies": [self.body_a, self.body_b], "p_W_m": [round(v, 4) for v in self.p_W_m]}


@dataclasses.dataclass(frozen=True)
class CanResult:
    """Where one can ended."""

    can_id: int
    attempted: bool
    where: str  # "bin", "plate" or "elsewhere"
    p_WC_m: tuple[float, float, float]
    in_bin_at_s: float | None

    def to_json(self) -> dict:
        return {"can_id": self.can_id, "attempted": self.attempted, "where": self.where,
                "p_WC_m": [round(v, 4) for v in self.p_WC_m],
                "in_bin_at_s": None if self.in_bin_at_s is None else round(self.in_bin_at_s, 3)}


@dataclasses.dataclass(frozen=True)
class ExecutionOutcome:
    """What happened when one planner's plans for one scene were executed.

    Attributes:
        cans_total: cans on the plate at the start.
        cans_attempted: cans whose whole cycle was planned and executed.
        cans_in_bin, cans_on_plate, cans_elsewhere: where the cans ended.
        collisions: unintended contact episodes (robot vs static scene, robot vs a can it was not
            picking, the carried can vs the scene or other cans).
        contact_events: the first few of them.
        peak_tracking_error_rad: largest |q - q_desired| of any arm joint.
        peak_slip_m: largest displacement of a carried can in the gripper frame since its lift
            began.
        sim_time_s: simulated time of the whole stream (settling included).
        clear_time_s: simulated time at which the last can entered the bin (None unless all did).
        clear_wall_time_s: wall time the simulation took to get there (None unless all did).
        wall_time_s: wall time of the simulation (the provider's planning between cycles is
            left out and recorded as between_cycles_wall_s).
        real_time_factor: sim_time_s / wall_time_s.
        stopped: why execution stopped before the last can ("" if it did not).
    """

    planner: str
    scene_seed: int
    variant: str
    cans_total: int
    cans_attempted: int
    cans_in_bin: int
    cans_on_plate: int
    cans_elsewhere: int
    collisions: int
    contact_events: tuple[ContactEvent, ...]
    peak_tracking_error_rad: float
    peak_slip_m: float
    sim_time_s: float
    clear_time_s: float | None
    clear_wall_time_s: float | None
    wall_time_s: float
    real_time_factor: float
    cans: tuple[CanResult, ...]
    stopped: str = ""
    extra: dict[str, Any] = dataclasses.field(default_factory=dict)

    def to_json(self) -> dict:
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
               if f.name not in ("contact_events", "cans", "extra")}
        out["contact_events"] = [e.to_json() for e in self.contact_events]
        out["cans"] = [c.to_json() for c in self.cans]
        out.update(self.extra)
        for k in ("peak_tracking_error_rad", "peak_slip_m", "sim_time_s", "wall_time_s", "real_time_factor"):
            out[k] = round(float(out[k]), 6)
        return out


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


class _Classifier:
    """Names the plant's bodies by role: robot, finger, can_<id>, static."""

    def __init__(self, plant, iiwa, wsg):
        from pydrake.multibody.tree import BodyIndex

        self.role: dict[int, str] = {}
        self.name: dict[int, str] = {}
        for i in range(plant.num_bodies()):
            body = plant.get_body(BodyIndex(i))
            self.name[i] = body.name()
            if body.model_instance() in (iiwa, wsg):
                self.role[i] = "finger" if body.name().endswith("_finger") else "robot"
            elif body.name().startswith("can_"):
                self.role[i] = body.name()
            else:
                self.role[i] = "static"

    def unintended(self, a: int, b: int, segment: Segment) -> bool:
        """Is contact between bodies a and b something the plan did not intend?"""
        ra, rb = self.role[a], self.role[b]
        target = f"can_{segment.can_id}"
        robot = ("robot", "finger")
        if ra in robot and rb in robot:
            return False  # self contact inside the gripper (fingers against each other when empty)
        if rb in robot:
            ra, rb = rb, ra
        if ra in robot:
            if rb == "static":
                return True
            if rb == target and ra == "finger" and segment.phase in ("descend", "close", "lift", "transit", "open"):
                return False
            return rb != target or ra != "finger"
        # Neither is the robot: only the carried can's contacts matter.
        if segment.carrying and target in (ra, rb):
            other = rb if ra == target else ra
            return not (other == "static" and segment.phase == "lift" and self.name[b if ra == target else a] == "plate")
        return False


def bin_region(spec) -> tuple[np.ndarray, np.ndarray]:
    """The inside of the bin as an axis-aligned box (lower, upper corners), metres."""
    b = spec.bin
    half = np.array(b.outer_size_m[:2]) / 2 - b.wall_thickness_m
    lo = np.array([b.center_xy_m[0] - half[0], b.center_xy_m[1] - half[1], 0.0])
    hi = np.array([b.center_xy_m[0] + half[0], b.center_xy_m[1] + half[1], b.outer_size_m[2]])
    return lo, hi


def where(spec, p_WC_m: np.ndarray) -> str:
    """"bin" if the can's centre is inside the bin, "plate" if above the plate, else "elsewhere"."""
    lo, hi = bin_region(spec)
    if np.all(p_WC_m >= lo) and np.all(p_WC_m <= hi):
        return "bin"
    plate = spec.plate
    c, s = np.array(plate.center_m[:2]), np.array(plate.size_m[:2]) / 2
    if np.all(np.abs(p_WC_m[:2] - c) <= s) and p_WC_m[2] >= spec.plate_top_z_m - 1e-3:
        return "plate"
    return "elsewhere"


def execute_cycles(
    scene: Scene,
    provider: CycleProvider,
    *,
    q_home: np.ndarray,
    planner: str,
    config: ExecutionConfig = ExecutionConfig(),
    meshcat=None,
    cameras: bool = False,
    on_progress: Callable[[float, float], None] | None = None,
) -> ExecutionOutcome:
    """Simulate the cans' cycles one after the other and measure the outcome.

    Args:
        scene: the scene as the cans really stand at the start.
        provider: gives each next can's timed motions (`planned_ahead` for plans made before
            execution; a closed-loop provider perceives and plans between cycles).
        q_home: the arm's configuration at the start (the first approach's start).
        planner: its name (recorded).
        config: control, contact and timing settings.
        meshcat: a pydrake Meshcat to record the execution into, or None.
        cameras: add the spec's cameras and render them after each release (closed loop).
        on_progress: called with (simulated time, planned total) every simulated second.
    """
    from pydrake.multibody.tree import MultibodyForces
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import BasicVector, DiagramBuilder, LeafSystem

    from scenes.drake_scene import build_drake_scene

    spec = scene.spec
    stream = CommandStream(q_home=q_home, open_width_m=spec.grasp.open_width_m, config=config)
    from pydrake.multibody.plant import MultibodyPlantConfig

    builder = DiagramBuilder()
    _check_choice("contact model", config.contact_model, CONTACT_MODELS)
    _check_choice("contact approximation", config.contact_approximation, CONTACT_APPROXIMATIONS)
    plant_config = MultibodyPlantConfig(
        time_step=config.time_step_s, contact_model=config.contact_model,
        discrete_contact_approximation=config.contact_approximation)
    ds = build_drake_scene(scene, mode="sim", cameras=cameras, builder=builder, build=False,
                           plant_config=plant_config, couple_fingers=True)
    plant, iiwa, wsg = ds.plant, ds.iiwa, ds.wsg
    if config.contact_model != "point":
        _make_compliant(plant, ds.scene_graph, wsg, scene, config)
    scratch = plant.CreateDefaultContext()
    plant.SetPositions(scratch, iiwa, q_home)
    _set_gains(plant, iiwa, wsg, scratch, config)
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
            self._cached_t, self._cached = None, None

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
    commander_context = commander.GetMyContextFromRoot(root)
    desired_port = commander.GetOutputPort("arm_desired_state")
    contact_port = plant.get_contact_results_output_port()

    classifier = _Classifier(plant, iiwa, wsg)
    inspector = ds.scene_graph.model_inspector()
    body_of = {gid: int(plant.GetBodyFromFrameId(inspector.GetFrameId(gid)).index())
               for gid in inspector.GetAllGeometryIds()}
    can_bodies = {c.id: plant.GetBodyByName(f"can_{c.id}") for c in scene.cans}
    in_bin_at: dict[int, float] = {}
    in_bin_wall: dict[int, float] = {}
    events: list[ContactEvent] = []
    touching: set[tuple[int, int]] = set()
    peak_err = 0.0
    n_episodes = 0
    gripper = plant.GetBodyByName("body", wsg)
    grip_ref: dict[int, np.ndarray] = {}  # can id -> its position in G when the lift began
    peak_slip = 0.0

    def monitor(context, full: bool):
        """Every step: tracking error and contacts (an impact can last a single step). With
        `full`: also the carried can's slip and which cans reached the bin."""
        nonlocal peak_err, n_episodes, touching, peak_slip
        t = context.get_time()
        segment = stream.at(t)
        if full and segment.carrying:
            X_WG = plant.EvalBodyPoseInWorld(pc, gripper)
            p_GC = X_WG.inverse() @ plant.EvalBodyPoseInWorld(pc, can_bodies[segment.can_id]).translation()
            ref = grip_ref.setdefault(segment.can_id, p_GC)
            peak_slip = max(peak_slip, float(np.linalg.norm(p_GC - ref)))
        q = plant.GetPositions(pc, iiwa)
        q_d = desired_port.Eval(commander_context)[:7]
        peak_err = max(peak_err, float(np.max(np.abs(q - q_d))))
        results = contact_port.Eval(pc)
        now = {}
        for i in range(results.num_point_pair_contacts()):
            info = results.point_pair_contact_info(i)
            a, b = int(info.bodyA_index()), int(info.bodyB_index())
            if classifier.unintended(a, b, segment):
                now[(min(a, b), max(a, b))] = info.contact_point()
        for i in range(results.num_hydroelastic_contacts()):
            surface = results.hydroelastic_contact_info(i).contact_surface()
            a, b = body_of[surface.id_M()], body_of[surface.id_N()]
            if classifier.unintended(a, b, segment):
                now[(min(a, b), max(a, b))] = surface.centroid()
        for pair in now.keys() - touching:
            n_episodes += 1
            if len(events) < 20:
                events.append(ContactEvent(t, segment.phase, segment.can_id, classifier.name[pair[0]],
                                           classifier.name[pair[1]], tuple(float(v) for v in now[pair])))
        touching = set(now)
        if not full:
            return
        for can_id, body in can_bodies.items():
            if can_id not in in_bin_at:
                p = plant.EvalBodyPoseInWorld(pc, body).translation()
                if where(spec, p) == "bin":
                    in_bin_at[can_id] = t
                    in_bin_wall[can_id] = time.perf_counter() - wall0 - provider_wall

    snapshot: dict = {}

    def world_state() -> WorldState:
        return WorldState(
            t_s=root.get_time(), q_arm=plant.GetPositions(pc, iiwa).copy(), q_command=stream.q_end,
            X_WCans={i: plant.EvalBodyPoseInWorld(pc, b).GetAsMatrix4() for i, b in can_bodies.items()},
            images=snapshot.get("images"),
        )

    wall0 = time.perf_counter()
    provider_wall = 0.0
    simulator.Initialize()
    if meshcat is not None:
        meshcat.StartRecording(frames_per_second=config.publish_hz)
    every = max(1, round(0.01 / config.time_step_s))  # the full check every 10 ms
    steps = 0
    t = 0.0
    next_progress = 1.0
    attempted: list[int] = []
    stopped = ""
    finished = False
    while True:
        if not finished and t >= stream.duration_s - 1e-9:
            p0 = time.perf_counter()
            cycle, stopped = provider(world_state())
            provider_wall += time.perf_counter() - p0
            if cycle is None:
                stream.finish()
                finished = True
            else:
                stream.append_cycle(cycle)
                attempted.append(cycle.can_id)
        if finished and t >= stream.duration_s - 1e-9:
            break
        steps += 1
        t = min(steps * config.time_step_s, stream.duration_s)
        simulator.AdvanceTo(t)
        monitor(root, full=steps % every == 0 or t >= stream.duration_s)
        segment = stream.at(t)
        if cameras and segment.phase == "return" and snapshot.get("cycle") != len(attempted):
            from scenes.render import render_context

            p0 = time.perf_counter()
            snapshot.update(cycle=len(attempted), images=render_context(ds, root))
            provider_wall += time.perf_counter() - p0
        if on_progress is not None and t >= next_progress:
            on_progress(t, stream.duration_s)
            next_progress += 1.0
    wall = time.perf_counter() - wall0 - provider_wall
    if meshcat is not None:
        meshcat.StopRecording()
        meshcat.PublishRecording()

    cans = []
    for can in scene.cans:
        p = plant.EvalBodyPoseInWorld(pc, can_bodies[can.id]).translation()
        place = where(spec, p)
        cans.append(CanResult(can.id, can.id in attempted, place, tuple(float(v) for v in p),
                              in_bin_at.get(can.id) if place == "bin" else None))
    counts = {w: sum(c.where == w for c in cans) for w in ("bin", "plate", "elsewhere")}
    cleared = counts["bin"] == len(cans) and bool(cans)
    clear = max(c.in_bin_at_s for c in cans) if cleared else None
    clear_wall = max(in_bin_wall[c.can_id] for c in cans) if cleared else None
    return ExecutionOutcome(
        planner=planner, scene_seed=scene.seed, variant=scene.variant, cans_total=len(scene.cans),
        cans_attempted=len(attempted), cans_in_bin=counts["bin"], cans_on_plate=counts["plate"],
        cans_elsewhere=counts["elsewhere"], collisions=n_episodes, contact_events=tuple(events),
        peak_tracking_error_rad=peak_err, peak_slip_m=peak_slip, sim_time_s=stream.duration_s, clear_time_s=clear,
        clear_wall_time_s=clear_wall,
        wall_time_s=wall, real_time_factor=stream.duration_s / wall if wall > 0 else float("inf"),
        cans=tuple(cans), stopped=stopped, extra={"between_cycles_wall_s": round(provider_wall, 3)},
    )


CONTACT_MODELS = ("point", "hydroelastic_with_fallback")
CONTACT_APPROXIMATIONS = ("lagged", "sap", "similar")


def _check_choice(what: str, value: str, allowed: tuple[str, ...]) -> None:
    if value not in allowed:
        from scenes.errors import SuiteError

        raise SuiteError(f"unknown {what} {value!r}; allowed: {', '.join(allowed)}")


def timed_cycle(can_id: int, paths: Sequence[np.ndarray]) -> CanCycle | None:
    """Time one can's five validated paths with TOPP-RA (as the trials did); None if one
    cannot be timed."""
    from scenes.robot_model import load_robot
    from suite.scoring.timing import time_parameterize

    robot = load_robot()
    timed = []
    for path in paths:
        tt = time_parameterize(np.asarray(path, float), robot=robot)
        if not tt.ok:
            return None
        timed.append(tt)
    return CanCycle(can_id, tuple(timed))
