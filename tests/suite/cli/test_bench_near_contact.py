"""`bench kernel --near-contact`: the certified signed distance that judges the deciders, the
classification of a disagreement, and a tiny draw whose every disagreement lies near contact."""

from __future__ import annotations

import math

import fcl
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from suite.bench.exact_distance import Prim, point_sd, sd_bounds
from suite.bench.near_contact import CONTACT_TOL_M, Bounds, Dispute, near_contact

BOX = Prim("box", (1.0, 1.0, 1.0), np.eye(3), np.zeros(3))  # its top face at z = 0.5


def _lowest_z(kind: str, dims, R: np.ndarray) -> float:
    """The lowest point of a shape turned by R about its centre (its support along -z)."""
    if kind == "box":
        return -float(np.abs(R[2]) @ (np.asarray(dims) / 2))
    r, length = dims
    side = r if kind == "capsule" else r * math.sqrt(max(0.0, 1 - R[2, 2] ** 2))
    return -abs(R[2, 2]) * length / 2 - side


@pytest.mark.parametrize("kind,dims", [("capsule", (0.05, 0.2)), ("cylinder", (0.033, 0.12)), ("box", (0.06, 0.1, 0.16))])
def test_the_bounds_hold_the_exact_distance_to_a_face(kind, dims):
    rng = np.random.default_rng(7)
    for d in (1e-3, 1e-8, 1e-11, -1e-11, -1e-8, -1e-3):
        for _ in range(3):
            R = Rotation.random(random_state=int(rng.integers(1 << 30))).as_matrix()
            p = np.array([*rng.uniform(-0.2, 0.2, 2), 0.5 + d - _lowest_z(kind, dims, R)])
            lo, hi = sd_bounds(Prim(kind, dims, R, p), BOX)
            assert lo - 1e-15 <= d <= hi + 1e-15
            assert abs(lo - d) < 1e-14  # the lower bound is the distance; the upper one proves the side
            assert (hi - lo < 1e-14) if d > 0 else (hi < 0.5 * d)  # overlapping: within a factor 2


def test_the_bounds_decide_where_fcl_collide_does_not():
    """A capsule 1e-8 m into a box: FCL's collide misses it for most turns; the bounds do not."""
    rng = np.random.default_rng(0)
    missed = 0
    for _ in range(10):
        R = Rotation.random(random_state=int(rng.integers(1 << 30))).as_matrix()
        p = np.array([*rng.uniform(-0.2, 0.2, 2), 0.5 - 1e-8 - _lowest_z("capsule", (0.05, 0.2), R)])
        a = fcl.CollisionObject(fcl.Capsule(0.05, 0.2), fcl.Transform(R, p))
        b = fcl.CollisionObject(fcl.Box(1.0, 1.0, 1.0), fcl.Transform())
        missed += not fcl.collide(a, b, fcl.CollisionRequest(), fcl.CollisionResult())
        lo, hi = sd_bounds(Prim("capsule", (0.05, 0.2), R, p), BOX)
        assert lo <= hi + 1e-15 and hi < 0 and abs(lo + 1e-8) < 1e-14  # equal to rounding: deepest at a point
    assert missed >= 5


def test_point_distances_are_signed():
    cyl = Prim("cylinder", (0.1, 0.4), np.eye(3), np.zeros(3))
    assert point_sd(cyl, (0.0, 0.0, 0.0)) == pytest.approx(-0.1)
    assert point_sd(cyl, (0.4, 0.0, 0.5)) == pytest.approx(math.hypot(0.3, 0.3))
    assert point_sd(BOX, (0.5, 0.5, 0.6)) == pytest.approx(0.1)
    assert point_sd(Prim("capsule", (0.1, 0.4), np.eye(3), np.zeros(3)), (0.0, 0.0, 0.35)) == pytest.approx(0.05)


def test_a_disagreement_is_classified_by_its_bounds():
    ans = {"compiled": False, "numpy": True, "fcl": True}
    assert Dispute("state", "open", ans, Bounds(-3e-8, -2e-8)).wrong == ("numpy", "fcl")
    assert Dispute("state", "open", ans, Bounds(2e-9, 2e-9)).wrong == ("compiled",)
    assert Bounds(-1e-14, 1e-14).truth == "contact" and Bounds(-1e-9, 0.0).truth == "unresolved"
    assert Dispute("state", "open", ans, Bounds(-1e-9, 0.0)).wrong == ()  # neither side proved
    assert Bounds(-3e-8, -2e-8).within_m == 3e-8 and Bounds(1e-9, 2e-9).within_m == 2e-9


def test_a_tiny_near_contact_draw_disagrees_only_near_contact():
    from suite.bench.kernel_worlds import draw_worlds

    worlds = [w for w in draw_worlds() if w[0] in ("window", "clutter")][:3]
    nc = near_contact(pairs_per_world=6, brackets_per_world=1, seed=5, worlds=worlds, bracket_sample=3)
    s = nc.summary()
    assert s["boundary_pairs"] >= 15 and s["grazing_motions"] >= 8
    for x in nc.disputes:  # every disagreement is near contact, and the kernel itself is never refuted
        assert x.bounds.within_m < CONTACT_TOL_M and x.bounds.lo_m <= x.bounds.hi_m + 1e-15
        assert not ("compiled" in x.wrong and x.compiled_by == "kernel")
        assert set(x.wrong) <= {k for k, v in x.answers.items() if v != (x.bounds.truth == "free")}
    assert s["max_dispute_within_m"] < CONTACT_TOL_M
    # the bisection reaches the boundary: the ends it certified lie within FCL's tolerance of contact
    assert s["bracket_within_m"]["n"] >= 10 and s["bracket_within_m"]["max"] < CONTACT_TOL_M


def test_a_coarse_bisection_is_refused():
    import argparse

    from scenes.errors import SuiteError
    from suite.bench import kernel

    p = argparse.ArgumentParser()
    kernel.add_arguments(p)
    args = p.parse_args(["--near-contact", "--tol-rad", "1e-5"])
    with pytest.raises(SuiteError, match=r"^--tol-rad 1e-05 is coarser than 1e-6 rad"):
        kernel.run(args)
    args = p.parse_args(["--near-contact", "--families", "open,attic"])
    with pytest.raises(SuiteError, match=r"^--families 'open,attic': recycle-v3.1 has clutter, open, shelf"):
        kernel.run(args)
