"""Seed-driven scene generation: a station (drawn for a family), then N cans on the plate, all apart
from each other and from the obstacles, and all graspable."""

from __future__ import annotations

import dataclasses
import logging

import numpy as np

from scenes.placement import capacity_bound, gripper_clear, layout, place
from scenes.scene import CanPose, Scene
from scenes.spec import SceneSpec
from scenes.errors import SuiteError

log = logging.getLogger(__name__)

MAX_REACH_ROUNDS = 20
MAX_STATION_DRAWS = 30
#: Grasp IK solves a drawn station may fail while its cans are made reachable before it is drawn
#: again: a failing solve costs all of its restarts (about 0.6 s), and a station on which grasps
#: keep failing (most of its plate under a board or behind a wall) is cheaper to draw anew than to
#: fill. Counted, not timed, so that the same seed gives the same scene on any machine.
MAX_IK_FAILURES_PER_STATION = 4


def _grasp_ik_options():
    """The grasp checks' IK: the seed, the seeds near it and one random restart, 60 SNOPT major
    iterations each. Over 30 shelf, clutter and window scenes, the three later random restarts
    found 1 of 746 solutions, and solutions came in at most 26 ms, while a failing solve ran up
    to 250 ms at 150 iterations. A can these limits give up on is drawn again, so they bias
    scenes slightly towards grasps the IK finds quickly, never towards unreachable ones."""
    from scenes.ik import IkOptions

    return IkOptions(restarts=1, major_iterations=60)


def station_unreachable(spec: SceneSpec) -> str | None:
    """Why a drawn station is infeasible, or None: the three task waypoints must have
    collision-free IK solutions, reached one from the other (above the plate with the gripper
    open; middle and above the bin also holding an upright can)."""
    from scenes.drake_scene import build_drake_scene
    from scenes.grasp_rule import truth_grasp, waypoint_pose
    from scenes.ik import Q_READY, PoseIk
    from scenes.scene import HeldCan

    spec.require("plate", "can", "waypoints", needed_by="a station's reachability check")
    empty = Scene(spec, 0, ())
    rng = np.random.default_rng(0)
    ik = PoseIk(build_drake_scene(empty, mode="plan", cameras=False))
    wp = spec.waypoints
    q = ik.solve(waypoint_pose(wp.above_plate_m), q_seed=Q_READY, rng=rng)
    if q is None:
        return "the waypoint above the plate"
    px, py, _ = spec.plate.center_m
    can = CanPose(0, (px, py, spec.plate_top_z_m + spec.can.height_m / 2), False, 0.0)
    held = HeldCan.from_grasp(can, truth_grasp(Scene(spec, 0, (can,)), can).X_WG)
    ik_held = PoseIk(build_drake_scene(empty, mode="plan", cameras=False,
                                       gripper_opening_m=2 * spec.can.radius_m, held=held))
    for name, p in (("middle", wp.middle_m), ("above the bin", wp.above_bin_m)):
        q = ik_held.solve(waypoint_pose(p), q_seed=q, rng=rng)
        if q is None:
            return f"the {name} waypoint holding a can"
    return None


def draw_feasible_station(spec: SceneSpec, rng: np.random.Generator) -> SceneSpec:
    """A family's concrete station whose waypoints are reachable (drawn again otherwise)."""
    from scenes.families import draw_station

    if spec.family is None:
        return spec
    for _ in range(MAX_STATION_DRAWS):
        drawn = draw_station(spec, rng)
        why = station_unreachable(drawn)
        if why is None:
            return drawn
        log.debug("%s station redrawn: no IK for %s", spec.variant, why)
    raise SuiteError(f"{spec.variant}: no feasible station in {MAX_STATION_DRAWS} draws; widen the family's ranges")


class _IkFailures:
    """The failed grasp IK solves one station may still spend (see MAX_IK_FAILURES_PER_STATION)."""

    def __init__(self, limit: int) -> None:
        self.left = limit

    def spend(self, seed: int) -> None:
        self.left -= 1
        if self.left < 0:
            raise SuiteError(f"seed {seed}: more than {MAX_IK_FAILURES_PER_STATION} grasp IK solves failed on this station")


def unreachable_cans(scene: Scene, *, ids=None, failures: _IkFailures | None = None) -> list[int]:
    """Ids of cans (of `ids`, all by default) with no collision-free IK solution for their grasp
    or pre-grasp while every can of the scene is on the plate, or whose gripper would touch
    another can or obstacle on the way down from the pre-grasp to the grasp. With `failures`,
    each failed IK solve is spent from it (SuiteError once it runs out)."""
    from scenes.drake_scene import build_drake_scene
    from scenes.grasp_rule import truth_grasp
    from scenes.ik import Q_READY, PoseIk

    ik = None
    bad = []
    for can in scene.cans:
        if ids is not None and can.id not in ids:
            continue
        if not gripper_clear(can, [c for c in scene.cans if c.id != can.id], scene.spec):
            # the open gripper cannot even reach the grasp from the pre-grasp without touching a
            # neighbour or an obstacle: no IK needed (and a failing IK costs all of its restarts)
            bad.append(can.id)
            continue
        ik = ik or PoseIk(build_drake_scene(scene, mode="plan", cameras=False))
        grasp = truth_grasp(scene, can)
        rng = np.random.default_rng([scene.seed, can.id])
        opts = _grasp_ik_options()
        q_pre = ik.solve(grasp.X_WGpre, q_seed=Q_READY, rng=rng, options=opts)
        if q_pre is None or ik.solve(grasp.X_WG, q_seed=q_pre, rng=rng, options=opts) is None:
            bad.append(can.id)
            if failures is not None:
                failures.spend(scene.seed)
    return bad


