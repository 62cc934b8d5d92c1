"""The person beside the moving bin, as the loop watches them: swept checks, protective stops, near misses.

A mixin of `suite.execution.moving_bin_episode.Episode` over the geometry and formulas of
`suite.execution.person`:

- `_person_check`: every new plan is checked against the person's positions predicted along its
  timing (a swept check, `person_margin_m`), not only where they stand on arrival;
- `_protective_stop`, `_hold_for_person`: speed-and-separation monitoring in the spirit of
  ISO/TS 15066 during a transit or a return (not a put-down's carry back, which the monitor
  would cut mid-sequence: it leads away from the person): at every estimate, the robot's
  distance to the person (by the estimate) against the protective separation distance from the
  person's top speed (the scenario's cruise speed), the loop's reaction time (estimate latency
  plus period), the fastest point of the arm and its stopping time and distance (from the
  stopping blend of the commanded state, not measured in the physics), with the position
  uncertainty of `SsmSettings.for_scenario`. Nearer: a protective stop;
  the arm replans from rest once the person is clear by `resume_hysteresis_m`;
- `_escape`: when the person has walked to within `person_margin_m` of the arm standing still
  (waiting for a plan, after a protective stop, or holding over the bin), or the bin has walked
  into its place in the world of the moment, the gripper backs away
  from them, horizontally at `ESCAPE_SPEED_M_S` and up at `ESCAPE_RISE_M_S`, by differential IK
  (`suite.execution.track.tracking_motion`), then stops; the motion is validated in the world of
  the moment without the person (`suite.execution.replan.loop_motion_reason`: it starts inside a
  margin and leads out, so it must be free from its first free sample on), straight away first,
  then 45 degrees to either side. The loop then
  plans again from there. Not checked against the person's predicted path: it moves away from
  where they are, not from where they will be;
- `_watch_person`: the true distance (measured joints, the person's true place) every 10 ms:
  its minimum and the near misses (passes under `near_miss_m`).
"""

from __future__ import annotations

import numpy as np

#: The escape: the gripper's horizontal speed away from the person and its rise (m/s), the ramp
#: to that speed and the whole motion before the stop (s): about 9 cm away and 6 cm up.
ESCAPE_SPEED_M_S = 0.25
ESCAPE_RISE_M_S = 0.15
ESCAPE_RAMP_S = 0.15
ESCAPE_S = 0.45
#: Escapes a can may make; past them the loop waits as before (its time limits still hold).
ESCAPE_TRIES = 8


