"""Pair by pair: why python-fcl and roboplan (coal) disagree about one configuration.

For a configuration on which `CollisionWorld.is_free` and roboplan's `Scene.hasCollisions` differ,
`diagnose` names the pairs each engine finds in collision and measures them three ways on the same
primitives at the python-fcl world's poses: python-fcl's `collide` and signed `distance`, and
coal's (the library roboplan checks with) `collide` and signed `distance`. roboplan's own pairs
come from `hasCollisions(q, debug=True)`, which checks every active pair and prints the colliding
ones (captured from the C++ stdout); its plain `hasCollisions(q)` goes through a broadphase tree
and stops at the first collision.
"""

from __future__ import annotations

import ctypes
import dataclasses
import os
import re
import tempfile

import fcl
import numpy as np

from planners.roboplan_scene import RoboplanWorld, obstacle_primitive
from scenes.collision.shapes import fcl_geometry

#: Contacts within this depth or gap (m) are "shallow": both verdicts are right to floating point.
SHALLOW_M = 1e-6
_PAIR_LINE = re.compile(r"Collision detected between (\S+) and (\S+)")
_LIBC = ctypes.CDLL(None)


@dataclasses.dataclass(frozen=True)
class PairMeasure:
    """One pair at one configuration, measured by both libraries on the same shapes and poses.

    Attributes:
        a, b: the body or obstacle names, in roboplan's order (pinocchio checks a pair of
            geometries (i, j) with i < j: robot geometry before obstacles).
        shapes: their primitive kinds, e.g. "capsule-cylinder".
        fcl_collide: python-fcl's boolean collision query.
        coal_collide: coal's boolean `collide(a, b)` with pinocchio's request (no contact
            information: GJK alone, no EPA), in roboplan's order; coal_collide_swapped: the same
            as `collide(b, a)`; coal_collide_epa: `collide(a, b)` with coal's default request
            (contacts enabled: EPA after GJK).
        fcl_distance_m, coal_distance_m: each library's signed distance (negative in penetration).
    """

    a: str
    b: str
    shapes: str
    fcl_collide: bool
    coal_collide: bool
    coal_collide_swapped: bool
    coal_collide_epa: bool
    fcl_distance_m: float
    coal_distance_m: float


@dataclasses.dataclass(frozen=True)
class Diagnosis:
    """Why the two engines disagree about one configuration.

    Attributes:
        fcl_free, roboplan_free: the two verdicts (they differ).
        roboplan_pairs: the pairs roboplan's exhaustive debug check finds in collision.
        pairs: every pair either engine (or either library's collide) finds in collision, measured.
        kind: the class of the disagreement (see `classify`).
    """

    fcl_free: bool
    roboplan_free: bool
    roboplan_pairs: tuple[tuple[str, str], ...]
    pairs: tuple[PairMeasure, ...]
    kind: str


def roboplan_pairs(rw: RoboplanWorld, q: np.ndarray) -> tuple[bool, tuple[tuple[str, str], ...]]:
    """roboplan's exhaustive check of q: (any collision, the colliding pairs by body name).

    `hasCollisions(q, debug=True)` prints each colliding pair to the process's stdout from C++;
    it is captured through a temporary file. Robot geometry is named `<link>_<k>` by pinocchio.
    """
    _LIBC.fflush(None)
    with tempfile.TemporaryFile() as f:
        saved = os.dup(1)
        os.dup2(f.fileno(), 1)
        try:
            hit = rw.scene.hasCollisions(np.asarray(q, float), True)
            _LIBC.fflush(None)
        finally:
            os.dup2(saved, 1)
            os.close(saved)
        f.seek(0)
        text = f.read().decode(errors="replace")
    bodies = set(rw.robot_bodies)

    def body(geom: str) -> str:
        stem = geom.rsplit("_", 1)[0]
        return stem if stem in bodies else geom

    pairs = tuple(sorted(tuple(sorted((body(a), body(b)))) for a, b in _PAIR_LINE.findall(text)))
    return bool(hit), pairs


def pinocchio_request():
    """The collision request pinocchio's GeometryData gives every pair (checked with pinocchio
    4.1: `CollisionRequest(NO_REQUEST, 1)`, so `enable_contact` is False)."""
    import coal

    return coal.CollisionRequest(coal.CollisionRequestFlag.NO_REQUEST, 1)


def _coal_geometry(kind: str, dims):
    import coal

    if kind == "box":
        return coal.Box(*map(float, dims))
    if kind == "cylinder":
        return coal.Cylinder(float(dims[0]), float(dims[1]))
    if kind == "capsule":
        return coal.Capsule(float(dims[0]), float(dims[1]))
    if kind == "sphere":
        return coal.Sphere(float(dims[0]))
    raise ValueError(f"unsupported shape {kind!r}")


