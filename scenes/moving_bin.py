"""A moving bin held by a person: the scenario, the bin's seeded path and the geometry it moves.

The seed paper's intended scenario ("a moving person holding trash bag"): the bin moves in the
floor plane while the arm works, held by a person who stands beside it on the side away from the
robot base (a standing cylinder, an obstacle too). Nothing here enters a `SceneSpec`'s hashed
fields: a scenario is a value of its own, and the worlds it makes (`spec_with_bin_at`) are built
online for replanning, never stored, so every existing scene key and dataset stays as it is.

The bin path (`BinPath`): from the spec's bin centre, the bin walks to target points drawn
uniformly in `region_m` (a box its centre stays in), one after the other along straight lines,
each with a trapezoidal speed profile (cruise `speed_m_s`, accelerate and brake at
`accel_m_s2`), pausing `dwell_s` at every target. It is sampled once on a 10 ms grid for cheap
lookup. The bin never turns.

Whether a station can run a scenario (its region, obstacles and the arm's reach) is
`scenes.moving_bin_check`'s: it needs the Drake scene, which builds on this geometry.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Literal

import numpy as np

from scenes.schema import FieldError, NonNeg, NonNegInt, Pos, PosInt, Vec2, load

if TYPE_CHECKING:
    from scenes.spec import Obstacle, SceneSpec

#: The families a moving bin runs on: the paper's station and its wall variant.
MOVING_BIN_FAMILIES = ("open", "wall")
#: The default region around the spec's bin centre: its lower and upper corners' offsets (m). It
#: reaches further toward the robot base, where the arm still reaches the drop pose holding a can
#: (on open and wall: x 0.20..0.44, y 0.40..0.60). At 0.46, 0.62 (the region of the first moving
#: bin runs) the drop pose with the first can of the scene in the gripper has no IK at the goals' 2 mm
#: clearance (8 random restarts, yaw free; found at 1 cm inward on open and wall, seeds 5 and 77).
DEFAULT_REGION_OFFSETS_M = ((-0.16, -0.12), (0.08, 0.08))
#: The bin path's sample spacing (s) and length (s); beyond it the bin stands at its last place.
PATH_DT_S = 0.01
PATH_HORIZON_S = 900.0


@dataclasses.dataclass(frozen=True)
class MovingBinScenario:
    """How the bin moves, how the robot sees it, and how the replanning loop reacts.

    Attributes:
        speed_m_s: the bin's cruise speed (0: it stands still, the static bin).
        accel_m_s2: its acceleration and braking limit (a person walking with a load: 1-2 m/s^2;
            the bin stops at each target, so at high speeds it cruises only part of the time:
            the records give its mean speed too).
        dwell_s: how long the person pauses at each target point before walking on.
        region_m: the box its centre stays in, ((x_lo, y_lo), (x_hi, y_hi)) in metres; None for
            the spec's bin centre offset by DEFAULT_REGION_OFFSETS_M. It must hold the spec's bin
            centre.
        seed: the scenario's seed; an episode's bin path (target points) and estimate noise draw
            from `suite.execution.moving_bin_records.episode_seed` of it, the run seed, the scene
            and the path's index (every episode its own path, the same for every planner).
        person_radius_m, person_height_m: the standing cylinder holding the bin.
        person_gap_m: its gap to the bin's outer wall, on the side away from the robot base.
        estimate_latency_s: delay of the bin estimate (sensing + processing).
        estimate_rate_hz: estimates per second (held between updates: zero-order hold).
        estimate_noise_m: standard deviation of the Gaussian noise on each estimate's x and y.
        velocity_window: estimates a constant-velocity prediction fits its line to (least
            squares; the last one alone when there is one).
        drift_tolerance_m: a predicted drop position this far from the planned one triggers a
            replan while the arrival is `drift_horizon_s` or more away; closer to it the
            tolerance shrinks linearly with the time to go, down to `drift_tolerance_min_m` on
            arrival (far out, a prediction is coarse and a correction cheap; near the release it
            must be finer, though well inside the opening's capture region: ±11 cm for the
            spec's bin and can, so that noise alone does not trigger a replan at every estimate).
        commit_s: no drift replan whose splice falls in the transit's last `commit_s`: the arm
            commits to its arrival (the release tracks the bin from there); without it a loop
            near arrival can replace its plan at every estimate and never arrive.
        replan_deadline_s: in "measured" latency mode, a replan's wall-time deadline: its plan
            is spliced in this long after the replan starts, from the state the current plan
            commands then; a plan ready later is dropped (the current plan goes on).
        latency_mode: "measured": every plan's latency is its wall time on this machine (the
            planner's budget is what is left of the deadline); "modelled": every plan's latency
            is the planner's declared constant (`modelled_latency_s`, else the loop's
            calibrated table `suite.execution.moving_bin_records.MODELLED_LATENCY_S`), the splice is that
            long after the replan starts, and planners finish by their own criteria and seeds
            (their budget is the run's time limit, a cap), so a run gives the same records on
            any machine.
        modelled_latency_s: per planner name, its declared latency (s) in "modelled" mode.
        max_wait_s: how long the arm may hold over (or near) the bin waiting for a release or a
            plan before it gives the can up.
        can_time_limit_s: a can's time from its grasp to its release, in every phase (transit,
            chasing, waiting); past it the can is given up: put back down where it was picked,
            and the episode goes on with the next can.
        release: "moving": on arrival the gripper accelerates to the bin's estimated velocity
            over `track_ramp_s` and follows it while the fingers open (the can falls with the
            bin's velocity: it lands where the bin will be); the transit aims ahead of the
            predicted bin by the ramp's lag. "rest": the arm releases standing still, when the
            bin is under it now and at the end of the opening.
        track_ramp_s: the release's acceleration to the bin's velocity.
        track_feedback: during the ramp and the opening, until the fingers let the can go, every
            new estimate re-aims the gripper (the bin's new velocity, corrected toward its
            predicted centre) and the return is planned again; False holds the velocity estimated
            on arrival (open loop).
        aim: "predicted": the transit aims at where the bin is predicted on arrival and is
            replanned as the prediction drifts; "centre": a control without replanning: the arm
            carries the can over the centre of the bin's region and waits there for the bin to come
            under it (the opening covers the region's centre most of the time when the region is
            small), then releases as `release` says.
        person_margin_m: every new plan keeps this far from the person along its timing (a swept
            check against the person's predicted positions).
        ssm: speed-and-separation monitoring: the arm makes a protective stop when the person
            is nearer than the protective separation distance (`suite.execution.person`).
        near_miss_m: a pass of the robot this close to the person (true positions) is a near miss.
        release_margin_m: the can's centre must be this far inside the bin's inner walls (besides
            the can's radius) for a release.
        bin_mass_kg, person_mass_kg: the driven body's masses (heavy: the arm hardly moves it).
        drive_bandwidth_rad_s: natural frequency of the drive's PD loop on each axis (stiff).
    """

    speed_m_s: NonNeg = 0.1
    accel_m_s2: Pos = 2.0
    dwell_s: NonNeg = 0.5
    region_m: tuple[Vec2, Vec2] | None = None
    seed: NonNegInt = 0
    person_radius_m: Pos = 0.2
    person_height_m: Pos = 1.7
    person_gap_m: NonNeg = 0.05
    estimate_latency_s: NonNeg = 0.1
    estimate_rate_hz: Pos = 10.0
    estimate_noise_m: NonNeg = 0.003
    velocity_window: PosInt = 5
    drift_tolerance_m: Pos = 0.08
    drift_tolerance_min_m: Pos = 0.03
    drift_horizon_s: Pos = 1.0
    commit_s: NonNeg = 0.2
    replan_deadline_s: Pos = 0.3
    latency_mode: Literal["measured", "modelled"] = "measured"
    modelled_latency_s: dict[str, Pos] | None = None
    max_wait_s: Pos = 3.0
    can_time_limit_s: Pos = 20.0
    release: Literal["moving", "rest"] = "moving"
    track_ramp_s: Pos = 0.15
    track_feedback: bool = True
    aim: Literal["predicted", "centre"] = "predicted"
    person_margin_m: NonNeg = 0.05
    ssm: bool = True
    near_miss_m: Pos = 0.05
    release_margin_m: NonNeg = 0.01
    bin_mass_kg: Pos = 20.0
    person_mass_kg: Pos = 70.0
    drive_bandwidth_rad_s: Pos = 40.0

    def __post_init__(self):
        if self.region_m is not None:
            (x0, y0), (x1, y1) = self.region_m
            if not (x0 < x1 and y0 < y1):
                raise FieldError("region_m", f"{self.region_m}: allowed: ((x_lo, y_lo), (x_hi, y_hi)) with "
                                             "x_lo < x_hi and y_lo < y_hi")

    def to_json(self) -> dict:
        d = dataclasses.asdict(self)
        d["region_m"] = None if self.region_m is None else [list(c) for c in self.region_m]
        d["modelled_latency_s"] = None if self.modelled_latency_s is None else dict(self.modelled_latency_s)
        return d

    def drift_tolerance(self, time_to_go_s: float) -> float:
        """The drift that triggers a replan with `time_to_go_s` left to the arrival (m)."""
        f = min(max(time_to_go_s / self.drift_horizon_s, 0.0), 1.0)
        return self.drift_tolerance_min_m + f * max(self.drift_tolerance_m - self.drift_tolerance_min_m, 0.0)


def make_scenario(values: dict | None = None, *, where: str = "moving bin scenario: ") -> MovingBinScenario:
    """A scenario from plain values (YAML, flags), every field checked: one SuiteError line."""
    return load(MovingBinScenario, dict(values or {}), where=where)


def region(scenario: MovingBinScenario, spec: SceneSpec) -> tuple[np.ndarray, np.ndarray]:
    """The box the bin centre stays in (lower, upper corners (2,)), metres."""
    if scenario.region_m is not None:
        return np.array(scenario.region_m[0], float), np.array(scenario.region_m[1], float)
    c = np.array(spec.bin.center_xy_m, float)
    lo, hi = (np.array(o) for o in DEFAULT_REGION_OFFSETS_M)
    return c + lo, c + hi


def person_offset_m(scenario: MovingBinScenario, spec: SceneSpec) -> np.ndarray:
    """The person's axis relative to the bin centre (2,): beside the bin, away from the robot base."""
    c = np.array(spec.bin.center_xy_m, float)
    u = c / max(float(np.linalg.norm(c)), 1e-9)
    half = np.array(spec.bin.outer_size_m[:2]) / 2
    reach = float(abs(u[0]) * half[0] + abs(u[1]) * half[1])
    return u * (reach + scenario.person_gap_m + scenario.person_radius_m)


def person_obstacle(scenario: MovingBinScenario, spec: SceneSpec, bin_xy_m) -> Obstacle:
    """The person as a static cylinder for a planning world with the bin centre at bin_xy_m."""
    from scenes.spec_parts import Obstacle, pose_tuple

    X = np.eye(4)
    X[:2, 3] = np.asarray(bin_xy_m, float) + person_offset_m(scenario, spec)
    X[2, 3] = scenario.person_height_m / 2
    return Obstacle("person", "cylinder", (scenario.person_radius_m, scenario.person_height_m), pose_tuple(X),
                    (0.80, 0.60, 0.45, 1.0))


def spec_with_bin_at(scenario: MovingBinScenario, spec: SceneSpec, bin_xy_m) -> SceneSpec:
    """The station with the bin centre at bin_xy_m and the person beside it: a planning world of
    the moment (its key is its own; never stored)."""
    b = dataclasses.replace(spec.bin, center_xy_m=(float(bin_xy_m[0]), float(bin_xy_m[1])))
    return dataclasses.replace(spec, bin=b, extra=spec.extra + (person_obstacle(scenario, spec, bin_xy_m),))


def drop_pose(spec: SceneSpec, bin_xy_m) -> np.ndarray:
    """The gripper pose (4, 4) over the bin's opening with the bin centre at bin_xy_m: the spec's
    `above_bin_m` waypoint carried along with the bin (the gripper points down, its yaw by the
    task's rule)."""
    from scenes.grasp_rule import waypoint_pose

    p = np.array(spec.waypoints.above_bin_m, float)
    p[:2] += np.asarray(bin_xy_m, float) - np.array(spec.bin.center_xy_m, float)
    return waypoint_pose(p)


@dataclasses.dataclass(frozen=True, eq=False)
class BinPath:
    """The bin centre's seeded path, sampled every PATH_DT_S: positions (K, 2) m, velocities
    (K, 2) m/s at times t_s (K,)."""

    t_s: np.ndarray
    xy_m: np.ndarray
    v_m_s: np.ndarray

    def mean_speed_m_s(self, until_s: float) -> float:
        """The bin's mean speed from 0 to until_s."""
        n = max(2, min(len(self.t_s), int(until_s / PATH_DT_S) + 1))
        return float(np.mean(np.linalg.norm(self.v_m_s[:n], axis=1)))

    def at(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """The bin centre (2,) and its velocity (2,) at time t_s (held after the horizon)."""
        t = min(max(float(t_s), 0.0), float(self.t_s[-1]))
        i = min(int(t / PATH_DT_S), len(self.t_s) - 2)
        w = (t - self.t_s[i]) / PATH_DT_S
        return (1 - w) * self.xy_m[i] + w * self.xy_m[i + 1], (1 - w) * self.v_m_s[i] + w * self.v_m_s[i + 1]


def _trapezoid(d: float, v: float, a: float) -> tuple[float, float, float]:
    """(time to cruise, cruise time, peak speed) of a rest-to-rest move of length d."""
    if d * a <= v * v:  # never reaches cruise speed: a triangle
        peak = math.sqrt(d * a)
        return peak / a, 0.0, peak
    return v / a, d / v - v / a, v


def bin_path(scenario: MovingBinScenario, spec: SceneSpec, *, horizon_s: float = PATH_HORIZON_S) -> BinPath:
    """The seeded path of the bin centre (see the module docstring)."""
    t = np.arange(0.0, horizon_s + PATH_DT_S / 2, PATH_DT_S)
    start = np.array(spec.bin.center_xy_m, float)
    xy = np.tile(start, (len(t), 1))
    vel = np.zeros((len(t), 2))
    v, a = scenario.speed_m_s, scenario.accel_m_s2
    if v <= 0:
        return BinPath(t, xy, vel)
    lo, hi = region(scenario, spec)
    rng = np.random.default_rng([scenario.seed, 1913])
    t0, p0 = 0.0, start
    while t0 < horizon_s:
        target = rng.uniform(lo, hi)
        d = float(np.linalg.norm(target - p0))
        if d < 1e-3:
            continue
        u = (target - p0) / d
        ta, tc, peak = _trapezoid(d, v, a)
        T = 2 * ta + tc
        m = (t >= t0) & (t < t0 + T)
        tau = t[m] - t0
        s = np.where(tau < ta, 0.5 * a * tau**2,
                     np.where(tau < ta + tc, 0.5 * a * ta**2 + peak * (tau - ta),
                              d - 0.5 * a * np.maximum(T - tau, 0.0) ** 2))
        sd = np.where(tau < ta, a * tau, np.where(tau < ta + tc, peak, a * np.maximum(T - tau, 0.0)))
        xy[m] = p0 + s[:, None] * u
        vel[m] = sd[:, None] * u
        xy[t >= t0 + T] = target
        vel[t >= t0 + T] = 0.0
        t0, p0 = t0 + T + scenario.dwell_s, target
    return BinPath(t, xy, vel)