class PersonGuard:
    """The loop's watch over the person (module docstring); mixed into the Episode."""

    def _person_check(self, t: float, held: bool, t_start: float):
        """The swept check of a new motion starting at t_start against the person's positions as
        predicted at t; None with no margin to keep."""
        from suite.execution.person import swept_person_check

        if self.s.person_margin_m <= 0:
            return None
        est = self.estimator
        held_can = self.transit_template.held if held else None
        opening = 2 * self.spec.can.radius_m if held else self.open_w

        def check(pieces) -> str | None:
            t0 = t_start
            for piece in pieces:
                if piece.duration_s > 0:
                    reason, _ = swept_person_check(
                        self.spec.robot, piece, t0, lambda ta: est.predict(t, ta) + self.person_offset, self.s,
                        self.spec, held_can=held_can, opening_m=opening, margin_m=self.s.person_margin_m)
                    if reason is not None:
                        return reason
                t0 += piece.duration_s
            return None

        return check

    def _separation(self, t: float, q: np.ndarray) -> float:
        from suite.execution.person import robot_person_distance

        carrying = self.carrying(t)
        person = self.estimator.predict(t, t) + self.person_offset
        return float(robot_person_distance(
            self.spec.robot, q[None, :], person[None, :], self.s, self.spec,
            held_can=self.transit_template.held if carrying else None,
            opening_m=2 * self.spec.can.radius_m if carrying else self.open_w)[0])

    def _protective_stop(self, t: float) -> bool:
        """Speed and separation monitoring during a transit or a return: stop the arm when the
        person (by the estimate) is nearer than the protective separation distance."""
        from suite.execution.person import robot_speed, ssm_verdict, stopping_motion

        if self.mode not in ("transit", "returning") or t >= self.stream.duration_s or t < self.escaping_until:
            return False  # at rest, or escaping (away from the person)
        q, v, a = self.stream.state(t)
        if np.max(np.abs(v)) < 1e-6:
            return False
        stop_t, stop_d = stopping_motion(self.spec.robot, q, v, a)
        verdict, _ = ssm_verdict(self.ssm, separation_m=self._separation(t, q),
                                 human_speed_m_s=self.s.speed_m_s,
                                 robot_speed_m_s=robot_speed(self.spec.robot, q, v), stop_time_s=stop_t,
                                 stop_distance_m=stop_d)
        if verdict != "hold":
            return False
        self.ssm_holds += 1
        self.resume_mode = self.mode
        self._halt(t, "stop")
        self.mode = "ssm_hold"
        return True

    def _hold_for_person(self, t: float) -> None:
        """At rest after a protective stop: go on when the person is clear, else hold a period."""
        from suite.execution.person import ssm_verdict

        if self._over_time(t):
            return
        q = self.stream.q_end
        verdict, _ = ssm_verdict(self.ssm, separation_m=self._separation(t, q),
                                 human_speed_m_s=self.s.speed_m_s,
                                 robot_speed_m_s=0.0, stop_time_s=0.0, stop_distance_m=0.0, holding=True)
        if verdict == "go":
            self.mode = self.resume_mode
            if self.mode == "transit":
                self.busy_until = 0.0
                self._arrived(t, "resume")  # at rest short of the bin: release if over it, else replan
            else:
                self.mode = "released"
                self._plan_return(t)
            return
        width = self.stream.at(t).width(t)[0]
        self.stream.append_hold("wait", self.can_id, self.period, width_from_m=width, carrying=self.carrying(t))

    def _crowded(self, t: float) -> bool:
        """Has the person (by the estimate) come within the person margin of the arm at rest, or
        the arm's place collided in the world of the moment (the bin walked into it)?"""
        from suite.execution.replan import start_free

        q = self.stream.q_end
        if self.s.person_margin_m > 0 and self._separation(t, q) < self.s.person_margin_m:
            return True
        template = self.transit_template if self.carrying(t) else self.return_template
        return not start_free(template, self.s, self.estimator.predict(t, t), q)

    def _escape(self, t: float) -> bool:
        """Back the gripper away from the person who walked into the standing arm (module
        docstring), from rest at the stream's end; False if no escape is valid (or none is left)."""
        from suite.execution.replan import loop_motion_reason
        from suite.execution.splice import stopping_blend
        from suite.execution.track import tracking_motion

        if self.escapes >= ESCAPE_TRIES:
            return False
        st = self.stream
        q = st.q_end
        person = self.estimator.predict(t, t) + self.person_offset
        away = self.robot.gripper_pose(q[None, :])[0][:2, 3] - person
        away = away / max(float(np.linalg.norm(away)), 1e-9)
        held = self.carrying(t)
        template = self.transit_template if held else self.return_template
        r = self.robot
        for angle in (0.0, np.pi / 4, -np.pi / 4):
            c, s_ = np.cos(angle), np.sin(angle)
            d = np.array([c * away[0] - s_ * away[1], s_ * away[0] + c * away[1]])
            track = tracking_motion(self.spec.robot, q, np.array([*(ESCAPE_SPEED_M_S * d), ESCAPE_RISE_M_S]),
                                    ramp_s=ESCAPE_RAMP_S, duration_s=ESCAPE_S)
            if track is None:
                continue
            qe, ve, _ = track.sample(track.duration_s)
            stop = stopping_blend(qe, ve, np.zeros(7), v_lim=r.velocity_limits_rad_s, a_lim=r.acceleration_limits_rad_s2,
                                  q_lo=r.lower_rad, q_hi=r.upper_rad)
            if stop is None:
                continue
            dense = np.concatenate([track.sample(np.linspace(0.0, track.duration_s, 24))[0],
                                    stop.sample(np.linspace(0.0, stop.duration_s, 12))[0]])
            if loop_motion_reason(template, self.s, self.estimator.predict(t, t), dense) is not None:
                continue
            self.escapes += 1
            width = st.at(t).width(t)[0]
            st.append_motion("escape", self.can_id, track, width_m=width, carrying=held)
            st.append_motion("escape", self.can_id, stop, width_m=width, carrying=held)
            self.escaping_until = st.duration_s
            return True
        return False

    def _watch_person(self, t: float) -> None:
        """The true distance from the robot (measured joints) to the person: minimum and near misses."""
        from suite.execution.person import robot_person_distance

        sim = self.sim
        q = sim.plant.GetPositions(sim.pc, sim.iiwa)
        person = self.path.at(t)[0] + self.person_offset
        carrying = self.carrying(t)
        d = float(robot_person_distance(self.spec.robot, q[None, :], person[None, :], self.s, self.spec,
                                        held_can=self.transit_template.held if carrying else None,
                                        opening_m=2 * self.spec.can.radius_m if carrying else self.open_w)[0])
        self.person_min = min(self.person_min, d)
        near = d < self.s.near_miss_m
        if near and not self._near:
            self.near_misses += 1
        self._near = near

    # --- the loop ------------------------------------------------------------------------------
