"""What an execution measures while it runs: unintended contacts, where the cans end, tracking error and slip.

Contacts of the robot with the static scene or with cans it is not picking, and of the carried
can with the scene, are counted as episodes (a contact pair that starts touching); the first few
are kept as `ContactEvent`s. Every can's fate is "bin", "plate" or "elsewhere" (`where`), with the
simulated and wall time at which it first entered the bin.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from scenes.scene import Scene

if TYPE_CHECKING:
    from suite.execution.commands import CommandStream, Segment
    from suite.execution.plant import Simulation


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


def bin_region(spec, center_xy_m=None) -> tuple[np.ndarray, np.ndarray]:
    """The inside of the bin as an axis-aligned box (lower, upper corners), metres; the bin at the
    spec's place, or with its centre at `center_xy_m` (a moving bin's current place)."""
    b = spec.bin
    c = b.center_xy_m if center_xy_m is None else center_xy_m
    half = np.array(b.outer_size_m[:2]) / 2 - b.wall_thickness_m
    lo = np.array([c[0] - half[0], c[1] - half[1], 0.0])
    hi = np.array([c[0] + half[0], c[1] + half[1], b.outer_size_m[2]])
    return lo, hi


def where(spec, p_WC_m: np.ndarray, bin_xy_m=None) -> str:
    """"bin" if the can's centre is inside the bin (at the spec's place, or centred at
    `bin_xy_m`), "plate" if above the plate, else "elsewhere"."""
    lo, hi = bin_region(spec, bin_xy_m)
    if np.all(p_WC_m >= lo) and np.all(p_WC_m <= hi):
        return "bin"
    plate = spec.plate
    c, s = np.array(plate.center_m[:2]), np.array(plate.size_m[:2]) / 2
    if np.all(np.abs(p_WC_m[:2] - c) <= s) and p_WC_m[2] >= spec.plate_top_z_m - 1e-3:
        return "plate"
    return "elsewhere"


#: Phases in which the fingers may touch the can of the cycle without carrying it: closing on it,
#: reaching it, opening, and retreating from a can put back down (the moving bin's give-up).
INTENDED_GRIP_PHASES = ("descend", "close", "open", "retreat")

#: The driven bodies of a moving bin (`scenes.drake_scene._add_moving_bin`) by role.
MOVING_ROLES = {"bin": "bin", "person": "person"}


class _Classifier:
    """Names the plant's bodies by role: robot, finger, can_<id>, static, and a moving bin's
    "bin" and "person"."""

    def __init__(self, plant, iiwa, wsg, moving_bin=None):
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
            elif moving_bin is not None and body.model_instance() == moving_bin and body.name() in MOVING_ROLES:
                self.role[i] = MOVING_ROLES[body.name()]
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
            if rb in ("static", "bin", "person"):
                return True
            # the fingers on the can they pick: while closing on it, carrying it (lift, transit; a
            # moving bin's blends and waits), opening, and leaving a can put back down
            if rb == target and ra == "finger" and (segment.carrying or segment.phase in INTENDED_GRIP_PHASES):
                return False
            return rb != target or ra != "finger"
        # Neither is the robot: only the carried can's contacts matter.
        if segment.carrying and target in (ra, rb):
            other = rb if ra == target else ra
            if other in ("bin", "person"):
                return True
            return not (other == "static" and segment.phase in ("lift", "put_down")
                        and self.name[b if ra == target else a] == "plate")
        return False


class Monitor:
    """The measurements of one execution, updated by `check` after simulation steps.

    Attributes:
        can_bodies: every can's plant body by id.
        in_bin_at, in_bin_wall: simulated and wall time (s) at which each can first entered the bin.
        events: the first 20 unintended contact episodes; n_episodes: all of them.
        moving_contacts: of those, the episodes with a moving bin's "bin" or "person" (by role;
            the robot's or the carried can's).
        peak_err: largest |q - q_desired| of any arm joint (rad).
        peak_slip: largest displacement of a carried can in the gripper frame since its lift
            began (m).
    """

    def __init__(self, sim: Simulation, scene: Scene, stream: CommandStream, wall_s: Callable[[], float]):
        """`wall_s` gives the wall time the simulation has taken so far (recorded when a can
        enters the bin)."""
        plant = sim.plant
        self._sim = sim
        self._spec = scene.spec
        self._stream = stream
        self._wall_s = wall_s
        self._desired_port = sim.commander.GetOutputPort("arm_desired_state")
        self._contact_port = plant.get_contact_results_output_port()
        self._classifier = _Classifier(plant, sim.iiwa, sim.wsg, getattr(sim, "moving_bin", None))
        self.moving_contacts = {"bin": 0, "person": 0}
        inspector = sim.ds.scene_graph.model_inspector()
        self._body_of = {gid: int(plant.GetBodyFromFrameId(inspector.GetFrameId(gid)).index())
                         for gid in inspector.GetAllGeometryIds()}
        self._can_ids = [c.id for c in scene.cans]
        self.can_bodies = {c.id: plant.GetBodyByName(f"can_{c.id}") for c in scene.cans}
        self.in_bin_at: dict[int, float] = {}
        self.in_bin_wall: dict[int, float] = {}
        self.events: list[ContactEvent] = []
        self._touching: set[tuple[int, int]] = set()
        self.peak_err = 0.0
        self.n_episodes = 0
        self._gripper = plant.GetBodyByName("body", sim.wsg)
        self._grip_ref: dict[int, np.ndarray] = {}  # can id -> its position in G when the lift began
        self.peak_slip = 0.0

    def check(self, context, full: bool) -> None:
        """Every step: tracking error and contacts (an impact can last a single step). With
        `full`: also the carried can's slip and which cans reached the bin."""
        plant, pc, iiwa = self._sim.plant, self._sim.pc, self._sim.iiwa
        classifier = self._classifier
        t = context.get_time()
        segment = self._stream.at(t)
        if full and segment.carrying:
            X_WG = plant.EvalBodyPoseInWorld(pc, self._gripper)
            p_GC = X_WG.inverse() @ plant.EvalBodyPoseInWorld(pc, self.can_bodies[segment.can_id]).translation()
            ref = self._grip_ref.setdefault(segment.can_id, p_GC)
            self.peak_slip = max(self.peak_slip, float(np.linalg.norm(p_GC - ref)))
        q = plant.GetPositions(pc, iiwa)
        q_d = self._desired_port.Eval(self._sim.commander_context)[:7]
        self.peak_err = max(self.peak_err, float(np.max(np.abs(q - q_d))))
        results = self._contact_port.Eval(pc)
        now = {}
        for i in range(results.num_point_pair_contacts()):
            info = results.point_pair_contact_info(i)
            a, b = int(info.bodyA_index()), int(info.bodyB_index())
            if classifier.unintended(a, b, segment):
                now[(min(a, b), max(a, b))] = info.contact_point()
        for i in range(results.num_hydroelastic_contacts()):
            surface = results.hydroelastic_contact_info(i).contact_surface()
            a, b = self._body_of[surface.id_M()], self._body_of[surface.id_N()]
            if classifier.unintended(a, b, segment):
                now[(min(a, b), max(a, b))] = surface.centroid()
        for pair in now.keys() - self._touching:
            self.n_episodes += 1
            for role in (classifier.role[pair[0]], classifier.role[pair[1]]):
                if role in self.moving_contacts:
                    self.moving_contacts[role] += 1
            if len(self.events) < 20:
                self.events.append(ContactEvent(t, segment.phase, segment.can_id, classifier.name[pair[0]],
                                                classifier.name[pair[1]], tuple(float(v) for v in now[pair])))
        self._touching = set(now)
        if not full:
            return
        self._sim.settle_fallen(self.can_bodies.values(), self._spec.can.height_m)  # a fallen can: out of play
        bin_xy = self.bin_xy()
        for can_id, body in self.can_bodies.items():
            if can_id not in self.in_bin_at:
                p = plant.EvalBodyPoseInWorld(pc, body).translation()
                if where(self._spec, p, bin_xy) == "bin":
                    self.in_bin_at[can_id] = t
                    self.in_bin_wall[can_id] = self._wall_s()

    def bin_xy(self) -> np.ndarray | None:
        """The bin centre now (a moving bin's current place), or None for the spec's."""
        current = getattr(self._sim, "bin_center_xy", None)
        return current() if current is not None else None

    def fates(self, attempted: list[int]) -> list[CanResult]:
        """Where every can is now, in the scene's order (`attempted`: the ids of the cans whose
        cycle was executed)."""
        plant, pc = self._sim.plant, self._sim.pc
        bin_xy = self.bin_xy()
        cans = []
        for can_id in self._can_ids:
            p = plant.EvalBodyPoseInWorld(pc, self.can_bodies[can_id]).translation()
            place = where(self._spec, p, bin_xy)
            cans.append(CanResult(can_id, can_id in attempted, place, tuple(float(v) for v in p),
                                  self.in_bin_at.get(can_id) if place == "bin" else None))
        return cans
