"""The compiled checks (`scenes.collision.compiled`) decide exactly as the numpy reference does.

The default run draws a small differential check over every family of recycle-v3 (held cans,
both gripper openings, states past the joint limits); `-m slow` runs it at full size (1,000,000
states and 100,000 motions; also `python -m suite bench kernel`)."""

from __future__ import annotations

import numpy as np
import pytest

from scenes.errors import SuiteError


def _assert_no_disagreement(d):
    assert d.state_disagreements == 0 and d.single_disagreements == 0 and d.motion_disagreements == 0, d.examples
    # the draw is not trivial: both answers occur, for states and for motions
    assert 0.2 < d.free_states / d.states < 0.8
    assert 0.2 < d.free_motions / d.motions < 0.8


def test_a_small_differential_draw_has_no_disagreement():
    from suite.bench.kernel import differential
    from suite.bench.kernel_worlds import draw_worlds

    worlds = draw_worlds()
    families = {f for f, _, _ in worlds}
    assert families == {"clutter", "open", "shelf", "station", "wall", "window"}
    assert any(p.held is not None for _, p, _ in worlds) and any(p.held is None for _, p, _ in worlds)
    assert len({(f, p.held is None, p.gripper_opening_m) for f, p, _ in worlds}) == len(worlds) > 2 * len(families)
    d = differential(states_per_world=600, motions_per_world=150, seed=11)
    _assert_no_disagreement(d)
    assert d.compiled_fcl_calls > 0  # FCL still decides what the spheres and tables leave open


@pytest.mark.slow
def test_the_full_differential_draw_has_no_disagreement():
    from suite.bench.kernel import differential
    from suite.bench.kernel_worlds import draw_worlds

    n = len(draw_worlds())
    d = differential(states_per_world=-(-1_000_000 // n), motions_per_world=-(-100_000 // n), seed=0)
    assert d.states >= 1_000_000 and d.motions >= 100_000
    _assert_no_disagreement(d)


@pytest.fixture(scope="module")
def worlds():
    from scenes.collision.compiled import CompiledWorld
    from scenes.collision.world import CollisionWorld
    from suite.bench.kernel_worlds import draw_worlds

    family, p, points = next(w for w in draw_worlds() if w[0] == "window" and w[1].held is not None)
    kw = dict(gripper_opening_m=p.gripper_opening_m, held=p.held, removed_can_ids=p.removed_can_ids)
    return CollisionWorld(p.scene, **kw), CompiledWorld(p.scene, **kw), points


def test_paths_and_first_collisions_agree(worlds):
    ref, fast, points = worlds
    rng = np.random.default_rng(3)
    for _ in range(40):
        path = points[2:] + rng.normal(size=points[2:].shape) * 0.05
        for r in (0.05, 0.01):
            assert fast.path_free(path, resolution_rad=r) == ref.path_free(path, resolution_rad=r)
            assert fast.motion_free(path[0], path[-1], resolution_rad=r) == ref.motion_free(path[0], path[-1],
                                                                                            resolution_rad=r)


def test_a_state_in_an_undecided_pair_goes_to_fcl_and_is_counted(worlds):
    ref, fast, points = worlds
    rng = np.random.default_rng(5)
    Q = points[rng.integers(len(points), size=400)] + rng.normal(size=(400, 7)) * 0.1
    before = fast.fcl_calls
    assert [fast.is_free(q) for q in Q] == [ref.is_free(q) for q in Q]
    assert fast.fcl_calls > before  # near the witness some spheres overlap and no inner ball decides: FCL does
    assert fast.engine == "compiled" and ref.engine == "numpy"


def test_the_checker_switch(monkeypatch):
    from planners.worlds import CHECKER_ENV, collision_world, planning_world
    from scenes.collision.compiled import CompiledWorld
    from suite.problems.dataset import load_dataset

    p = load_dataset("recycle-v3:quick").problems[0]
    monkeypatch.delenv(CHECKER_ENV, raising=False)
    assert isinstance(planning_world(p), CompiledWorld)
    assert not isinstance(collision_world(p), CompiledWorld)  # the judge keeps the reference
    monkeypatch.setenv(CHECKER_ENV, "numpy")
    assert planning_world(p) is collision_world(p)
    monkeypatch.setenv(CHECKER_ENV, "fortran")
    with pytest.raises(SuiteError, match=r"SUITE_CHECKER='fortran' is not a checker; allowed: compiled, numpy"):
        planning_world(p)


def test_no_writable_cache_directory_means_compiling_in_memory(tmp_path):
    from scenes.collision.kernel_data import cache_dir

    blocked = tmp_path / "file"
    blocked.write_text("")  # a file where a directory should be: not creatable
    assert cache_dir([blocked / "numba"]) is None
    assert cache_dir([blocked / "numba", tmp_path / "ok"]) == tmp_path / "ok"
