"""Problem identity (content hash) and the straight-segment triviality test."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from scenes.errors import SuiteError
from scenes.grasp_rule import truth_grasp
from scenes.identity_rule import LEGACY_RULE
from scenes.scene import CanPose, HeldCan
from suite.problems.cycle import build_problems
from suite.problems.identity import problem_id, straight_line


@pytest.fixture(scope="module")
def cycle(wall_scene):
    return {p.kind: p for p in build_problems(wall_scene, [truth_grasp(wall_scene, wall_scene.cans[0])],
                                              time_limit_s=1.0, seed=5)}


def test_descend_is_trivial_and_the_wall_transit_is_not(cycle):
    down = straight_line(cycle["descend"])
    assert down.trivial and down.collision_fraction == 0.0
    over = straight_line(cycle["transit"])  # straight through the wall
    assert not over.trivial and 0.0 < over.collision_fraction < 1.0
    assert over.length_rad == pytest.approx(np.linalg.norm(cycle["transit"].q_goal - cycle["transit"].q_start))


def test_same_content_same_id_whatever_the_labels(cycle):
    p = cycle["transit"]
    assert problem_id(p) == problem_id(p.with_(can_id=7, kind="return", seed=99, time_limit_s=30.0))


def test_any_change_of_world_or_configuration_changes_the_id(cycle):
    p = cycle["transit"]
    base = problem_id(p)
    q = p.q_goal.copy()
    q[3] += 1e-6
    assert problem_id(p.with_(q_goal=q)) != base
    assert problem_id(p.with_(gripper_opening_m=p.gripper_opening_m + 0.001)) != base
    assert problem_id(p.with_(removed_can_ids=(0, 1))) != base  # another can gone from the plate
    assert problem_id(p.with_(removed_can_ids=())) == base  # the held can is never on the plate anyway
    assert problem_id(p.with_(held=None)) != base
    # a different held can pose in the gripper (another can) misses
    X = p.held.X_GC.copy()
    X[2, 3] += 0.01
    assert problem_id(p.with_(held=type(p.held)(p.held.can, X))) != base


# --- the identity rule: zeros of either sign, and float noise in a zero slot ------------------------


def _noisy_zeros(values, how: str) -> np.ndarray:
    """`values` with every zero entry replaced: its sign flipped ("flip"), or +-1e-17 alternating
    ("tiny"). Non-zero entries are kept as they are."""
    a = np.array(values, float)
    zero = a == 0.0
    if how == "flip":
        a[zero] = np.copysign(0.0, -np.copysign(1.0, a[zero]))
    else:
        a[zero] = 1e-17 * np.where(np.arange(int(zero.sum())) % 2 == 0, 1.0, -1.0)
    return a


class _NoisyCan(CanPose):
    """A can whose pose matrix has its zeros replaced as `_noisy_zeros` does."""

    how: str = "flip"

    def X_WC(self) -> np.ndarray:
        return _noisy_zeros(super().X_WC(), self.how)


def _noisy_problem(p, how: str, monkeypatch):
    """Problem p with every zero of every hashed structure replaced: q_start, q_goal, the held
    can's X_GC, the gripper opening, the cans' X_WC and the obstacles' size_m and X_WO."""
    q0, q1 = p.q_start.copy(), p.q_goal.copy()
    q0[[0, 2]] = 0.0  # zero slots in the configurations (rad)
    q1[[2, 4]] = 0.0
    X_GC = p.held.X_GC.copy()
    X_GC[np.abs(X_GC) < 1e-12] = 0.0  # the pose's float noise as exact zeros
    clean = p.with_(q_start=q0, q_goal=q1, held=HeldCan(p.held.can, X_GC), gripper_opening_m=0.0)
    cans = tuple(_NoisyCan(c.id, c.p_WC_m, c.lying, c.axis_yaw_rad) for c in p.scene.cans)
    for c in cans:
        object.__setattr__(c, "how", how)
    spec_cls = type(p.scene.spec)
    obstacles = spec_cls.obstacles

    def noisy_obstacles(spec):
        return [dataclasses.replace(o, size_m=tuple(_noisy_zeros(o.size_m, how)),
                                    X_WO=tuple(map(tuple, _noisy_zeros(o.X_WO, how)))) for o in obstacles(spec)]

    noisy = clean.with_(q_start=_noisy_zeros(q0, how), q_goal=_noisy_zeros(q1, how),
                        held=HeldCan(p.held.can, _noisy_zeros(X_GC, how)),
                        gripper_opening_m=float(_noisy_zeros([0.0], how)[0]),
                        scene=dataclasses.replace(p.scene, cans=cans))
    return clean, noisy, lambda: monkeypatch.setattr(spec_cls, "obstacles", noisy_obstacles)


@pytest.mark.parametrize("how", ["flip", "tiny"])
def test_the_current_rule_hashes_a_zero_of_either_sign_and_noise_as_zero(cycle, how, monkeypatch):
    from planners.gcs.sets import RegionOptions, problem_hash, world_hash

    p = cycle["transit"]
    clean, noisy, noisy_obstacles = _noisy_problem(p, how, monkeypatch)
    assert sum(np.sum(X == 0.0) for X in (clean.held.X_GC, clean.q_start)) >= 4  # the test has zeros to change
    assert any(np.signbit(np.asarray(noisy.held.X_GC)[np.asarray(clean.held.X_GC) == 0.0])) or how == "tiny"
    options = RegionOptions()
    before = (problem_id(clean), clean.world_key(), world_hash(clean, options), problem_hash(clean))
    # the legacy rule is exact about zeros: the same change moves its id (what the new rule is for)
    legacy = problem_id(clean, rule=LEGACY_RULE)
    noisy_obstacles()
    after = (problem_id(noisy), noisy.world_key(), world_hash(noisy, options), problem_hash(noisy))
    assert after == before
    if how == "flip":
        assert problem_id(noisy, rule=LEGACY_RULE) != legacy


def test_an_unknown_identity_rule_is_one_line_naming_the_known_ones(cycle):
    with pytest.raises(SuiteError, match=r"identity rule 'round8' is unknown; allowed: round9, round9-unsigned-zero"):
        problem_id(cycle["transit"], rule="round8")


def test_the_shipped_dataset_keeps_its_ids_under_its_own_rule():
    from suite.problems import DEFAULT_DATASET
    from suite.problems.dataset import dataset_dir, identity_rule, load_dataset, read_manifest

    ds = load_dataset(f"{DEFAULT_DATASET}:quick")
    rule = identity_rule(read_manifest(dataset_dir(DEFAULT_DATASET)))
    assert rule == LEGACY_RULE  # frozen before rules had names
    assert [problem_id(p, rule=rule) for p in ds.problems] == list(ds.ids)
