"""A moving bin in physics: the replanning loop around every planner, and its record.

Each can's approach, descend and lift are the planner's plans as today (the plate does not move).
The rest is planned online, identically for every planner (`suite.execution.replan.plan_online`):

- at lift start, the transit toward the drop pose over where the bin is predicted to be on
  arrival (`suite.execution.bin_estimate`: delayed, noisy estimates, constant velocity); the arm
  holds at the lift's end until it is ready (its wall time counts as simulated time);
- during the transit, at every new estimate: if the drop position predicted for the plan's
  arrival has drifted beyond `drift_tolerance_m` from the planned one, a replan starts. Its splice
  time is t_s = now + `replan_deadline_s`; it plans from the state the current plan commands at
  t_s (a stopping blend, then the planner's path, validated and timed). The simulation is treated
  as running in real time while it plans: if its latency (wall time) is within the deadline, the
  new plan is spliced in at t_s; otherwise it is a deadline miss and the current plan goes on
  (the planner is busy until now + latency). A failed replan also leaves the current plan;
- on arrival the can is released only when the gripper (the arm's own joint state) is over the
  bin's opening by the estimate now and by its prediction at the end of the opening; otherwise
  the arm holds and replans from rest (same deadline rule), and after `max_wait_s` it stops
  safely with the can in the gripper (not delivered; later cans are not attempted);
- after the release, the return to above the plate is planned from where the arm is (its
  commanded rest configuration, within tracking error of the measured one).

The record (`MovingBinRecord`) holds per episode: cans in the bin (by the bin's current pose),
replans, their latencies, deadline misses, failures, the jump at every splice, grasp-to-release
times, contacts with the bin or the person, and every replan event.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from typing import Any, Sequence

import numpy as np

from planners.base import PlanningProblem, TaskWaypoint
from scenes.grasp_rule import truth_grasp, waypoint_pose
from scenes.moving_bin import MovingBinScenario, bin_path, check_scenario
from scenes.scene import HeldCan, Scene
from suite.execution.bin_estimate import BinEstimator
from suite.execution.commands import CommandStream
from suite.execution.config import ExecutionConfig
from suite.execution.monitor import Monitor
from suite.execution.replan import OnlinePlan, plan_online

log = logging.getLogger(__name__)

#: Planners the loop cannot run, with the reason (their offline preparation is tied to the world).
NOT_APPLICABLE = {
    "gcs": "its convex regions are built offline for one fixed world",
    "prm-roadmap": "its roadmap is built offline for one fixed world",
    "prm-roadmap-shortcut": "its roadmap is built offline for one fixed world",
}
#: A first guess of a transit's duration (s), before one was timed.
TRANSIT_GUESS_S = 1.5
#: Kept replan events per record.
MAX_EVENTS = 400
#: Simulated time an episode may take per can before it stops safely (a guard: every wait of the
#: loop is bounded by max_wait_s, so only a bug would reach it).
EPISODE_CAP_PER_CAN_S = 60.0


@dataclasses.dataclass(frozen=True)
class ReplanEvent:
    """One online plan: when, why, how long it took and what came of it.

    Attributes:
        t_s: simulated time it started.
        can_id: the can in the gripper (or just released, for a return).
        trigger: "lift" (the first transit), "drift" (the prediction moved during the transit),
            "arrival" (not over the opening on arrival), "return".
        drift_m: the predicted drop position's distance from the planned one (drift, arrival).
        latency_s: its wall time.
        deadline_s: its deadline (drift, arrival), or None (the arm waits at rest for it).
        outcome: "spliced", "missed" (latency over the deadline: the current plan goes on),
            "failed" (no valid plan: the current plan goes on), "planned" (lift, return).
        reason: a failure's reason.
        jump_q_rad, jump_v_rad_s: the largest joint jump of the command at the splice and where
            the blend meets the new path (spliced only; ~0 by construction).
        parts_s: wall time per step (world, blend, ik, plan, validate, timing).
    """

    t_s: float
    can_id: int
    trigger: str
    drift_m: float | None
    latency_s: float
    deadline_s: float | None
    outcome: str
    reason: str = ""
    jump_q_rad: float | None = None
    jump_v_rad_s: float | None = None
    parts_s: dict[str, float] = dataclasses.field(default_factory=dict)

    def to_json(self) -> dict:
        out = dataclasses.asdict(self)
        for k, v in out.items():
            if isinstance(v, float):
                out[k] = round(v, 6)
        out["parts_s"] = {k: round(v, 5) for k, v in self.parts_s.items()}
        return out


@dataclasses.dataclass(frozen=True)
class CanEpisode:
    """One can's run with the moving bin: released over the bin or not, and its timing."""

    can_id: int
    released: bool
    grasp_to_release_s: float | None
    release_offset_m: float | None  # the gripper's true distance (xy) from the bin centre at release
    gave_up: str = ""

    def to_json(self) -> dict:
        out = dataclasses.asdict(self)
        for k in ("grasp_to_release_s", "release_offset_m"):
            out[k] = None if out[k] is None else round(out[k], 4)
        return out


