"""The command stream of an execution: cans' timed cycles chained with the gripper actions between them.

Each can's five timed trajectories (approach, descend, lift, transit, return) are chained into one
command stream with the gripper actions between them: approach, descend, close, lift, transit,
open, return. A `CycleProvider` hands over each next can's cycle when the stream so far has been
executed (`planned_ahead` for plans made before execution; a closed-loop provider perceives and
plans between cycles from the `WorldState`).
"""

from __future__ import annotations

import bisect
import dataclasses
from collections.abc import Callable, Sequence

import numpy as np

from suite.execution.config import ExecutionConfig
from suite.scoring.timing import TimedTrajectory

#: The motions of one can's cycle and the gripper actions between them, in execution order.
PHASES = ("approach", "descend", "close", "lift", "transit", "open", "return")


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
    """One can's five timed motions, in the order of `planners.base.PROBLEM_KINDS` (four for a last
    can whose return was not planned)."""

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
        """Append a can's motions; a cycle of four (no return) ends with the gripper open over the bin."""
        approach, descend, lift, transit, *rest = cycle.trajectories
        w, closed = self._open, 0.0  # closed: the force limit, not the position, holds the can
        self._add("approach", cycle.can_id, approach.duration_s, approach, w, w, False)
        self._add("descend", cycle.can_id, descend.duration_s, descend, w, w, False)
        self._add("close", cycle.can_id, self._config.close_s, None, w, closed, False)
        self._add("lift", cycle.can_id, lift.duration_s, lift, closed, closed, True)
        self._add("transit", cycle.can_id, transit.duration_s, transit, closed, closed, True)
        self._add("open", cycle.can_id, self._config.open_s, None, closed, w, False)
        if rest:
            self._add("return", cycle.can_id, rest[0].duration_s, rest[0], w, w, False)

    @property
    def q_end(self) -> np.ndarray:
        """The arm's commanded configuration at the end of the stream so far."""
        return self._q.copy()

    def finish(self) -> None:
        """Hold still for the settling time at the end."""
        self._add("hold", -1, self._config.settle_s, None, self._open, self._open, False)

    # --- piece by piece (the moving bin's replanning loop) ------------------------------------

    def append_motion(self, phase: str, can_id: int, trajectory, *, width_m: float, carrying: bool) -> None:
        """Append one timed motion (a `TimedTrajectory` or a `splice.BlendTrajectory`) from where the
        stream ends."""
        self._add(phase, can_id, trajectory.duration_s, trajectory, width_m, width_m, carrying)

    def append_hold(self, phase: str, can_id: int, duration_s: float, *, width_from_m: float,
                    width_to_m: float | None = None, carrying: bool) -> None:
        """Append a piece where the arm holds where the stream ends (the gripper may move)."""
        to = width_from_m if width_to_m is None else width_to_m
        self._add(phase, can_id, duration_s, None, width_from_m, to, carrying)

    def state(self, t_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The commanded arm position, velocity and acceleration (7,) each at t_s."""
        return self.at(t_s).arm(t_s)

    def cut(self, t_s: float, *, can_id: int, width_m: float, carrying: bool) -> None:
        """End the stream at t_s: the piece running then ends there and later pieces are dropped;
        a stream that ends before t_s holds until then. The next piece starts from the commanded
        state at t_s (a splice: `splice.stopping_blend` from it)."""
        if t_s >= self.duration_s:
            if t_s > self.duration_s:
                self.append_hold("wait", can_id, t_s - self.duration_s, width_from_m=width_m, carrying=carrying)
            return
        q_s = self.state(t_s)[0].copy()
        i = bisect.bisect_right(self._starts, t_s) - 1
        del self.segments[i + 1:], self._starts[i + 1:]
        last = self.segments[i]
        self.segments[i] = dataclasses.replace(last, duration_s=t_s - last.t0_s)
        self.duration_s = t_s
        self._q = q_s

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
        q_images: the arm's joint positions when `images` were rendered (its points are left out
            of a perceived world), or None.
    """

    t_s: float
    q_arm: np.ndarray
    q_command: np.ndarray
    X_WCans: dict[int, np.ndarray]
    images: dict | None
    q_images: np.ndarray | None = None


#: Given the world between cycles, the next can's cycle, or None to stop (with a reason).
CycleProvider = Callable[[WorldState], "tuple[CanCycle | None, str]"]


def planned_ahead(cycles: Sequence[CanCycle], stopped: str = "") -> CycleProvider:
    """The open-loop provider: cycles planned before execution, in order."""
    queue = list(cycles)

    def provide(_world: WorldState):
        return (queue.pop(0), "") if queue else (None, stopped)

    return provide


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
