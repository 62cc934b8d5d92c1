"""Per-process caches of the collision worlds and the plan-mode Drake scene of a problem.

Problems cross process boundaries as plain values; each worker builds the heavy objects (Drake
diagrams, python-fcl objects) once per distinct world and reuses them.

Two python-fcl worlds answer the same questions: `collision_world`, the numpy reference, which the
judge (validator, certifier, metrics) uses; and `planning_world`, which the planners check with:
the compiled kernels (`scenes.collision.compiled`) unless the environment's SUITE_CHECKER says
`numpy` (`compare --checker numpy`: the fallback, the same answers at numpy's speed).
"""

from __future__ import annotations

import contextlib
import os

from scenes.errors import SuiteError
from scenes.collision.world import CollisionWorld

#: The planners' checkers (`planning_world`), and the environment variable that chooses one.
CHECKERS = ("compiled", "numpy")
CHECKER_ENV = "SUITE_CHECKER"

_FCL: dict[tuple, CollisionWorld] = {}
_COMPILED: dict[tuple, CollisionWorld] = {}
_DRAKE: dict[tuple, object] = {}
MAX_CACHED = 64


def remember(cache: dict, key, value, *, max_items: int = MAX_CACHED):
    """Store `value` under `key` in a per-process cache, dropping the oldest entry when full."""
    if len(cache) >= max_items:
        cache.pop(next(iter(cache)))
    cache[key] = value
    return value


#: The padding of the worlds `collision_world` gives in this process (`padded_worlds`).
_PADDING_M = 0.0


@contextlib.contextmanager
def padded_worlds(padding_m: float):
    """Within this block `collision_world` gives worlds whose obstacles are grown by padding_m
    (a dataset build searches its witnesses so, to keep them off the obstacles); never in a trial."""
    global _PADDING_M
    before, _PADDING_M = _PADDING_M, float(padding_m)
    try:
        yield
    finally:
        _PADDING_M = before


def collision_world(problem) -> CollisionWorld:
    """The python-fcl world of a problem (robot with held can, remaining cans, opening): the numpy
    reference, the judge's."""
    return _cached_world(_FCL, CollisionWorld, problem)


def _cached_world(cache: dict, cls, problem) -> CollisionWorld:
    """The problem's world of class `cls` from `cache`, built on first use (this process's padding)."""
    key = (problem.world_key(), _PADDING_M)
    world = cache.get(key)
    if world is None:
        world = remember(cache, key, cls(
            problem.scene,
            gripper_opening_m=problem.gripper_opening_m,
            held=problem.held,
            removed_can_ids=problem.removed_can_ids,
            padding_m=_PADDING_M,
        ))
    return world


def checker() -> str:
    """The planners' checker in this process (SUITE_CHECKER, default `compiled`)."""
    name = os.environ.get(CHECKER_ENV) or "compiled"
    if name not in CHECKERS:
        raise SuiteError(f"{CHECKER_ENV}={name!r} is not a checker; allowed: {', '.join(CHECKERS)}")
    return name


def planning_world(problem) -> CollisionWorld:
    """The world the planners check with: the same questions and answers as `collision_world`,
    decided by the compiled kernels (or the numpy world itself when the checker is `numpy`)."""
    if checker() == "numpy":
        return collision_world(problem)
    from scenes.collision.compiled import CompiledWorld

    return _cached_world(_COMPILED, CompiledWorld, problem)


def drake_plan_scene(problem):
    """The plan-mode Drake scene of a problem (its plant's positions are the 7 arm joints)."""
    from scenes.drake_scene import build_drake_scene

    key = problem.world_key()
    ds = _DRAKE.get(key)
    if ds is None:
        scene = problem.scene.without_cans(problem.removed_can_ids)
        ds = remember(_DRAKE, key, build_drake_scene(
            scene, mode="plan", cameras=False, gripper_opening_m=problem.gripper_opening_m, held=problem.held
        ))
    return ds
