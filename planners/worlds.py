"""Per-process caches of the collision world and the plan-mode Drake scene of a problem.

Problems cross process boundaries as plain values; each worker builds the heavy objects (Drake
diagrams, python-fcl objects) once per distinct world and reuses them.
"""

from __future__ import annotations

import contextlib

from scenes.fcl_world import CollisionWorld

_FCL: dict[tuple, CollisionWorld] = {}
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
    """The python-fcl world of a problem (robot with held can, remaining cans, opening)."""
    key = (problem.world_key(), _PADDING_M)
    world = _FCL.get(key)
    if world is None:
        world = remember(_FCL, key, CollisionWorld(
            problem.scene,
            gripper_opening_m=problem.gripper_opening_m,
            held=problem.held,
            removed_can_ids=problem.removed_can_ids,
            padding_m=_PADDING_M,
        ))
    return world


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