@dataclasses.dataclass(frozen=True)
class MovingBinRecord:
    """One planner's episode on one scene at one bin speed (`to_json` for moving_bin.json).

    status is "ok", "not_applicable" (the planner cannot run the loop: `reason`) or "error".
    speed_m_s is the bin's cruise speed; bin_mean_speed_m_s its mean over the episode (it stops at
    each target point)."""

    planner: str
    scene_seed: int
    variant: str
    speed_m_s: float
    scenario: dict[str, Any]
    status: str
    reason: str = ""
    bin_mean_speed_m_s: float | None = None
    cans_total: int = 0
    cans_attempted: int = 0
    cans_in_bin: int = 0
    cans_released: int = 0
    cans_given_up: int = 0
    replans: int = 0
    splices: int = 0
    deadline_misses: int = 0
    replan_failures: int = 0
    replan_latency_median_s: float | None = None
    replan_latency_p95_s: float | None = None
    plan_latency_median_s: float | None = None
    splice_jump_q_rad: float | None = None
    splice_jump_v_rad_s: float | None = None
    grasp_to_release_median_s: float | None = None
    contacts_bin: int = 0
    contacts_person: int = 0
    collisions: int = 0
    sim_time_s: float = 0.0
    wall_time_s: float = 0.0
    stopped: str = ""
    cans: tuple[CanEpisode, ...] = ()
    fates: tuple[dict, ...] = ()
    events: tuple[ReplanEvent, ...] = ()
    contact_events: tuple[dict, ...] = ()
    replay: str | None = None

    @property
    def replans_per_can(self) -> float | None:
        return self.replans / self.cans_attempted if self.cans_attempted else None

    def to_json(self) -> dict:
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        out["cans"] = [c.to_json() for c in self.cans]
        out["events"] = [e.to_json() for e in self.events]
        out["fates"] = list(self.fates)
        out["contact_events"] = list(self.contact_events)
        out["replans_per_can"] = self.replans_per_can
        for k, v in out.items():
            if isinstance(v, float):
                out[k] = round(v, 6)
        return out


@dataclasses.dataclass(frozen=True)
class MovingBinJob:
    """One planner's moving-bin episode on one scene (picklable plain values).

    Attributes:
        planner, planner_config: the planner and its settings.
        scene: the scene at the start (an `open` or `wall` station).
        scenario: the bin's motion, sensing and the loop's settings.
        cans: per can in picking order, (can id, its five paths or None where a problem failed,
            first failed status): the approach, descend and lift are executed as planned.
        q_home: where the first approach starts.
        time_limit_s: the planning budget of a motion the arm waits for at rest (the first
            transit, the return).
        seed: the run seed.
        replay_path: where to write the Meshcat replay, or None.
        config: the simulation settings.
    """

    planner: str
    planner_config: dict[str, Any]
    scene: Scene
    scenario: MovingBinScenario
    cans: tuple[tuple[int, tuple[Any, ...], str], ...]
    q_home: tuple[float, ...]
    time_limit_s: float
    seed: int
    replay_path: str | None = None
    config: ExecutionConfig = ExecutionConfig()


def _quantile(values: Sequence[float], q: float) -> float | None:
    return float(np.quantile(values, q)) if len(values) else None