class PairMeter:
    """Every pair the python-fcl world counts, with its primitives, measurable at any q."""

    def __init__(self, world, rw: RoboplanWorld) -> None:
        self.world = world
        parts = world.parts
        self.items: dict[str, tuple[str, tuple, object]] = {}  # name -> (kind, dims, body index or X_WO)
        for p in parts:
            self.items[p.name] = (p.kind, p.dims, (p.body, p.X_BS))
        for name, _obj in world.obstacles:
            self.items[name] = obstacle_primitive(world, name)
        # roboplan's geometry index of each name orders a pair as pinocchio checks it
        self.index = {name: min(rw.scene.getCollisionGeometryIDs(name)) for name in self.items}
        names = [p.name for p in parts]
        self.pairs = [self.ordered((names[i], names[j])) for i, j in world.self_pairs]
        obstacle_names = [n for n, _ in world.obstacles]
        self.pairs += [self.ordered((p.name, o)) for p in parts if p.name != "iiwa_link_0" for o in obstacle_names
                       if not (p.name == "held_can" and o == "plate")]

    def ordered(self, pair) -> tuple[str, str]:
        """The pair in roboplan's order (lower geometry index first)."""
        return tuple(sorted(pair, key=self.index.__getitem__))

    def poses(self, q: np.ndarray) -> dict[str, np.ndarray]:
        X_WB = self.world.robot.link_poses(np.asarray(q, float))
        out = {}
        for name, (_kind, _dims, where) in self.items.items():
            out[name] = X_WB[where[0]] @ where[1] if isinstance(where, tuple) else where
        return out

    def measure(self, q: np.ndarray, pair: tuple[str, str], poses: dict | None = None) -> PairMeasure:
        import coal

        poses = poses or self.poses(q)
        (ka, da, _), (kb, db, _) = self.items[pair[0]], self.items[pair[1]]
        Xa, Xb = poses[pair[0]], poses[pair[1]]
        oa = fcl.CollisionObject(fcl_geometry(ka, da), fcl.Transform(Xa[:3, :3], Xa[:3, 3]))
        ob = fcl.CollisionObject(fcl_geometry(kb, db), fcl.Transform(Xb[:3, :3], Xb[:3, 3]))
        f_col = bool(fcl.collide(oa, ob, fcl.CollisionRequest(), fcl.CollisionResult()))
        f_dist = float(fcl.distance(oa, ob, fcl.DistanceRequest(enable_signed_distance=True), fcl.DistanceResult()))
        ga, gb = _coal_geometry(ka, da), _coal_geometry(kb, db)
        Ta, Tb = coal.Transform3s(Xa[:3, :3], Xa[:3, 3]), coal.Transform3s(Xb[:3, :3], Xb[:3, 3])
        c_ab = coal.collide(ga, Ta, gb, Tb, pinocchio_request(), coal.CollisionResult()) > 0
        c_ba = coal.collide(gb, Tb, ga, Ta, pinocchio_request(), coal.CollisionResult()) > 0
        c_epa = coal.collide(ga, Ta, gb, Tb, coal.CollisionRequest(), coal.CollisionResult()) > 0
        c_dist = float(coal.distance(ga, Ta, gb, Tb, coal.DistanceRequest(), coal.DistanceResult()))
        return PairMeasure(pair[0], pair[1], f"{ka}-{kb}", f_col, bool(c_ab), bool(c_ba), bool(c_epa), f_dist,
                           c_dist)

    def colliding(self, q: np.ndarray) -> list[PairMeasure]:
        """The counted pairs that either library's collide, or its signed distance, puts in contact."""
        poses = self.poses(q)
        out = []
        for pair in self.pairs:
            m = self.measure(q, pair, poses)
            if m.fcl_collide or m.coal_collide or m.coal_collide_swapped or min(m.fcl_distance_m, m.coal_distance_m) <= SHALLOW_M:
                out.append(m)
        return out


def classify(*, fcl_free: bool, roboplan_free: bool, roboplan_debug_hit: bool, pairs: list[PairMeasure]) -> str:
    """The class of one disagreement, from the measured pairs.

    - "broadphase": roboplan's exhaustive check agrees with python-fcl, its broadphase query does not.
    - "shallow contact": every pair in contact by either library is within SHALLOW_M of touching
      (depth or gap): a floating-point tie, either verdict is right.
    - "coal collide misses <shapes> <a>-<b> in roboplan's order": both libraries' signed
      distances put the pair deeper than SHALLOW_M in penetration, and coal's boolean `collide`
      (GJK without EPA, as pinocchio calls it) reports it free in roboplan's argument order;
      then whether `collide(b, a)` and coal's default request (with EPA) report it.
    - "fcl collide misses ...": the reverse (python-fcl's boolean query reports a deep pair free).
    - "other": none of these (its pairs are in the JSON).
    """
    if roboplan_debug_hit == (not fcl_free) and roboplan_debug_hit != (not roboplan_free):
        return "broadphase"
    deep = [m for m in pairs if max(m.fcl_distance_m, m.coal_distance_m) < -SHALLOW_M]
    if not deep:
        return "shallow contact"
    if not fcl_free and roboplan_free:
        missed = [m for m in deep if m.fcl_collide and not m.coal_collide]
        if missed:
            m = max(missed, key=lambda m: -m.fcl_distance_m)
            other = "; found in the other order" if m.coal_collide_swapped else "; missed in both orders"
            other += ", and with EPA" if m.coal_collide_epa else ", not with EPA either"
            return f"coal collide misses {m.shapes} {m.a}-{m.b} in roboplan's order{other}"
    if fcl_free and not roboplan_free:
        missed = [m for m in deep if m.coal_collide and not m.fcl_collide]
        if missed:
            m = max(missed, key=lambda m: -m.coal_distance_m)
            return f"fcl collide misses {m.shapes} {m.a}-{m.b}"
    return "other"


def diagnose(meter: PairMeter, rw: RoboplanWorld, q: np.ndarray, *, fcl_free: bool, roboplan_free: bool) -> Diagnosis:
    """Measure and classify one disagreement (see `classify`)."""
    hit, rp_pairs = roboplan_pairs(rw, q)
    pairs = meter.colliding(q)
    named = {(m.a, m.b) for m in pairs}
    for pair in rp_pairs:  # a pair roboplan reports that neither library's query puts in contact
        if pair[0] in meter.items and pair[1] in meter.items and meter.ordered(pair) not in named:
            pairs.append(meter.measure(q, meter.ordered(pair)))
    kind = classify(fcl_free=fcl_free, roboplan_free=roboplan_free, roboplan_debug_hit=hit, pairs=pairs)
    return Diagnosis(fcl_free, roboplan_free, rp_pairs, tuple(pairs), kind)
