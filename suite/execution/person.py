"""The person beside a moving bin, over time: the robot's distance to them, a plan's swept check,
and speed and separation monitoring.

The person is the scenario's standing cylinder (`scenes.moving_bin`: radius `person_radius_m`,
from the floor plane z = 0 up to `person_height_m`), its axis wherever the caller says at each
instant. The robot is the python-fcl world's own geometry (`scenes.collision.world.CollisionWorld`'s
parts: the arm's primitives, the gripper body, the fingers at an opening, a held can grown by the
grasp's `held_margin_m`), placed by `RobotModel.link_poses`; distances are FCL's signed distances.

A plan validated against the person where they are predicted on its arrival may still meet them
on the way; `swept_person_check` samples the plan's timing against the person's predicted path.
The speed and separation monitoring follows ISO/TS 15066:2016 clause 5.5.4: the robot keeps at
least the protective separation distance S_p from the person, or stops.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Callable

import fcl
import numpy as np

from scenes.collision.shapes import G_INDEX, aabb_half_extents, bounding_radius
from scenes.collision.world import robot_parts
from scenes.robot_model import load_robot
from suite.execution.splice import stopping_blend

_DREQ = fcl.DistanceRequest(enable_signed_distance=True)


@functools.lru_cache(maxsize=64)
def _robot_parts(robot_name: str, opening_m: float, held: tuple | None):
    """The robot's parts as in `CollisionWorld`: FK body indices (P,), poses in their bodies
    (P, 4, 4), bounding radii about their origins (P,) and FCL objects (moved per query: one
    caller per thread). held: (X_GC as a 16-tuple, can radius, can height) grown already."""
    held_can = None if held is None else (np.array(held[0], float).reshape(4, 4), held[1:])
    parts = robot_parts(load_robot(robot_name), opening_m, held_can)
    body = np.array([p.body for p in parts])
    X_BS = np.stack([p.X_BS for p in parts])
    radius = np.array([bounding_radius(p.kind, p.dims) for p in parts])
    return body, X_BS, radius, [p.obj for p in parts]


def _cylinder_signed(p: np.ndarray, axis_xy: np.ndarray, r: float, h: float) -> np.ndarray:
    """Signed distance (...,) of points p (..., 3) to the upright cylinder of radius r on axis_xy
    (..., 2) from z = 0 to h (negative inside)."""
    radial = np.linalg.norm(p[..., :2] - axis_xy, axis=-1) - r
    vertical = np.maximum(p[..., 2] - h, -p[..., 2])
    outside = np.hypot(np.maximum(radial, 0.0), np.maximum(vertical, 0.0))
    return np.where((radial > 0) | (vertical > 0), outside, np.maximum(radial, vertical))


def robot_person_distance(robot_name: str, q: np.ndarray, person_xy: np.ndarray, scenario, spec, *,
                          held_can=None, opening_m: float) -> np.ndarray:
    """The signed distance (m) from the robot at each q[i] (N, 7) to the person with their axis at
    person_xy[i] (N, 2): (N,), negative in penetration (FCL's depth), 0 touching.

    The robot is the arm, the gripper, its fingers at opening_m and the held can if any (a
    `scenes.scene.HeldCan`, grown by `spec.grasp.held_margin_m` as the worlds grow it). Exact FCL
    distances are taken only for parts whose bounding-sphere lower bound could beat the nearest
    part found so far (that skips no answer); the parts are built once per (robot, opening, can).
    """
    q = np.atleast_2d(np.asarray(q, float))
    axis = np.atleast_2d(np.asarray(person_xy, float))
    held = None
    if held_can is not None:
        m = spec.grasp.held_margin_m
        held = (tuple(np.asarray(held_can.X_GC, float).ravel()), spec.can.radius_m + m, spec.can.height_m + 2 * m)
    body, X_BS, radius, objs = _robot_parts(robot_name, float(opening_m), held)
    X_WS = load_robot(robot_name).link_poses(q)[:, body] @ X_BS  # (N, P, 4, 4)
    r, h = float(scenario.person_radius_m), float(scenario.person_height_m)
    lb = _cylinder_signed(X_WS[..., :3, 3], axis[:, None, :], r, h) - radius  # (N, P)
    person = fcl.CollisionObject(fcl.Cylinder(r, h), fcl.Transform())
    out = np.empty(len(q))
    for i in range(len(q)):
        person.setTranslation(np.array([axis[i, 0], axis[i, 1], h / 2]))
        best = math.inf
        for k in np.argsort(lb[i]):
            if lb[i, k] >= best and lb[i, k] > 0:  # a bound <= 0 may hide any depth: always measured
                break
            obj = objs[k]
            obj.setRotation(np.ascontiguousarray(X_WS[i, k, :3, :3]))
            obj.setTranslation(np.ascontiguousarray(X_WS[i, k, :3, 3]))
            best = min(best, float(fcl.distance(obj, person, _DREQ, fcl.DistanceResult())))
        out[i] = best
    return out


def swept_person_check(robot_name: str, trajectory, t0_s: float, person_xy_at: Callable[[float], np.ndarray],
                       scenario, spec, *, held_can=None, opening_m: float, margin_m: float,
                       dt_s: float = 0.05) -> tuple[str | None, float]:
    """A timed plan against the person's path: (reason or None, the least distance in m).

    The trajectory (`.duration_s`, `.sample(t)` -> (q, v, a); a `TimedTrajectory` or a
    `BlendTrajectory`) starts at absolute time t0_s; it is sampled every dt_s from 0 to its end
    (the end included), the person's axis at person_xy_at(t0_s + t). The reason names the worst
    sample when the least distance is under margin_m.
    """
    T = float(trajectory.duration_s)
    t = np.arange(0.0, T, dt_s) if T > 0 else np.zeros(0)
    t = np.append(t, max(T, 0.0))
    q = np.atleast_2d(trajectory.sample(t)[0])
    xy = np.array([person_xy_at(t0_s + float(ti)) for ti in t], float)
    d = robot_person_distance(robot_name, q, xy, scenario, spec, held_can=held_can, opening_m=opening_m)
    k = int(np.argmin(d))
    if d[k] >= margin_m:
        return None, float(d[k])
    what = (f"the robot runs {-d[k]:.3f} m into the person" if d[k] < 0
            else f"the person comes within {d[k]:.3f} m of the robot")
    return f"{what} at t+{t[k]:.2f} s (margin {margin_m:g} m)", float(d[k])


# --- speed and separation monitoring (ISO/TS 15066:2016, 5.5.4) -------------------------------------


@dataclasses.dataclass(frozen=True)
class SsmSettings:
    """Speed and separation monitoring's settings.

    Attributes:
        reaction_s: T_r, from the person's move to the robot's stop command: the bin estimate's
            latency (0.1 s) plus one estimate period (0.1 s at 10 Hz).
        intrusion_m: C, the reach of a body part past the sensed boundary: 0, the person is a
            solid cylinder whose radius already holds the hands.
        uncertainty_m: Z_d + Z_r, the person's and the robot's position uncertainty: 3 mm estimate
            noise rounded up to 1 cm for a still person; the loop adds how far the person walks
            in one estimate latency and period (`for_scenario`).
        human_speed_m_s: v_h; None: the speed the caller gives (the loop: the scenario's
            cruise speed, the person's known top speed, not the lagging estimate).
        resume_hysteresis_m: after a hold, the robot goes again only at S_p plus this, so that
            it does not chatter at the boundary.
    """

    reaction_s: float = 0.2
    intrusion_m: float = 0.0
    uncertainty_m: float = 0.01
    human_speed_m_s: float | None = None
    resume_hysteresis_m: float = 0.05

    @staticmethod
    def for_scenario(scenario) -> "SsmSettings":
        """The loop's settings for a moving-bin scenario: v_h its cruise speed, the reaction its
        estimate latency plus one period, and the uncertainty 1 cm plus how far the person walks
        in that time (at 0.4 m/s: 9 cm; the estimate of where the person is now errs by 3.6 cm
        median, 7.9 cm p95 at 0.4 m/s, the review's simulation)."""
        reaction = scenario.estimate_latency_s + 1.0 / scenario.estimate_rate_hz
        return SsmSettings(reaction_s=reaction, uncertainty_m=0.01 + scenario.speed_m_s * reaction,
                           human_speed_m_s=scenario.speed_m_s)


def protective_distance(*, human_speed_m_s: float, reaction_s: float, stop_time_s: float, robot_speed_m_s: float,
                        stop_distance_m: float, intrusion_m: float, uncertainty_m: float) -> float:
    """ISO/TS 15066 5.5.4's protective separation distance (m), speeds held constant:
    S_p = S_h + S_r + S_s + C + Z_d + Z_r with S_h = v_h (T_r + T_s) (the person's approach while
    the robot reacts and stops), S_r = v_r T_r (the robot's motion while it reacts), S_s the
    robot's stopping distance, C the intrusion distance and Z_d + Z_r (uncertainty_m) the
    position uncertainties. Infinite when the robot cannot stop (T_s or S_s infinite)."""
    return (human_speed_m_s * (reaction_s + stop_time_s) + robot_speed_m_s * reaction_s + stop_distance_m
            + intrusion_m + uncertainty_m)


def _tracked_points(robot_name: str, Q: np.ndarray) -> np.ndarray:
    """(K, P, 3): the arm's tracked points at configurations Q (K, 7): every link origin (the
    elbow's among them), the flange, the gripper frame and the finger tips."""
    robot = load_robot(robot_name)
    X = robot.link_poses(Q)  # (K, 9, 4, 4)
    tip = X[:, G_INDEX] @ np.array([0.0, _finger_reach_m(robot_name), 0.0, 1.0])
    return np.concatenate([X[:, 1:, :3, 3], (X[:, 7] @ robot.X_7F)[:, None, :3, 3], tip[:, None, :3]], axis=1)


def stopping_motion(robot_name: str, q, v, a) -> tuple[float, float]:
    """(T_s in s, S_s in m): the duration of the suite's stopping blend from (q, v, a)
    (`splice.stopping_blend`, within the joint limits) and the farthest any tracked point of the
    arm (`_tracked_points`) travels during it from where it starts. (inf, inf) when no blend
    stops it."""
    robot = load_robot(robot_name)
    blend = stopping_blend(q, v, a, v_lim=robot.velocity_limits_rad_s, a_lim=robot.acceleration_limits_rad_s2,
                           q_lo=robot.lower_rad, q_hi=robot.upper_rad)
    if blend is None:
        return math.inf, math.inf
    points = _tracked_points(robot_name, blend.q)
    return float(blend.duration_s), float(np.max(np.linalg.norm(points - points[:1], axis=-1)))


def robot_speed(robot_name: str, q, v) -> float:
    """v_r: the fastest tracked point of the arm (`_tracked_points`: link origins, flange, gripper,
    finger tips), m/s, at joint positions q and velocities v (finite difference, h = 1e-4 s)."""
    h = 1e-4
    q = np.asarray(q, float)
    p = _tracked_points(robot_name, np.stack([q, q + np.asarray(v, float) * h]))
    return float(np.max(np.linalg.norm(p[1] - p[0], axis=-1)) / h)


@functools.lru_cache(maxsize=None)
def _finger_reach_m(robot_name: str) -> float:
    """How far the finger shapes reach along the gripper frame's +y (towards the tips), m."""
    robot = load_robot(robot_name)
    X_GF = robot.finger_offsets(0.0)
    Xs = [(X_GF[s.body] @ s.X_BS, s) for s in robot.shapes if s.body in X_GF]
    return max((float(X[1, 3] + aabb_half_extents(s.kind, s.dims, X[:3, :3])[1]) for X, s in Xs), default=0.0)


def gripper_speed(robot_name: str, q, v) -> float:
    """The gripper frame origin's Cartesian speed (m/s) at joint positions q and velocities v:
    |FK(q + v h) - FK(q)| / h with h = 1e-4 s."""
    h = 1e-4
    q = np.asarray(q, float)
    p = load_robot(robot_name).gripper_pose(np.stack([q, q + np.asarray(v, float) * h]))[:, :3, 3]
    return float(np.linalg.norm(p[1] - p[0]) / h)


def ssm_verdict(settings: SsmSettings, *, separation_m: float, human_speed_m_s: float, robot_speed_m_s: float,
                stop_time_s: float, stop_distance_m: float, holding: bool = False) -> tuple[str, float]:
    """("hold" or "go", S_p in m): hold while the separation (the robot's distance to the person,
    `robot_person_distance`) is under the protective distance S_p (`protective_distance`, with
    the settings' T_r, C and uncertainty; v_h the settings' speed if set, else human_speed_m_s).
    A robot already holding goes again only at S_p + resume_hysteresis_m."""
    v_h = human_speed_m_s if settings.human_speed_m_s is None else settings.human_speed_m_s
    s_p = protective_distance(human_speed_m_s=v_h, reaction_s=settings.reaction_s, stop_time_s=stop_time_s,
                              robot_speed_m_s=robot_speed_m_s, stop_distance_m=stop_distance_m,
                              intrusion_m=settings.intrusion_m, uncertainty_m=settings.uncertainty_m)
    threshold = s_p + (settings.resume_hysteresis_m if holding else 0.0)
    return ("hold" if separation_m < threshold else "go"), s_p