class _Episode:
    """The state machine of one episode (see the module docstring)."""

    def __init__(self, job: MovingBinJob, planner, *, meshcat=None):
        from scenes.robot_model import load_robot
        from suite.execution.plant import build_simulation
        from suite.scoring.timing import time_parameterize

        self.job, self.planner = job, planner
        scene, scenario = job.scene, job.scenario
        self.spec = spec = scene.spec
        self.s = scenario
        self.robot = load_robot(spec.robot)
        self.path = bin_path(scenario, spec)
        self.estimator = BinEstimator(scenario, self.path, spec)
        origin = np.array(spec.bin.center_xy_m, float)
        path = self.path
        self.open_w = spec.grasp.open_width_m
        self.q_home = np.asarray(job.q_home, float)
        self.stream = CommandStream(q_home=self.q_home, open_width_m=self.open_w, config=job.config)
        self.sim = build_simulation(scene, self.stream, q_home=self.q_home, config=job.config, meshcat=meshcat,
                                    moving_bin=scenario, bin_drive=lambda t: (path.at(t)[0] - origin, path.at(t)[1]))
        self.rng = np.random.default_rng([job.seed, scene.seed, 2024])
        self.period = 1.0 / scenario.estimate_rate_hz
        X_plate, X_middle = (waypoint_pose(p) for p in (spec.waypoints.above_plate_m, spec.waypoints.middle_m))
        self.X_middle = X_middle
        self.X_plate = X_plate
        # the cans: the first three motions timed as in a trial; the rest is planned online
        self.queue: list[tuple[int, list]] = []
        self.stopped = ""
        for can_id, paths, failed in job.cans:
            if any(p is None for p in paths[:3]):
                self.stopped = f"can {can_id}: {failed or 'not planned'}"
                break
            timed = [time_parameterize(np.asarray(p, float), robot=self.robot) for p in paths[:3]]
            if not all(t.ok for t in timed):
                self.stopped = f"can {can_id}: timing failed"
                break
            self.queue.append((can_id, timed))
        self.removed: list[int] = []
        self.attempted: list[int] = []
        self.events: list[ReplanEvent] = []
        self.cans: list[CanEpisode] = []
        self.mode = "idle"
        self.can_id = -1
        self.done = False
        self.plan_wall = 0.0
        self.last_transit_s = TRANSIT_GUESS_S

    # --- helpers -------------------------------------------------------------------------------

    def _templates(self, can_id: int) -> tuple[PlanningProblem, PlanningProblem]:
        """The can's transit and return problems as the cycle poses them (no IK: the goals are
        solved online)."""
        scene, spec = self.job.scene, self.spec
        can = next(c for c in scene.cans if c.id == can_id)
        grasp = truth_grasp(scene, can)
        X_bin = waypoint_pose(spec.waypoints.above_bin_m)
        removed = tuple(self.removed) + (can_id,)
        nan = np.full(7, np.nan)
        common = dict(scene=scene, can_id=can_id, q_start=nan, q_goal=None, removed_can_ids=removed,
                      time_limit_s=self.job.time_limit_s, seed=self.job.seed)
        transit = PlanningProblem(kind="transit", X_WG_goal=X_bin, held=HeldCan.from_grasp(can, grasp.X_WG),
                                  gripper_opening_m=2 * spec.can.radius_m,
                                  waypoints=(TaskWaypoint(18.0, self.X_plate), TaskWaypoint(30.0, X_bin)), **common)
        back = PlanningProblem(kind="return", X_WG_goal=self.X_plate, held=None, gripper_opening_m=self.open_w,
                               waypoints=(TaskWaypoint(33.0, X_bin), TaskWaypoint(45.0, self.X_plate)), **common)
        return transit, back

    def _plan(self, *, template, t: float, bin_xy, q_s, v_s, a_s, budget_s, q_goal=None, via=None,
              warm=None) -> OnlinePlan:
        w0 = time.perf_counter()
        res = plan_online(planner=self.planner, template=template, scenario=self.s, bin_xy_m=bin_xy, q_s=q_s,
                          v_s=v_s, a_s=a_s, budget_s=budget_s, q_goal=q_goal, q_goal_seed=self.q_goal, via=via,
                          warm_start=warm, rng=self.rng)
        self.plan_wall += time.perf_counter() - w0
        return res

    def _event(self, t, trigger, res: OnlinePlan, outcome, *, drift=None, deadline=None, jump=(None, None)):
        self.events.append(ReplanEvent(t, self.can_id, trigger, drift, res.latency_s, deadline, outcome, res.reason,
                                       jump[0], jump[1], dict(res.parts_s)))

    def _gripper_xy(self) -> np.ndarray:
        sim = self.sim
        body = sim.plant.GetBodyByName("body", sim.wsg)
        return sim.plant.EvalBodyPoseInWorld(sim.pc, body).translation()[:2].copy()

    def _over_opening(self, t: float) -> bool:
        """Is the gripper over the bin's opening by the estimate now and at the end of the opening?"""
        b = self.spec.bin
        half = np.array(b.outer_size_m[:2]) / 2 - b.wall_thickness_m - self.spec.can.radius_m - self.s.release_margin_m
        p = self._gripper_xy()
        return all(bool(np.all(np.abs(p - self.estimator.predict(t, t_at)) <= half))
                   for t_at in (t, t + self.job.config.open_s))

    def _via(self, q: np.ndarray, bin_xy) -> list:
        """The task's middle waypoint while the gripper has not passed it on the way to the bin."""
        from scenes.moving_bin import drop_pose

        p = self.robot.gripper_pose(q[None, :])[0][:3, 3]
        goal = drop_pose(self.spec, bin_xy)[:3, 3]
        return [self.X_middle] if np.linalg.norm(p - goal) > np.linalg.norm(self.X_middle[:3, 3] - goal) else []

    def _stop(self, reason: str, *, carrying: bool) -> None:
        """Stop safely: hold where the arm is (the gripper closed on a carried can) and settle."""
        self.stopped = reason
        w = 0.0 if carrying else self.open_w
        self.stream.append_hold("hold", self.can_id if carrying else -1, self.job.config.settle_s, width_from_m=w,
                                carrying=carrying)
        self.done = True

    # --- events --------------------------------------------------------------------------------

    def on_stream_end(self, t: float) -> None:
        handler = {"idle": self._next_can, "lift": self.on_lift_start, "await_transit": self._retry_transit,
                   "transit": self._arrived, "released": self._plan_return, "returning": self._next_can}[self.mode]
        handler(t)

    def _next_can(self, t: float) -> None:
        if not self.queue:
            self.stream.finish()
            self.done = True
            return
        self.can_id, (approach, descend, lift) = self.queue.pop(0)
        self.attempted.append(self.can_id)
        self.transit_template, self.return_template = self._templates(self.can_id)
        st, c = self.stream, self.can_id
        st.append_motion("approach", c, approach, width_m=self.open_w, carrying=False)
        st.append_motion("descend", c, descend, width_m=self.open_w, carrying=False)
        st.append_hold("close", c, self.job.config.close_s, width_from_m=self.open_w, width_to_m=0.0, carrying=False)
        self.grasp_t = st.duration_s
        self.lift_start_t = st.duration_s
        st.append_motion("lift", c, lift, width_m=0.0, carrying=True)
        self.lift_end_t = st.duration_s
        self.q_goal = None
        self.mode = "lift"
        self.arrived_t = None
        self.busy_until = 0.0

    def on_lift_start(self, t: float) -> None:
        """Plan the transit toward where the bin will be on arrival; the arm holds until it is ready."""
        bin_xy = self.estimator.predict(t, self.lift_end_t + self.last_transit_s)
        q = self.stream.q_end
        z = np.zeros(7)
        res = self._plan(template=self.transit_template, t=t, bin_xy=bin_xy, q_s=q, v_s=z, a_s=z,
                         budget_s=self.job.time_limit_s, via=self._via(q, bin_xy))
        self._event(t, "lift", res, "planned" if res.ok else "failed")
        if res.ok:
            start = max(self.lift_end_t, t + res.latency_s)
            self._start_transit(res, start)
        else:
            self.mode = "await_transit"

    def _start_transit(self, res: OnlinePlan, start: float) -> None:
        st = self.stream
        if start > st.duration_s:
            st.append_hold("wait", self.can_id, start - st.duration_s, width_from_m=0.0, carrying=True)
        st.append_motion("transit", self.can_id, res.trajectory, width_m=0.0, carrying=True)
        self._adopt(res, start)

    def _adopt(self, res: OnlinePlan, motion_start: float) -> None:
        self.target_xy = res.bin_xy_m
        self.q_goal = res.q_goal
        self.transit = (res.trajectory, motion_start)
        self.arrival_t = motion_start + res.trajectory.duration_s
        self.last_transit_s = res.trajectory.duration_s
        self.mode = "transit"

    def _retry_transit(self, t: float) -> None:
        if t - self.lift_end_t > self.s.max_wait_s:
            self._give_up(t, "no transit plan within the wait")
            return
        self.on_lift_start(t)
        if self.mode == "await_transit":
            self.stream.append_hold("wait", self.can_id, max(self.events[-1].latency_s, self.period),
                                    width_from_m=0.0, carrying=True)

    def on_estimate(self, t: float) -> None:
        """A new estimate during the transit: replan if the predicted drop position drifted."""
        if self.mode != "transit" or t >= self.arrival_t or t < self.busy_until:
            return
        predicted = self.estimator.predict(t, self.arrival_t)
        drift = float(np.linalg.norm(predicted - self.target_xy))
        if drift <= self.s.drift_tolerance_m:
            return
        D = self.s.replan_deadline_s
        t_s = t + D
        q_s, v_s, a_s = self.stream.state(t_s)
        traj, t0 = self.transit
        warm = traj.q[traj.t_s >= t_s - t0] if t_s - t0 < traj.duration_s else None
        res = self._plan(template=self.transit_template, t=t, bin_xy=predicted, q_s=q_s, v_s=v_s, a_s=a_s,
                         budget_s=D, via=self._via(q_s, predicted), warm=warm if warm is not None and len(warm) > 1 else None)
        self._settle(t, t_s, res, "drift", drift)

    def _settle(self, t: float, t_s: float, res: OnlinePlan, trigger: str, drift: float) -> None:
        """Splice a replan's motion in at t_s if it came within the deadline; else keep the plan."""
        D = self.s.replan_deadline_s
        if res.latency_s > D:
            self._event(t, trigger, res, "missed", drift=drift, deadline=D)
            self.busy_until = t + res.latency_s
            return
        if not res.ok:
            self._event(t, trigger, res, "failed", drift=drift, deadline=D)
            self.busy_until = t + res.latency_s
            return
        st = self.stream
        q_old, v_old, _ = st.state(t_s)
        st.cut(t_s, can_id=self.can_id, width_m=0.0, carrying=True)
        if res.blend.duration_s > 0:
            st.append_motion("blend", self.can_id, res.blend, width_m=0.0, carrying=True)
        start = t_s + res.blend.duration_s
        st.append_motion("transit", self.can_id, res.trajectory, width_m=0.0, carrying=True)
        q_new, v_new, _ = st.state(t_s)
        qb, vb, _ = res.blend.sample(res.blend.duration_s)
        qp, vp, _ = res.trajectory.sample(0.0)
        jump_q = max(float(np.max(np.abs(q_new - q_old))), float(np.max(np.abs(qp - qb))))
        jump_v = max(float(np.max(np.abs(v_new - v_old))), float(np.max(np.abs(vp - vb))))
        self._event(t, trigger, res, "spliced", drift=drift, deadline=D, jump=(jump_q, jump_v))
        self._adopt(res, start)
        self.busy_until = t_s

    def _arrived(self, t: float) -> None:
        """At rest at the end of the transit: release over the opening, or hold and replan."""
        st = self.stream
        if t < self.busy_until:  # a replan that missed its deadline is still running
            st.append_hold("wait", self.can_id, self.busy_until - t, width_from_m=0.0, carrying=True)
            return
        if self.arrived_t is None:
            self.arrived_t = t  # the wait runs from the first arrival, whatever is replanned after it
        if self._over_opening(t):
            truth = self.path.at(t)[0]
            self.cans.append(CanEpisode(self.can_id, True, t - self.grasp_t,
                                        float(np.linalg.norm(self._gripper_xy() - truth))))
            st.append_hold("open", self.can_id, self.job.config.open_s, width_from_m=0.0, width_to_m=self.open_w,
                           carrying=False)
            self.removed.append(self.can_id)
            self.mode = "released"
            self.released_t = t + self.job.config.open_s
            return
        if t - self.arrived_t > self.s.max_wait_s:
            self._give_up(t, f"not over the bin's opening after {self.s.max_wait_s:g} s")
            return
        D = self.s.replan_deadline_s
        t_s = t + D
        predicted = self.estimator.predict(t, t_s + 1.0)
        drift = float(np.linalg.norm(predicted - self.target_xy))
        q = st.q_end
        z = np.zeros(7)
        res = self._plan(template=self.transit_template, t=t, bin_xy=predicted, q_s=q, v_s=z, a_s=z, budget_s=D)
        self._settle(t, t_s, res, "arrival", drift)
        if self.stream.duration_s <= t + 1e-9:  # nothing spliced: hold and look again
            st.append_hold("wait", self.can_id, max(res.latency_s, self.period), width_from_m=0.0, carrying=True)

    def _give_up(self, t: float, why: str) -> None:
        self.cans.append(CanEpisode(self.can_id, False, None, None, gave_up=why))
        self._stop(f"can {self.can_id}: {why}; stopped safely with the can in the gripper", carrying=True)

    def _plan_return(self, t: float) -> None:
        q = self.stream.q_end
        z = np.zeros(7)
        goal = np.asarray(self.queue[0][1][0].q[0], float) if self.queue else self.q_home
        res = self._plan(template=self.return_template, t=t, bin_xy=self.estimator.predict(t, t + 1.0), q_s=q,
                         v_s=z, a_s=z, budget_s=self.job.time_limit_s, q_goal=goal, via=[self.X_middle])
        self._event(t, "return", res, "planned" if res.ok else "failed")
        st = self.stream
        if res.ok:
            st.append_hold("wait", self.can_id, res.latency_s, width_from_m=self.open_w, carrying=False)
            st.append_motion("return", self.can_id, res.trajectory, width_m=self.open_w, carrying=False)
            self.mode = "returning"
        elif t - self.released_t > self.s.max_wait_s:
            self._stop(f"can {self.can_id}: no return plan ({res.reason})", carrying=False)
        else:
            st.append_hold("wait", self.can_id, max(res.latency_s, self.period), width_from_m=self.open_w,
                           carrying=False)

    # --- the loop ------------------------------------------------------------------------------

    def run(self) -> MovingBinRecord:
        job, st, sim = self.job, self.stream, self.sim
        wall0 = time.perf_counter()
        monitor = Monitor(sim, job.scene, st, lambda: time.perf_counter() - wall0 - self.plan_wall)
        sim.simulator.Initialize()
        dt = job.config.time_step_s
        every = max(1, round(0.01 / dt))
        steps, t = 0, 0.0
        last_k = self.estimator.latest_index(0.0)
        lifted: set[int] = set()
        while True:
            if not self.done and t > EPISODE_CAP_PER_CAN_S * max(1, len(job.cans)):
                carrying = st.at(t).carrying
                st.cut(t, can_id=self.can_id, width_m=0.0 if carrying else self.open_w, carrying=carrying)
                self._stop(f"the episode ran past its cap of {EPISODE_CAP_PER_CAN_S:g} s a can", carrying=carrying)
            if not self.done and t >= st.duration_s - 1e-9:
                self.on_stream_end(t)
            if self.done and t >= st.duration_s - 1e-9:
                break
            steps += 1
            t = min(steps * dt, st.duration_s)
            sim.simulator.AdvanceTo(t)
            monitor.check(sim.root, full=steps % every == 0 or t >= st.duration_s)
            if self.mode == "lift" and self.can_id not in lifted and t >= self.lift_start_t:
                lifted.add(self.can_id)
                self.on_lift_start(t)
            k = self.estimator.latest_index(t)
            if k > last_k:
                last_k = k
                self.on_estimate(t)
        wall = time.perf_counter() - wall0 - self.plan_wall
        fates = monitor.fates(self.attempted)
        return self._record(monitor, fates, wall)

    def _record(self, monitor, fates, wall: float) -> MovingBinRecord:
        deadline_bound = [e for e in self.events if e.trigger in ("drift", "arrival")]
        lat = [e.latency_s for e in deadline_bound]
        plans = [e.latency_s for e in self.events if e.trigger in ("lift", "return")]
        spliced = [e for e in deadline_bound if e.outcome == "spliced"]
        released = [c.grasp_to_release_s for c in self.cans if c.released]
        job = self.job
        return MovingBinRecord(
            planner=job.planner, scene_seed=job.scene.seed, variant=job.scene.variant,
            speed_m_s=self.s.speed_m_s, scenario=self.s.to_json(), status="ok",
            bin_mean_speed_m_s=self.path.mean_speed_m_s(self.stream.duration_s),
            cans_total=len(job.scene.cans), cans_attempted=len(self.attempted),
            cans_in_bin=sum(f.where == "bin" for f in fates), cans_released=len(released),
            cans_given_up=sum(1 for c in self.cans if not c.released),
            replans=len(deadline_bound), splices=len(spliced),
            deadline_misses=sum(e.outcome == "missed" for e in deadline_bound),
            replan_failures=sum(e.outcome == "failed" for e in deadline_bound),
            replan_latency_median_s=_quantile(lat, 0.5), replan_latency_p95_s=_quantile(lat, 0.95),
            plan_latency_median_s=_quantile(plans, 0.5),
            splice_jump_q_rad=max((e.jump_q_rad for e in spliced), default=None),
            splice_jump_v_rad_s=max((e.jump_v_rad_s for e in spliced), default=None),
            grasp_to_release_median_s=_quantile(released, 0.5),
            contacts_bin=monitor.moving_contacts["bin"], contacts_person=monitor.moving_contacts["person"],
            collisions=monitor.n_episodes, sim_time_s=self.stream.duration_s, wall_time_s=wall,
            stopped=self.stopped, cans=tuple(self.cans), fates=tuple(f.to_json() for f in fates),
            events=tuple(self.events[:MAX_EVENTS]), contact_events=tuple(e.to_json() for e in monitor.events),
        )


