"""Whether a station can run a moving-bin scenario: the bin's region on the table and clear of the
plate, the wall and the other obstacles, for the bin and the person beside it, and (with `reach`)
the drop pose over every corner of the region in the arm's collision-free reach.

The checks use the scenario's geometry (`scenes.moving_bin`) and, for the reach, the Drake scene
and its IK, which is why they stand above both.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from scenes.errors import SuiteError
from scenes.moving_bin import (
    MOVING_BIN_FAMILIES,
    MovingBinScenario,
    drop_pose,
    person_offset_m,
    region,
    spec_with_bin_at,
)

if TYPE_CHECKING:
    from scenes.spec import SceneSpec


def _overlap(lo_a, hi_a, lo_b, hi_b) -> bool:
    return bool(np.all(lo_a < hi_b) and np.all(lo_b < hi_a))


def check_scenario(scenario: MovingBinScenario, spec: SceneSpec, *, reach: bool = True) -> None:
    """Refuse a scenario this station cannot run, in one SuiteError line: a family other than
    open and wall, a region that does not hold the bin's place, leaves the table, lets the bin or
    the person overlap the plate, the wall or another obstacle, or (with `reach`) puts the drop
    pose over one of its corners out of the arm's collision-free reach (IK, as the dataset's goals)."""
    if spec.variant not in MOVING_BIN_FAMILIES or spec.family is not None:
        raise SuiteError(f"a moving bin runs on the {' and '.join(MOVING_BIN_FAMILIES)} families, not "
                         f"{spec.variant!r}")
    spec.require("bin", "cans", needed_by="a moving bin")
    lo, hi = region(scenario, spec)
    c = np.array(spec.bin.center_xy_m, float)
    where = f"moving bin region {[list(map(float, lo)), list(map(float, hi))]}"
    if np.any(c < lo) or np.any(c > hi):
        raise SuiteError(f"{where} must hold the bin's place {list(map(float, c))}")
    half = np.array(spec.bin.outer_size_m[:2]) / 2
    r = scenario.person_radius_m
    p_off = person_offset_m(scenario, spec)
    sweeps = {"the bin": (lo - half, hi + half), "the person": (lo + p_off - r, hi + p_off + r)}
    t = spec.table
    t_lo = np.array(t.center_m[:2]) - np.array(t.size_m[:2]) / 2
    t_hi = np.array(t.center_m[:2]) + np.array(t.size_m[:2]) / 2
    b_lo, b_hi = sweeps["the bin"]
    if np.any(b_lo < t_lo) or np.any(b_hi > t_hi):
        raise SuiteError(f"{where} takes the bin off the table (x {t_lo[0]:.2f}..{t_hi[0]:.2f}, "
                         f"y {t_lo[1]:.2f}..{t_hi[1]:.2f} m)")
    for obstacle in spec.obstacles():
        if obstacle.name == "table" or obstacle.name.startswith("bin_"):
            continue
        o_lo, o_hi = _footprint(obstacle)
        for who, (s_lo, s_hi) in sweeps.items():
            if _overlap(s_lo, s_hi, o_lo, o_hi):
                raise SuiteError(f"{where} lets {who} run into the {obstacle.name}; allowed: a region clear of it")
    if reach:
        _check_reach(scenario, spec, lo, hi)


def _footprint(obstacle) -> tuple[np.ndarray, np.ndarray]:
    """An obstacle's axis-aligned footprint in the floor plane (lower, upper (2,))."""
    X = obstacle.pose()
    s = obstacle.size_m
    if obstacle.shape == "box":
        half = np.abs(X[:3, :3]) @ (np.array(s) / 2)
    elif obstacle.shape == "cylinder":
        half = np.full(3, s[0] + s[1] / 2)  # a bound, whatever the axis
    else:
        half = np.full(3, s[0])
    return X[:2, 3] - half[:2], X[:2, 3] + half[:2]


def _check_reach(scenario: MovingBinScenario, spec: SceneSpec, lo: np.ndarray, hi: np.ndarray) -> None:
    """Collision-free IK of the drop pose with the bin at each corner of the region."""
    from scenes.drake_scene import build_drake_scene
    from scenes.ik import Q_READY, IkOptions, PoseIk
    from scenes.scene import Scene

    rng = np.random.default_rng([scenario.seed, 4242])
    for corner in ((lo[0], lo[1]), (lo[0], hi[1]), (hi[0], lo[1]), (hi[0], hi[1])):
        moved = Scene(spec_with_bin_at(scenario, spec, corner), 0, ())
        ik = PoseIk(build_drake_scene(moved, mode="plan", cameras=False))
        if ik.solve(drop_pose(spec, corner), q_seed=Q_READY, rng=rng, options=IkOptions()) is None:
            raise SuiteError(f"moving bin region corner ({corner[0]:.2f}, {corner[1]:.2f}) m is out of the arm's "
                             "reach: no collision-free IK for the drop pose over the bin there; allowed: a "
                             "region the arm reaches")
