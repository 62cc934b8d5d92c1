"""The end of a can's transit in the moving-bin loop: the release, a given-up can put down, the return.

A mixin of `suite.execution.moving_bin_episode.Episode` (its state: the command stream, the
estimator, the can's lift and descend, the templates), one job per method:

- `_release_window`, `_release`: with `release: moving`, the gripper accelerates to the bin's
  estimated velocity over `track_ramp_s` and follows it while the fingers open
  (`suite.execution.track.tracking_motion`, Drake's differential IK), then stops; the can falls
  with the bin's velocity. The release happens only if the gripper so carried stays over the
  opening by the prediction until the fingers have opened. With `release: rest` it opens standing
  still when the bin is under it now and at the end of the opening;
- `_give_up`, `_put_down`: a can not released in time is carried back over its place (planned
  online by the same planner), lowered by the lift played backwards, let go, and the gripper
  retreats by the descend and the approach played backwards (the way it came, in the same world:
  the start of a return planned from the pre-grasp would sit within the margins of the can it just
  let go): the can is back on the plate, the next can follows;
- `_track_update` (`track_feedback`): at every new estimate during the ramp and the opening, until
  the fingers let the can go, the gripper is re-aimed: its velocity ramps from the commanded one
  to the bin's new estimated velocity plus a correction toward the bin's predicted centre (what
  is left of the offset over the time until the can is let go, at most TRACK_CORRECTION_M_S),
  and the return is planned again from the new end of the opening;
- `_plan_return`: the return to above the plate (or to the next can's approach) from rest.

A put-down's and a return's world has the bin and the person where they are estimated now (the
person's motion along the plan is the swept check's): the first loop placed them where they would
be a second later, which could put the person on the arm's start.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from suite.execution.moving_bin_records import CanEpisode, ReplanEvent
from suite.execution.splice import stopping_blend

#: Tries of a put-down plan before the episode stops with the can in the gripper.
PUT_DOWN_TRIES = 3
#: A release re-aimed at a new estimate takes over this long after it (s): differential IK over
#: the rest of the opening (a few milliseconds) and the command's next period.
TRACK_UPDATE_S = 0.02
#: The largest correction of the release's velocity toward the bin's predicted centre (m/s).
TRACK_CORRECTION_M_S = 0.2


class Window:
    """A time window [t0, t0 + duration] of a timed motion, as a motion of its own."""

    def __init__(self, trajectory, t0_s: float, duration_s: float):
        self._traj, self._t0, self.duration_s = trajectory, t0_s, duration_s
        self.q = trajectory.sample(np.array([t0_s, t0_s + duration_s]))[0]
        self.ok, self.status = True, "ok"

    def sample(self, t_s):
        return self._traj.sample(np.clip(t_s, 0.0, self.duration_s) + self._t0)


class Reversed:
    """A motion from rest to rest played backwards (a lift becomes a put-down)."""

    def __init__(self, trajectory):
        self._traj, self.duration_s = trajectory, trajectory.duration_s
        self.q = np.asarray(trajectory.q)[::-1].copy()
        self.ok, self.status = True, "ok"

    def sample(self, t_s):
        q, v, a = self._traj.sample(self.duration_s - np.clip(t_s, 0.0, self.duration_s))
        return q, -v, a


class ReleaseSteps:
    """The release, the put-down and the return (module docstring); mixed into the Episode."""

    def _halt(self, t: float, phase: str) -> None:
        """Cut the command at t and bring the arm to rest (a stopping blend from its state)."""
        st = self.stream
        seg = st.at(t)
        carrying, width = seg.carrying, seg.width(t)[0]
        q, v, a = st.state(t)
        st.cut(t, can_id=self.can_id, width_m=width, carrying=carrying)
        blend = stopping_blend(q, v, a, v_lim=self.robot.velocity_limits_rad_s,
                               a_lim=self.robot.acceleration_limits_rad_s2, q_lo=self.robot.lower_rad,
                               q_hi=self.robot.upper_rad)
        if blend is not None and blend.duration_s > 0:
            st.append_motion(phase, self.can_id, blend, width_m=width, carrying=carrying)

    # --- events --------------------------------------------------------------------------------

    def _release_window(self, t: float, v: np.ndarray) -> bool:
        """Will the gripper, carried at the bin's estimated velocity `v` from now (after the ramp),
        stay over the opening by the prediction until the fingers have opened?"""
        from suite.execution.track import ramp_lag_m

        ramp, open_s = (self.s.track_ramp_s, self.job.config.open_s) if self.s.release == "moving" \
            else (0.0, self.job.config.open_s)
        p = self._gripper_xy()
        half = self._half_opening()
        lag = np.asarray(ramp_lag_m(v, ramp), float) if ramp > 0 else np.zeros(2)
        for dt in np.linspace(ramp, ramp + open_s, 6):
            gripper = p + v * dt - lag
            if not np.all(np.abs(gripper - self.estimator.predict(t, t + dt)) <= half):
                return False
        return True

    def _release(self, t: float, v: np.ndarray) -> bool:
        """Open the gripper over the bin: following the bin at v (moving), or standing still."""
        st, cfg = self.stream, self.job.config
        if self.s.release == "moving":
            track, ramp = self._tracking(st.q_end, v, cfg.open_s)
            why = "no tracking motion at the bin's velocity within the limits" if track is None \
                else self._track_reason(t, track, ramp)
            if why is not None:
                self.events.append(ReplanEvent(t, self.can_id, "release", None, 0.0, None, "track failed", why,
                                               "track"))
                return False
            st.append_motion("track", self.can_id, Window(track, 0.0, ramp), width_m=0.0, carrying=True)
            st.append_motion("open", self.can_id, Window(track, ramp, cfg.open_s), width_m=0.0, carrying=False)
            last = st.segments[-1]  # the fingers open while the arm follows the bin
            st.segments[-1] = dataclasses.replace(last, width_from_m=0.0, width_to_m=self.open_w)
            # its offset from the bin is measured when the opening starts, after the ramp
            self.cans.append(CanEpisode(self.can_id, True, t + ramp - self.grasp_t, None,
                                        release_speed_m_s=float(np.linalg.norm(v))))
            self.pending_offset = (len(self.cans) - 1, t + ramp)
            self.removed.append(self.can_id)
            if self.s.track_feedback:  # the fingers let the can go once open wider than it
                free = min(1.0, 2 * self.spec.can.radius_m / self.open_w)
                self.releasing = (t + ramp, t + ramp + cfg.open_s, t + ramp + free * cfg.open_s)
            self._return_on_the_move(t, track.sample(track.duration_s))
            return True
        st.append_hold("open", self.can_id, cfg.open_s, width_from_m=0.0, width_to_m=self.open_w, carrying=False)
        self.cans.append(CanEpisode(self.can_id, True, t - self.grasp_t,
                                    float(np.linalg.norm(self._gripper_xy() - self.path.at(t)[0])),
                                    release_speed_m_s=0.0))
        self.removed.append(self.can_id)
        self.mode = "released"
        self.released_t = st.duration_s
        return True

    def _track_reason(self, t: float, track, t_open_s: float) -> str | None:
        """Why the tracking motion `track` may not run (None: it may): validated like any motion,
        in the world of the moment without the person, the can held until the opening starts
        (t_open_s into the motion) and the fingers open after it. Differential IK knows no
        obstacle and no self-collision (a release near the robot's base folds the elbow)."""
        from suite.execution.replan import loop_motion_reason

        bin_xy = self.estimator.predict(t, t)
        n = max(2, int(np.ceil(track.duration_s / 0.02)) + 1)
        ts = np.linspace(0.0, track.duration_s, n)
        q = track.sample(ts)[0]
        held, opening = q[ts <= t_open_s + 1e-9], q[ts >= t_open_s - 1e-9]
        for template, part in ((self.transit_template, held), (self.return_template, opening)):
            if len(part) >= 2:
                why = loop_motion_reason(template, self.s, bin_xy, part, leading_collisions=False)
                if why is not None:
                    return why
        return None

    def _track_update(self, t: float) -> None:
        """Re-aim the release at a new estimate (module docstring); past the moment the fingers
        let the can go, nothing more to do."""
        from suite.execution.track import tracking_motion

        t_open, t_end, t_free = self.releasing
        t_s = t + TRACK_UPDATE_S
        if t_s >= t_free:
            self.releasing = None
            return
        st = self.stream
        q_s, qd_s, _ = st.state(t_s)
        gripper = self.robot.gripper_pose(q_s[None, :])[0][:2, 3]
        fix = (self.estimator.predict(t, t_s) - gripper) / max(t_free - t_s, 0.1)
        norm = float(np.linalg.norm(fix))
        if norm > TRACK_CORRECTION_M_S:
            fix *= TRACK_CORRECTION_M_S / norm
        v = self.estimator.velocity(t) + fix
        a_lim = self.robot.acceleration_limits_rad_s2
        track = None
        for k in (1.0, 2.0):
            ramp = min(k * self.s.track_ramp_s, t_free - t_s)
            cand = tracking_motion(self.spec.robot, q_s, v, ramp_s=ramp, duration_s=t_end - t_s, qd0=qd_s)
            if cand is not None and np.all(np.abs(cand.sample(np.linspace(0, cand.duration_s, 100))[2]) <= a_lim):
                track = cand
                break
        why = "no re-aimed tracking motion within the limits" if track is None \
            else self._track_reason(t, track, max(t_open - t_s, 0.0))
        if why is not None:
            self.events.append(ReplanEvent(t, self.can_id, "track", None, 0.0, None, "failed", why, "track"))
            return
        seg = st.at(t_s)
        width, opening = seg.width(t_s)[0], seg.phase == "open"
        st.cut(t_s, can_id=self.can_id, width_m=width, carrying=not opening)
        if opening:  # the cut piece opens the fingers up to where they are at t_s
            st.segments[-1] = dataclasses.replace(st.segments[-1], width_to_m=width)
            st.append_motion("open", self.can_id, Window(track, 0.0, t_end - t_s), width_m=0.0, carrying=False)
        else:
            st.append_motion("track", self.can_id, Window(track, 0.0, t_open - t_s), width_m=0.0, carrying=True)
            st.append_motion("open", self.can_id, Window(track, t_open - t_s, t_end - t_open), width_m=0.0,
                             carrying=False)
        last = st.segments[-1]
        st.segments[-1] = dataclasses.replace(last, width_from_m=width if opening else 0.0, width_to_m=self.open_w)
        self.events.append(ReplanEvent(t, self.can_id, "track", None, 0.0, None, "spliced", "", "",
                                       splice_speed_rad_s=float(np.max(np.abs(qd_s)))))
        self._return_on_the_move(t, track.sample(track.duration_s))

    def _tracking(self, q0: np.ndarray, v: np.ndarray, open_s: float):
        """The release's tracking motion at the bin's velocity v, within the joint acceleration
        limits (differential IK bounds positions and velocities only): the ramp as set, else two
        and three times as long. (None, 0) if none is."""
        from suite.execution.track import tracking_motion

        a_lim = self.robot.acceleration_limits_rad_s2
        for k in (1.0, 2.0, 3.0):
            ramp = k * self.s.track_ramp_s
            track = tracking_motion(self.spec.robot, q0, v, ramp_s=ramp, duration_s=ramp + open_s)
            if track is not None:
                a = track.sample(np.linspace(0.0, track.duration_s, 200))[2]
                if np.all(np.abs(a) <= a_lim):
                    return track, ramp
        return None, 0.0

    def _measure_release(self, t: float) -> None:
        """The gripper's true distance (xy) from the bin centre when the opening starts."""
        i, at = self.pending_offset
        if t + 1e-9 >= at:
            offset = float(np.linalg.norm(self._gripper_xy() - self.path.at(t)[0]))
            self.cans[i] = dataclasses.replace(self.cans[i], release_offset_m=offset)
            self.pending_offset = None

    def _return_on_the_move(self, t: float, end) -> None:
        """Plan the return now, from the state in which the opening ends (the arm still moving with
        the bin), and join it there: the arm moves away instead of stopping where the person walks
        on into it. A plan not ready by then, or none, leaves a stop after the opening and the
        return planned from rest."""
        st = self.stream
        t_end = st.duration_s
        q_e, v_e, a_e = (np.asarray(x, float) for x in end)
        res = self._plan(template=self.return_template, t=t, bin_xy=self.estimator.predict(t, t_end), q_s=q_e,
                         v_s=v_e, a_s=a_e, deadline_bound=False, start_s=t_end, q_goal=self._return_goal(),
                         via=[self.X_middle], held=False)
        if res.ok and res.latency_s <= t_end - t:
            self._event(t, "return", res, "spliced", speed=float(np.max(np.abs(v_e))), expected=t_end - t)
            if res.blend.duration_s > 0:
                st.append_motion("return", self.can_id, res.blend, width_m=self.open_w, carrying=False)
            st.append_motion("return", self.can_id, res.trajectory, width_m=self.open_w, carrying=False)
            self.mode = "returning"
        else:
            self._event(t, "return", res, "missed" if res.ok else "failed", expected=t_end - t)
            self._halt(t_end, "stop")
            self.mode = "released"
        self.released_t = st.duration_s

    def _return_goal(self) -> np.ndarray:
        """Where the return goes: the next can's approach start, or home after the last can."""
        return np.asarray(self.queue[0][1][0].q[0], float) if self.queue else self.q_home

    def _give_up(self, t: float, why: str) -> None:
        """Give the can up: bring the arm to rest, then carry the can back to its place."""
        self.cans.append(CanEpisode(self.can_id, False, None, None, gave_up=why))
        self._halt(t, "stop")
        self.mode = "put_down"

    def _put_down(self, t: float) -> None:
        """Carry the given-up can back over its place, lower it (the lift reversed), open, and
        retreat (the descend and the approach reversed)."""
        st, c = self.stream, self.can_id
        q = st.q_end
        q_lift = np.asarray(self.lift.q[-1], float)
        if np.max(np.abs(q - q_lift)) > 1e-3:
            z = np.zeros(7)
            res = self._plan(template=self.transit_template.with_(X_WG_goal=self.X_plate), t=t,
                             bin_xy=self.estimator.predict(t, t), q_s=q, v_s=z, a_s=z, deadline_bound=False,
                             start_s=t, q_goal=q_lift, via=[self.X_middle])
            self._event(t, "put_down", res, "planned" if res.ok else "failed")
            if not res.ok:
                self.put_down_tries += 1
                if self.put_down_tries >= PUT_DOWN_TRIES:
                    self._stop(f"can {c}: given up, and no plan to put it down ({res.reason}); stopped safely "
                               "with the can in the gripper", carrying=True)
                    return
                st.append_hold("wait", c, max(res.latency_s, self.period), width_from_m=0.0, carrying=True)
                return
            st.append_hold("wait", c, res.latency_s, width_from_m=0.0, carrying=True)
            st.append_motion("carry_back", c, res.trajectory, width_m=0.0, carrying=True)
        st.append_motion("put_down", c, Reversed(self.lift), width_m=0.0, carrying=True)
        st.append_hold("open", c, self.job.config.open_s, width_from_m=0.0, width_to_m=self.open_w, carrying=False)
        st.append_motion("retreat", c, Reversed(self.descend), width_m=self.open_w, carrying=False)
        st.append_motion("retreat", c, Reversed(self.approach), width_m=self.open_w, carrying=False)
        last = self.cans[-1]
        self.cans[-1] = dataclasses.replace(last, put_down=True)
        self.mode = "put_down_done"
        self.released_t = st.duration_s

    def _plan_return(self, t: float) -> None:
        q = self.stream.q_end
        z = np.zeros(7)
        goal = self._return_goal()
        back = self.mode == "put_down_done"
        if np.max(np.abs(q - goal)) < 1e-6:  # back where the next approach starts (a put-down's retreat)
            self.mode = "returning"
            return
        template = self.back_template if back else self.return_template
        res = self._plan(template=template, t=t, bin_xy=self.estimator.predict(t, t), q_s=q, v_s=z, a_s=z,
                         deadline_bound=False, start_s=t, q_goal=goal, via=[] if back else [self.X_middle],
                         held=False)
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

    # --- the person --------------------------------------------------------------------------