def run_moving_bin(job: MovingBinJob, *, planner=None) -> MovingBinRecord:
    """Run one episode (`planner`: an instance to use instead of the job's, e.g. a test's)."""
    if job.planner in NOT_APPLICABLE and planner is None:
        return MovingBinRecord(job.planner, job.scene.seed, job.scene.variant, job.scenario.speed_m_s,
                               job.scenario.to_json(), "not_applicable", NOT_APPLICABLE[job.planner],
                               cans_total=len(job.scene.cans))
    check_scenario(job.scenario, job.scene.spec, reach=False)
    if len(job.q_home) != 7:
        return MovingBinRecord(job.planner, job.scene.seed, job.scene.variant, job.scenario.speed_m_s,
                               job.scenario.to_json(), "error", "no plan of this scene to execute",
                               cans_total=len(job.scene.cans))
    if planner is None:
        from planners.registry import planner_class
        from suite.run.trial import make_config

        cls = planner_class(job.planner)
        planner = cls(make_config(cls, job.planner_config))
    meshcat = None
    if job.replay_path:
        from suite.execution.jobs import meshcat_for

        meshcat = meshcat_for(job.scene)
    episode = _Episode(job, planner, meshcat=meshcat)
    if meshcat is not None:
        meshcat.StartRecording(frames_per_second=job.config.publish_hz)
    record = episode.run()
    if meshcat is not None:
        from pathlib import Path

        meshcat.StopRecording()
        meshcat.PublishRecording()
        Path(job.replay_path).write_text(meshcat.StaticHtml(), encoding="utf-8")
        record = dataclasses.replace(record, replay=Path(job.replay_path).name)
    return record


