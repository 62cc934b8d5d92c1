"""One moving-bin episode: the replanning loop around a planner, as a state machine over physics.

Each can's approach, descend and lift are the planner's plans (the plate does not move). The rest
is planned online, identically for every planner (`suite.execution.replan.plan_online`):

- at lift start, the transit toward the drop pose over where the bin is predicted to be on
  arrival (`suite.execution.bin_estimate`: delayed, noisy estimates, constant velocity), aimed
  ahead by the release ramp's lag; the arm holds at the lift's end until it is ready;
- during the transit, at every new estimate: if the drop position predicted for the plan's
  arrival has drifted beyond the tolerance (`MovingBinScenario.drift_tolerance`: it shrinks with
  the time to go), a replan starts. Its splice time is now plus the expected latency (the
  deadline when latency is measured, the planner's declared latency when it is modelled); it
  plans from the state the current plan commands then and joins the new path onto that motion
  without stopping (`suite.execution.splice.join_path`). A plan ready after its splice time is
  dropped (a deadline miss: the current plan goes on); a failed one likewise;
- on arrival, the release (`release: moving`): when the gripper, carried with the bin's
  estimated velocity, stays over the opening by the prediction, the arm accelerates to that
  velocity and follows the bin while the fingers open (`suite.execution.track`), then stops;
  otherwise it replans from rest toward the bin (same rule). With `release: rest` it releases
  standing still when the bin is under it now and at the end of the opening;
- a can's time from grasp to release is bounded in every phase (`can_time_limit_s`), and a
  wait over the bin by `max_wait_s`: past either the can is given up, carried back to its place
  on the plate and put down (reversed lift, open, reversed descend), and the next can follows;
- speed-and-separation monitoring (`ssm`): during a transit or a return the arm makes a
  protective stop when the person is nearer than the protective separation distance, and
  replans from rest once they are clear (`suite.execution.person`);
- after a release, the return to above the plate is planned from where the arm stopped.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from planners.base import PlanningProblem, TaskWaypoint
from scenes.grasp_rule import truth_grasp, waypoint_pose
from scenes.moving_bin import bin_path, person_offset_m, region
from scenes.scene import HeldCan
from suite.execution.bin_estimate import BinEstimator
from suite.execution.commands import CommandStream
from suite.execution.moving_bin_person import PersonGuard
from suite.execution.moving_bin_records import (
    CanEpisode,
    MovingBinJob,
    MovingBinRecord,
    ReplanEvent,
    episode_record,
    error_state,
    modelled_latency,
)
from suite.execution.moving_bin_release import ReleaseSteps
from suite.execution.replan import OnlinePlan, plan_online

#: A first guess of a transit's duration (s), before one was timed.
TRANSIT_GUESS_S = 1.5
#: Simulated time an episode may take per can before it stops safely: a guard above the per-can
#: limit and the put-down (only a bug reaches it).
EPISODE_CAP_PER_CAN_S = 90.0


class Episode(ReleaseSteps, PersonGuard):
    """The state machine of one episode (module docstring)."""

    def __init__(self, job: MovingBinJob, planner, *, meshcat=None):
        from scenes.robot_model import load_robot
        from suite.execution.person import SsmSettings
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
        self.modelled = scenario.latency_mode == "modelled"
        self.latency_model = modelled_latency(scenario, job.planner)
        self.person_offset = person_offset_m(scenario, spec)
        self.ssm = SsmSettings.for_scenario(scenario)
        X_plate, X_middle = (waypoint_pose(p) for p in (spec.waypoints.above_plate_m, spec.waypoints.middle_m))
        self.X_middle = X_middle
        self.X_plate = X_plate
        # the cans: approach, descend and lift timed as in a trial; the rest is planned online
        self.queue: list[tuple[int, list]] = []
        self.not_planned = ""
        for can_id, paths, failed in job.cans:
            if any(p is None for p in paths[:3]):
                self.not_planned = f"can {can_id}: {failed or 'not planned'}"
                break
            timed = [time_parameterize(np.asarray(p, float), robot=self.robot) for p in paths[:3]]
            if not all(t.ok for t in timed):
                self.not_planned = f"can {can_id}: timing failed"
                break
            self.queue.append((can_id, timed))
        self.stopped = self.not_planned
        self.removed: list[int] = []
        self.attempted: list[int] = []
        self.events: list[ReplanEvent] = []
        self.cans: list[CanEpisode] = []
        self.mode = "idle"
        self.can_id = -1
        self.done = False
        self.plan_wall = 0.0
        self.last_transit_s = TRANSIT_GUESS_S
        self.ssm_holds = 0
        self.escapes = 0  # this can's (`moving_bin_person.ESCAPE_TRIES`)
        self.escapes_total = 0
        self.escaping_until = -1.0
        self.releasing = None  # (opening starts, ends, lets the can go) of a release re-aimed at estimates
        self.pending_offset = None  # (index in cans, time) of a release whose offset is measured then
        self.person_min = np.inf
        self.near_misses = 0
        self._near = False
        self.t = 0.0

    # --- helpers -------------------------------------------------------------------------------

    def _templates(self, can_id: int) -> None:
        """The can's transit, return and put-down problems as the cycle poses them (no IK: the
        goals are solved online)."""
        scene, spec = self.job.scene, self.spec
        can = next(c for c in scene.cans if c.id == can_id)
        grasp = truth_grasp(scene, can)
        X_bin = waypoint_pose(spec.waypoints.above_bin_m)
        removed = tuple(self.removed) + (can_id,)
        nan = np.full(7, np.nan)
        common = dict(scene=scene, can_id=can_id, q_start=nan, q_goal=None, removed_can_ids=removed,
                      time_limit_s=self.job.time_limit_s, seed=self.job.seed)
        held = dict(held=HeldCan.from_grasp(can, grasp.X_WG), gripper_opening_m=2 * spec.can.radius_m)
        self.transit_template = PlanningProblem(
            kind="transit", X_WG_goal=X_bin, waypoints=(TaskWaypoint(18.0, self.X_plate), TaskWaypoint(30.0, X_bin)),
            **held, **common)
        self.return_template = PlanningProblem(
            kind="return", X_WG_goal=self.X_plate, held=None, gripper_opening_m=self.open_w,
            waypoints=(TaskWaypoint(33.0, X_bin), TaskWaypoint(45.0, self.X_plate)), **common)
        # the can goes back where it was: on the plate, not removed, once it is put down
        self.back_template = self.return_template.with_(removed_can_ids=tuple(self.removed))

    def _plan(self, *, template, t: float, bin_xy, q_s, v_s, a_s, deadline_bound: bool, start_s: float,
              q_goal=None, via=None, warm=None, drop_offset=None, held: bool = True) -> OnlinePlan:
        """One online plan of a motion starting at start_s; its latency is the wall time (measured)
        or the declared one (modelled)."""
        budget = self.s.replan_deadline_s if (deadline_bound and not self.modelled) else self.job.time_limit_s
        check = self._person_check(t, held, start_s)
        w0 = time.perf_counter()
        res = plan_online(planner=self.planner, template=template, scenario=self.s, bin_xy_m=bin_xy, q_s=q_s,
                          v_s=v_s, a_s=a_s, budget_s=budget, q_goal=q_goal, q_goal_seed=self.q_goal, via=via,
                          warm_start=warm, person_check=check, drop_offset_m=drop_offset, rng=self.rng)
        self.plan_wall += time.perf_counter() - w0
        if self.modelled:
            res = dataclasses.replace(res, latency_s=self.latency_model, parts_s={})
        return res

    def _event(self, t, trigger, res: OnlinePlan, outcome, *, drift=None, deadline=None, jump=(None, None),
               speed=None, expected=None):
        self.events.append(ReplanEvent(
            t, self.can_id, trigger, drift, res.latency_s, deadline, outcome, res.reason, res.stage, jump[0], jump[1],
            speed, bool(res.at_rest) if outcome == "spliced" else False, expected, dict(res.parts_s)))

    def _gripper_xy(self) -> np.ndarray:
        sim = self.sim
        body = sim.plant.GetBodyByName("body", sim.wsg)
        return sim.plant.EvalBodyPoseInWorld(sim.pc, body).translation()[:2].copy()

    def _half_opening(self) -> np.ndarray:
        b = self.spec.bin
        return np.array(b.outer_size_m[:2]) / 2 - b.wall_thickness_m - self.spec.can.radius_m - self.s.release_margin_m

    def _lead(self, t: float) -> np.ndarray:
        """How far ahead of the predicted bin the transit aims (the release ramp's lag)."""
        from suite.execution.track import ramp_lag_m

        if self.s.release != "moving":
            return np.zeros(2)
        return np.asarray(ramp_lag_m(self.estimator.velocity(t), self.s.track_ramp_s), float)

    def _via(self, q: np.ndarray, bin_xy) -> list:
        """The task's middle waypoint while the gripper has not passed it on the way to the bin."""
        from scenes.moving_bin import drop_pose

        p = self.robot.gripper_pose(q[None, :])[0][:3, 3]
        goal = drop_pose(self.spec, bin_xy)[:3, 3]
        return [self.X_middle] if np.linalg.norm(p - goal) > np.linalg.norm(self.X_middle[:3, 3] - goal) else []

    def _expected_latency(self) -> float:
        return self.latency_model if self.modelled else self.s.replan_deadline_s

    def _stop(self, reason: str, *, carrying: bool) -> None:
        """Stop safely: hold where the arm is (the gripper closed on a carried can) and settle."""
        self.stopped = reason
        w = 0.0 if carrying else self.open_w
        self.stream.append_hold("hold", self.can_id if carrying else -1, self.job.config.settle_s, width_from_m=w,
                                carrying=carrying)
        self.done = True

    def on_stream_end(self, t: float) -> None:
        """The arm has reached the end of its commands, at rest: the mode's next step, unless the
        person has walked into the arm standing there (then an escape first)."""
        if self.mode in ("transit", "released", "put_down", "put_down_done", "ssm_hold") and self._crowded(t) \
                and self._escape(t):
            self.escapes_total += 1
            return
        handler = {"idle": self._next_can, "lift": self.on_lift_start, "await_transit": self._retry_transit,
                   "transit": self._arrived, "released": self._plan_return, "returning": self._next_can,
                   "put_down": self._put_down, "put_down_done": self._plan_return,
                   "ssm_hold": self._hold_for_person}[self.mode]
        handler(t)

    def _next_can(self, t: float) -> None:
        if not self.queue:
            self.stream.finish()
            self.done = True
            return
        self.can_id, (approach, descend, lift) = self.queue.pop(0)
        self.attempted.append(self.can_id)
        self.approach, self.descend, self.lift = approach, descend, lift
        self._templates(self.can_id)
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
        self.put_down_tries = 0
        self.escapes = 0
        self.releasing = None

    def _over_time(self, t: float) -> bool:
        """Give the can up if its time from the grasp ran out (every carrying phase)."""
        if self.mode in ("await_transit", "transit", "ssm_hold") and self.carrying(t) \
                and t - self.grasp_t > self.s.can_time_limit_s:
            self._give_up(t, f"not released within {self.s.can_time_limit_s:g} s of the grasp")
            return True
        return False

    def carrying(self, t: float) -> bool:
        return self.stream.at(t).carrying

    def on_lift_start(self, t: float) -> None:
        """Plan the transit toward where the bin will be on arrival; the arm holds until it is ready."""
        if self._over_time(t):
            return
        bin_xy = self.estimator.predict(t, self.lift_end_t + self.last_transit_s)
        q = self.stream.q_end
        z = np.zeros(7)
        lead = self._lead(t)
        if self.s.aim == "centre":  # the control: over the region's centre, whatever the bin does
            bin_xy, lead = np.mean(region(self.s, self.spec), axis=0), np.zeros(2)
        res = self._plan(template=self.transit_template, t=t, bin_xy=bin_xy, q_s=q, v_s=z, a_s=z,
                         deadline_bound=False, start_s=max(self.lift_end_t, t), via=self._via(q, bin_xy),
                         drop_offset=lead)
        self._event(t, "lift", res, "planned" if res.ok else "failed")
        if res.ok:
            start = max(self.lift_end_t, t + res.latency_s)
            st = self.stream
            if start > st.duration_s:
                st.append_hold("wait", self.can_id, start - st.duration_s, width_from_m=0.0, carrying=True)
            st.append_motion("transit", self.can_id, res.trajectory, width_m=0.0, carrying=True)
            self._adopt(res, start, lead)
        else:
            self.mode = "await_transit"

    def _adopt(self, res: OnlinePlan, motion_start: float, lead) -> None:
        self.target_xy = res.bin_xy_m + lead
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
        """A new estimate: the time limit, the person's separation, then the drift of the transit."""
        if self.done:
            return
        if self.releasing is not None:
            self._track_update(t)
        if self._over_time(t):
            return
        if self.s.ssm and self._protective_stop(t):
            return
        if self.mode != "transit" or t >= self.arrival_t or t < self.busy_until or self.s.aim == "centre":
            return
        lead = self._lead(t)
        predicted = self.estimator.predict(t, self.arrival_t)
        drift = float(np.linalg.norm(predicted + lead - self.target_xy))
        if drift <= self.s.drift_tolerance(self.arrival_t - t):
            return
        E = self._expected_latency()
        t_s = t + E
        if t_s > self.arrival_t - self.s.commit_s:  # committed to this arrival
            return
        q_s, v_s, a_s = self.stream.state(t_s)
        traj, t0 = self.transit
        warm = traj.q[traj.t_s >= t_s - t0] if t_s - t0 < traj.duration_s else None
        res = self._plan(template=self.transit_template, t=t, bin_xy=predicted, q_s=q_s, v_s=v_s, a_s=a_s,
                         deadline_bound=True, start_s=t_s, via=self._via(q_s, predicted), drop_offset=lead,
                         warm=warm if warm is not None and len(warm) > 1 else None)
        self._settle(t, t_s, res, "drift", drift, lead)

    def _settle(self, t: float, t_s: float, res: OnlinePlan, trigger: str, drift: float, lead) -> None:
        """Splice a replan's motion in at t_s if it is ready by then; else keep the current plan."""
        D = None if self.modelled else self.s.replan_deadline_s
        E = t_s - t
        if res.latency_s > E + 1e-9:
            self._event(t, trigger, res, "missed", drift=drift, deadline=D, expected=E)
            self.busy_until = t + res.latency_s
            return
        if not res.ok:
            self._event(t, trigger, res, "failed", drift=drift, deadline=D, expected=E)
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
        self._event(t, trigger, res, "spliced", drift=drift, deadline=D, jump=(jump_q, jump_v),
                    speed=float(np.max(np.abs(v_old))), expected=E)
        self._adopt(res, start, lead)
        self.busy_until = t_s

    def _arrived(self, t: float, trigger: str = "arrival") -> None:
        """At rest at the end of the transit (or after a protective stop, `trigger` "resume"):
        release over the opening, or hold and replan."""
        st = self.stream
        if t < self.busy_until:  # a replan that missed its deadline is still running
            st.append_hold("wait", self.can_id, self.busy_until - t, width_from_m=0.0, carrying=True)
            return
        if self._over_time(t):
            return
        if self.arrived_t is None and trigger == "arrival":
            self.arrived_t = t  # the wait runs from the first arrival, whatever is replanned after it
        moving = self.s.release == "moving"
        v = self.estimator.velocity(t) if moving else np.zeros(2)
        if self._release_window(t, v) and self._release(t, v):
            return
        if self.arrived_t is not None and t - self.arrived_t > self.s.max_wait_s:
            self._give_up(t, f"not over the bin's opening after {self.s.max_wait_s:g} s")
            return
        centre = self.s.aim == "centre"
        if centre and np.max(np.abs(st.q_end - self.q_goal)) < 1e-3:
            # the control waits over the region's centre for the bin to come under it
            st.append_hold("wait", self.can_id, self.period, width_from_m=0.0, carrying=True)
            return
        E = self._expected_latency()
        t_s = t + E
        lead = self._lead(t)
        predicted = self.estimator.predict(t, t_s + self.last_transit_s)
        if centre:  # stopped short of the centre (a protective stop): go on to it
            predicted, lead = np.mean(region(self.s, self.spec), axis=0), np.zeros(2)
        drift = float(np.linalg.norm(predicted + lead - self.target_xy))
        q = st.q_end
        z = np.zeros(7)
        res = self._plan(template=self.transit_template, t=t, bin_xy=predicted, q_s=q, v_s=z, a_s=z,
                         deadline_bound=True, start_s=t_s, drop_offset=lead)
        self._settle(t, t_s, res, trigger, drift, lead)
        if self.stream.duration_s <= t + 1e-9:  # nothing spliced: hold and look again
            st.append_hold("wait", self.can_id, max(res.latency_s, self.period), width_from_m=0.0, carrying=True)

    def run(self) -> MovingBinRecord:
        from suite.execution.monitor import Monitor

        job, st, sim = self.job, self.stream, self.sim
        wall0 = time.perf_counter()
        monitor = Monitor(sim, job.scene, st, lambda: time.perf_counter() - wall0 - self.plan_wall)
        sim.simulator.Initialize()
        dt = job.config.time_step_s
        every = max(1, round(0.01 / dt))
        steps, t = 0, 0.0
        last_k = self.estimator.latest_index(0.0)
        lifted: set[int] = set()
        cap = EPISODE_CAP_PER_CAN_S * max(1, len(job.cans))
        try:
            while True:
                self.t = t
                if not self.done and t > cap:
                    carrying = self.carrying(t)
                    st.cut(t, can_id=self.can_id, width_m=0.0 if carrying else self.open_w, carrying=carrying)
                    self._stop(f"the episode ran past its cap of {EPISODE_CAP_PER_CAN_S:g} s a can", carrying=carrying)
                if not self.done and t >= st.duration_s - 1e-9:
                    self.on_stream_end(t)
                if self.done and t >= st.duration_s - 1e-9:
                    break
                steps += 1
                t = min(steps * dt, st.duration_s)
                sim.simulator.AdvanceTo(t)
                full = steps % every == 0 or t >= st.duration_s
                monitor.check(sim.root, full=full)
                if full:
                    self._watch_person(t)
                if self.pending_offset is not None:
                    self._measure_release(t)
                if self.mode == "lift" and self.can_id not in lifted and t >= self.lift_start_t:
                    lifted.add(self.can_id)
                    self.on_lift_start(t)
                k = self.estimator.latest_index(t)
                if k > last_k:
                    last_k = k
                    self.on_estimate(t)
        except Exception as exc:
            exc.moving_bin_state = self.error_state(t)  # type: ignore[attr-defined]
            raise
        wall = time.perf_counter() - wall0 - self.plan_wall
        fates = monitor.fates(self.attempted)
        return episode_record(self, monitor, fates, wall)

    def error_state(self, t: float) -> dict:
        """Where the simulation was when it failed (`moving_bin_records.error_state`)."""
        return error_state(self, t)
