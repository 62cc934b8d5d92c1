"""Every metric a trial record carries: its unit, its direction and a one-line definition.

This is the one list that tables, plots and the README read. A record's metric values are in
`record["metrics"][name]`, except `planning_time_s`, a field of the record itself. Where the field
(OMPL, cuRobo, MpiNets) defines a metric differently, `note` says how ours differs.
"""

from __future__ import annotations

import dataclasses
from typing import Literal

from scenes.errors import SuiteError

Direction = Literal["lower", "higher", "none"]
Group = Literal["time", "length", "optimality", "smoothness", "natural pose", "clearance", "goal", "timing check"]


@dataclasses.dataclass(frozen=True)
class MetricDef:
    """One metric.

    Attributes:
        name: the record key; ends with its unit where it has one (`_rad`, `_m`, `_s`, `_deg`).
        unit: the unit as printed ("1" for a dimensionless number).
        direction: "lower" or "higher" is better; "none" for a diagnostic with no better side.
        definition: one line saying what is measured, and on what samples.
        group: the theme it belongs to (for tables and plot panels).
        note: how it differs from the field's usual definition ("" if it does not).
        headline: shown in the summary and plots by default.
        label: its column label in tables, unit included ("" for its name and unit).
    """

    name: str
    unit: str
    direction: Direction
    definition: str
    group: Group
    note: str = ""
    headline: bool = False
    label: str = ""

    @property
    def column(self) -> str:
        """The column label: `label`, else its name without the unit suffix, with its unit."""
        if self.label:
            return self.label
        base = self.name.removesuffix(f"_{self.unit}") if self.unit != "1" else self.name
        return base.replace("_", " ") + ("" if self.unit == "1" else f" ({self.unit})")


#: Largest joint-space spacing (L2, rad) of the coarse samples along a path (the mean clearance).
COARSE_STEP_RAD = 0.05
#: Fine samples per coarse step: the extrema and the kinematic metrics use samples at most
#: COARSE_STEP_RAD / FINE_PER_COARSE = 0.01 rad apart.
FINE_PER_COARSE = 5
KINEMATIC_STEP_RAD = COARSE_STEP_RAD / FINE_PER_COARSE
_FINE = f"at most {KINEMATIC_STEP_RAD:g} rad apart by arc length"
_COARSE = f"at most {COARSE_STEP_RAD:g} rad apart by arc length"