def run_moving_bin_job(job: MovingBinJob) -> dict[str, Any]:
    """`run_moving_bin` as a JSON record; an exception is that episode's error record."""
    try:
        return run_moving_bin(job).to_json()
    except Exception as exc:  # one failed episode is its record's error, not the whole run's
        log.debug("moving bin episode of %s on seed %d failed", job.planner, job.scene.seed, exc_info=True)
        return MovingBinRecord(job.planner, job.scene.seed, job.scene.variant, job.scenario.speed_m_s,
                               job.scenario.to_json(), "error", f"{type(exc).__name__}: {exc}",
                               cans_total=len(job.scene.cans)).to_json()


def plan_scene_job(scene: Scene, scenario: MovingBinScenario, *, planner: str, planner_config: dict[str, Any],
                   time_limit_s: float, seed: int, replay_path: str | None = None,
                   config: ExecutionConfig = ExecutionConfig()) -> MovingBinJob:  # noqa: B008 (frozen)
    """A job whose approach, descend and lift are planned here, as a trial plans them (ground-truth
    grasps; `python -m suite execute --moving-bin`, tests)."""
    from planners.base import PROBLEM_KINDS
    from suite.problems.cycle import build_problems
    from suite.run.trial import run_problem

    problems = build_problems(scene, [truth_grasp(scene, c) for c in scene.cans], time_limit_s=time_limit_s, seed=seed)
    cans = []
    for i in range(0, len(problems), len(PROBLEM_KINDS)):
        chunk = problems[i:i + len(PROBLEM_KINDS)]
        paths, failed = [], ""
        for problem in chunk[:3]:  # approach, descend, lift; the transit and return are planned online
            rec = run_problem(problem, planner=planner, planner_config=planner_config, run_seed=seed)
            ok = rec["status"] == "success"
            paths.append(rec["path"] if ok else None)
            failed = failed or ("" if ok else f"{problem.kind} {rec['status']}")
        cans.append((chunk[0].can_id, (*paths, None, None), failed))
    return MovingBinJob(planner=planner, planner_config=planner_config, scene=scene, scenario=scenario,
                        cans=tuple(cans), q_home=tuple(float(v) for v in problems[0].q_start),
                        time_limit_s=time_limit_s, seed=seed, replay_path=replay_path, config=config)