def picking_order(scene: Scene, *, failures: _IkFailures | None = None) -> tuple[list[int], list[int]]:
    """A picking order in which every can is graspable when its turn comes, and the cans that
    are not graspable in any order.

    Removing a can only frees room, so a can graspable now stays graspable: the cans graspable
    with all others present come first (in id order), then those freed by their removal, and so
    on. On a sparse plate that is simply every can in id order; in clutter a can boxed in by its
    neighbours comes after them.
    """
    order: list[int] = []
    pending = [c.id for c in scene.cans]
    while pending:
        current = scene.without_cans(order)
        bad = unreachable_cans(current, ids=set(pending), failures=failures)
        free = [i for i in pending if i not in bad]
        if not free:
            return order, pending
        order += free
        pending = bad
    return order, []


def generate_scene(spec: SceneSpec, *, seed: int, check_reachable: bool = True) -> Scene:
    """Draw the station (for a family spec) and scatter `spec.cans.count` cans on the plate (a
    world without cans, `spec.cans` None, is its spec alone).

    Every can lies wholly on the plate (with the edge margin), at least `min_gap_m` from every
    other can and from the drawn obstacles, upright or lying with a random yaw; with
    `check_reachable`, every grasp and pre-grasp has a collision-free IK solution (unreachable cans
    are drawn again): with all other cans present for "random" placement (the paper's plate, as
    before families existed), or when the can's turn comes in the order of the ids for "pickable"
    placement (dense plates; see `picking_order`).

    A family's drawn station (with its drawn can count and gap) on which the cans do not fit, or
    do not become reachable in MAX_REACH_ROUNDS rounds, is drawn again from the same generator,
    up to MAX_STATION_DRAWS draws; a fixed spec (no family) fails at once.

    The same seed gives the same scene: all randomness comes from one PCG64 generator.
    """
    if spec.cans is None and spec.family is None:  # a world without cans: nothing to scatter
        return Scene(spec, seed, ())
    rng = np.random.default_rng(seed)
    family = spec
    draws = MAX_STATION_DRAWS if family.family is not None else 1
    why = ""
    for draw in range(draws):
        spec = draw_feasible_station(family, rng)
        n = spec.cans.count
        bound = capacity_bound(spec)
        try:
            if n > bound:
                raise SuiteError(
                    f"cans.count = {n} cannot fit on the plate with min_gap_m = {spec.cans.min_gap_m}: "
                    f"at most {bound} cans fit"
                )
            return _fill(rng, spec, seed, check_reachable=check_reachable, redrawable=family.family is not None)
        except SuiteError as exc:
            if family.family is None:
                raise
            why = str(exc)
            log.debug("seed %d: drawn station %d cannot hold its cans (%s); drawn again", seed, draw, why)
    raise SuiteError(
        f"{family.variant} seed {seed}: none of {MAX_STATION_DRAWS} drawn stations could hold its cans (last: {why}); "
        f"relax the ranges in 'families.{family.variant}.ranges' (fewer cans or distractors, smaller gaps)"
    )


def _fill(rng, spec: SceneSpec, seed: int, *, check_reachable: bool, redrawable: bool = False) -> Scene:
    """The cans of one concrete station (see `generate_scene`); SuiteError if they do not fit or
    do not all become reachable, or (for a `redrawable` station, drawn for a family) once more
    than MAX_IK_FAILURES_PER_STATION grasp IK solves failed."""
    n = spec.cans.count
    cans = layout(rng, spec)
    scene = Scene(spec, seed, tuple(cans))
    if not check_reachable:
        return scene
    # a fixed spec (no family) has no other station to draw: its failures are not counted
    failures = _IkFailures(MAX_IK_FAILURES_PER_STATION) if redrawable else None
    for round_ in range(MAX_REACH_ROUNDS):
        if spec.cans.placement == "pickable":
            order, bad = picking_order(scene, failures=failures)
        else:  # the paper's plate: every can graspable with all the others present, in any order
            bad = unreachable_cans(scene, failures=failures)
            order = [c.id for c in scene.cans]
        if not bad:
            # ids follow the picking order, so every user of the scene picks in a feasible order
            return Scene(spec, seed, tuple(dataclasses.replace(cans[i], id=k) for k, i in enumerate(order)))
        log.debug("seed %d round %d: redrawing unreachable cans %s", seed, round_, bad)
        for i in bad:
            others = [c for c in cans if c.id != i]
            can = place(rng, spec, i, others, cans[i].lying)
            if can is None:
                cans = layout(rng, spec)
                break
            cans[i] = can
        scene = Scene(spec, seed, tuple(cans))
    raise SuiteError(f"seed {seed}: could not draw {n} reachable cans in {MAX_REACH_ROUNDS} rounds")