METRICS: tuple[MetricDef, ...] = (
    MetricDef("planning_time_s", "s", "lower",
              "wall time of the planner's plan() call, measured by the orchestrator; building the problem's "
              "world (python-fcl world, a Drake-based planner's diagram and program) is done before the clock "
              "starts and recorded apart as setup_time_s", "time", headline=True, label="planning time (s)"),
    MetricDef("duration_s", "s", "lower",
              "duration of the TOPP-RA time-optimal trajectory within the iiwa's velocity and acceleration limits",
              "time", note="cuRobo's 'motion time'", headline=True, label="duration (s)"),
    MetricDef("timing_time_s", "s", "lower", "wall time of the TOPP-RA time parameterization and its checks", "time"),
    MetricDef("time_to_trajectory_s", "s", "lower",
              "planning_time_s + timing_time_s: the wall time from the problem to an executable, timed trajectory",
              "time", note="the time to an executable trajectory that users comparing cuRobo with OMPL asked for"),
    MetricDef("offline_s", "s", "lower",
              "offline preparation of the problem's collision world, outside planning time (gcs: the wall time "
              "its convex regions took to build, as recorded at the build; the same for every problem of the "
              "world, whether this run built them or loaded them)", "time",
              note="reported beside planning time, never inside it, as the GCS paper reports region building",
              label="offline (s)"),
    MetricDef("time_to_solve_s", "s", "lower",
              "success-aware time, per distinct problem: median over its trials of planning_time_s, a failed "
              "trial counted at its time budget (summary only, over every problem, not just the solved ones)",
              "time", note="a failure costs the whole budget (as PAR-1 in solver competitions)"),
    MetricDef("path_length_rad", "rad", "lower",
              "joint-space length: sum of L2 distances between consecutive waypoints", "length",
              note="as OMPL's PathGeometric::length() (MoveIt uses L1)", headline=True, label="path length (rad)"),
    MetricDef("ee_path_length_m", "m", "lower",
              f"length of the gripper origin's Cartesian path, forward kinematics at samples {_FINE}",
              "length", headline=True),
    MetricDef("ee_rotation_deg", "deg", "lower",
              f"total rotation of the gripper frame, summed over samples {_FINE}", "length"),
    MetricDef("length_ratio", "1", "lower",
              "joint path length / the problem's reference length (dataset's best known path); >= 1 unless "
              "the planner beat the reference", "optimality", headline=True, label="length / reference"),
    MetricDef("length_over_straight", "1", "lower",
              "joint path length / straight joint-space distance from start to goal (a lower bound, not an "
              "achievable optimum); >= 1", "optimality",
              note="a bound, not an optimum: the ratio overstates the optimality gap"),
    MetricDef("ee_length_ratio", "1", "lower",
              "gripper path length / the reference path's gripper path length, where the problem carries one",
              "optimality"),
    MetricDef("ee_length_over_straight", "1", "lower",
              "gripper path length / straight Cartesian distance between its start and end positions "
              "(NaN when they are under 1 cm apart)", "optimality"),
    MetricDef("turning_angle_rad", "rad", "lower",
              "total turning angle of the joint path: sum of angles between consecutive segment directions, "
              "zero-length segments and collinear points dropped (0 for a straight segment)", "smoothness",
              note="replaces OMPL's smoothness, which depends on waypoint spacing", headline=True,
              label="turning angle (rad)"),
    MetricDef("sparc", "1", "higher",
              "spectral arc length (SPARC, Balasubramanian et al. 2015; fc 10 Hz, threshold 0.05, padding 4) "
              "of the joint-space speed ||qd(t)|| of the TOPP-RA trajectory; <= 0, closer to 0 is smoother",
              "smoothness", note="MpiNets also reports SPARC of the end-effector speed; sign as in the paper",
              headline=True, label="SPARC (higher: smoother)"),
    MetricDef("smoothness", "1/rad^2", "lower",
              "OMPL's PathGeometric::smoothness() on the path resampled every 0.05 rad; for the Planner Arena "
              "export only", "smoothness",
              note="near 0 for any straight segment, huge for small kinks on dense paths: not a headline figure"),
    MetricDef("jerk_max", "rad/s^3", "lower",
              "largest absolute joint jerk of the TOPP-RA trajectory sampled every 0.01 s", "smoothness",
              note="as cuRobo's; on TOPP-RA's piecewise-constant accelerations it measures the timing grid"),
    MetricDef("jerk_sq_integral", "rad^2/s^5", "lower",
              "integral over time of the squared joint jerk norm (0.01 s samples)", "smoothness",
              note="depends on TOPP-RA's grid like jerk_max"),
    MetricDef("joint_margin_min_frac", "1", "higher",
              "smallest joint-limit margin along the path: min over joints and samples of the distance to the "
              f"nearer limit / the joint's range (0.5 mid-range, 0 at a limit); samples {_FINE}",
              "natural pose", headline=True),
    MetricDef("posture_distance_mean_rad", "rad", "lower",
              "mean by arc length of the joint-space L2 distance from the comfortable posture "
              "q = [-1.57, 0.1, 0, -1.2, 0, 1.6, 0] (Drake's iiwa 'ready')", "natural pose", headline=True),
    MetricDef("manipulability_min_m3", "m^3", "higher",
              f"smallest Yoshikawa manipulability sqrt(det(J J^T)) of the gripper's geometric Jacobian, "
              f"samples {_FINE} (0 at a singularity)", "natural pose", headline=True),
    MetricDef("can_tilt_max_deg", "deg", "lower",
              "largest angle between a carried upright can's axis and the vertical (a full can spills); "
              f"absent when no upright can is held; samples {_FINE}",
              "natural pose", headline=True),
    MetricDef("clearance_min_m", "m", "higher",
              f"smallest signed distance robot (and held can) to scene, negative in penetration; samples {_FINE}",
              "clearance",
              note="OMPL's benchmark reports clearance at the waypoints only", headline=True,
              label="min clearance (m)"),
    MetricDef("clearance_mean_m", "m", "higher",
              f"mean by arc length of the signed distance robot to scene; samples {_COARSE}",
              "clearance", note="OMPL's is the plain mean over the waypoints, which depends on their density"),
    MetricDef("goal_error_m", "m", "lower", "distance of the gripper's final position from the goal pose", "goal"),
    MetricDef("goal_error_deg", "deg", "lower", "rotation angle between the gripper's final and goal orientation",
              "goal"),
    MetricDef("velocity_limit_ratio", "1", "none",
              "largest |qd_i| / velocity limit_i over the dense timing check (1 = at the limit)", "timing check"),
    MetricDef("acceleration_limit_ratio", "1", "none",
              "largest |qdd_i| / acceleration limit_i over the dense timing check", "timing check"),
    MetricDef("path_deviation_rad", "rad", "lower",
              "largest L2 distance of the timed trajectory from the validated polyline (corner rounding)",
              "timing check"),
)

METRICS_BY_NAME: dict[str, MetricDef] = {m.name: m for m in METRICS}

#: Metrics that `suite.scoring.metrics.score` does not compute from the path: the orchestrator's
#: clock, and the times derived from it when records are read or summarized.
NOT_FROM_PATH: frozenset[str] = frozenset({"planning_time_s", "time_to_trajectory_s", "time_to_solve_s", "offline_s"})


def metric_def(name: str) -> MetricDef:
    """The definition of a metric by its record key."""
    try:
        return METRICS_BY_NAME[name]
    except KeyError:
        raise SuiteError(f"unknown metric {name!r}; known: {', '.join(METRICS_BY_NAME)}") from None


def headline_metrics() -> tuple[MetricDef, ...]:
    """The metrics shown by default, in registry order."""
    return tuple(m for m in METRICS if m.headline)


def markdown_table(metrics: tuple[MetricDef, ...] = METRICS) -> str:
    """The metrics as a Markdown table (for the README): name, unit, better, definition, differences."""
    better = {"lower": "lower", "higher": "higher", "none": "-"}
    rows = ["| metric | unit | better | definition | vs. the field |", "|---|---|---|---|---|"]
    rows += [f"| `{m.name}` | {m.unit} | {better[m.direction]} | {m.definition} | {m.note} |" for m in metrics]
    return "\n".join(rows)