def select_scenes(jobs: Sequence[Any], count: int) -> list[str]:
    """The keys of up to `count` open or wall scenes among execution jobs: the first of each
    family in turn (an open and a wall station before a second open), in the jobs' order."""
    by_family: dict[str, list[str]] = {}
    for job in jobs:
        key = job.scene.key()
        if job.scene.variant in ("open", "wall") and key not in by_family.setdefault(job.scene.variant, []):
            by_family[job.scene.variant].append(key)
    out: list[str] = []
    while len(out) < count and any(by_family.values()):
        for family in ("open", "wall"):
            if by_family.get(family) and len(out) < count:
                out.append(by_family[family].pop(0))
    return out


def sweep_jobs(exec_jobs: Sequence[Any], *, speeds: Sequence[float], scenario: MovingBinScenario, scenes: int,
               replay_dir=None, replay_speed: float | None = None) -> list[MovingBinJob]:
    """One moving-bin job per planner, selected scene and speed, from a comparison's execution jobs
    (`suite.execution.jobs.jobs_from_records`: their approach, descend and lift paths). Each
    planner's episode on the first scene at `replay_speed` records a Meshcat replay into
    `replay_dir` (replay_moving_bin_<planner>.html)."""
    from pathlib import Path

    keys = select_scenes(exec_jobs, scenes)
    out, replayed = [], set()
    for key in keys:
        for job in (j for j in exec_jobs if j.scene.key() == key):
            for speed in speeds:
                replay = None
                if replay_dir is not None and speed == replay_speed and job.planner not in replayed:
                    replayed.add(job.planner)
                    replay = str(Path(replay_dir) / f"replay_moving_bin_{job.planner}.html")
                out.append(MovingBinJob(
                    planner=job.planner, planner_config=job.planner_config, scene=job.scene,
                    scenario=dataclasses.replace(scenario, speed_m_s=float(speed)), cans=job.cans or (),
                    q_home=job.q_home or (), time_limit_s=job.time_limit_s, seed=job.seed, replay_path=replay,
                    config=job.config))
    return out
