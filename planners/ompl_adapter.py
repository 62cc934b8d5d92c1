"""The OMPL side of the joint-space planners: state space, python-fcl motion checks, seeding, path conversion.

The state space is the arm's 7 joints (RealVectorStateSpace with the joint limits). States and
motions are checked by the problem's python-fcl world (`planners.worlds.planning_world`): a state by
`is_free`, a straight motion by `motion_samples_free` over samples at most `resolution_rad` apart
in every joint: the end state and coarse samples first so that a blocked motion is rejected after
few checks, then only the samples their distance bounds do not prove free. With the `certified`
motion check a motion must also be proved free between its samples (`BatchMotionValidator`). `OmplProblem` creates every OMPL object of one solve
and releases them in dependency order.

A motion's samples are n equal steps, n = max(1, ceil(|q1 - q0| / resolution_rad)), in the
largest-joint norm (`linf`, the validator's rule: every joint moves at most `resolution_rad` per
step) or in the joint-space L2 norm (`l2`: roboplan's `hasCollisionsAlongPath` rule, checked
against roboplan 0.7.0; every joint moves at most `resolution_rad` too, and a diagonal motion gets
up to sqrt(7) times as many samples; `motion_steps`).

Randomness: OMPL draws every RNG's seed from one process-global seed generator. A trial restarts
that generator at a seed derived from `problem.seed` and the problem's identity before it creates
any OMPL object, so all of the trial's OMPL randomness (RRT-Connect's StateSampler, the
simplifier's shortcuts, the nearest-neighbour structures) depends on that seed alone, not on the
trials the process ran before. (A custom sampler cannot do this for RRT-Connect: it draws from
`StateSpace::allocStateSampler`, whose allocator the Python bindings do not expose, and the
simplifier has its own RNG.)
"""

from __future__ import annotations

import math
import time

import numpy as np
from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou

from planners.base import PlanningProblem
from scenes.identity_rule import LEGACY_RULE

DOF = 7
#: The norms a motion's sample count may be measured in (`motion_steps`).
RESOLUTION_NORMS = ("linf", "l2")


# --- OMPL process state ----------------------------------------------------------------------------


def set_ompl_log_level(verbose: bool) -> None:
    ou.setLogLevel(ou.LOG_INFO if verbose else ou.LOG_WARN)


def reseed_ompl(seed: int) -> None:
    """Restart OMPL's process-global seed generator at `seed` (1 <= seed < 2**32).

    `RNG::setSeed` reseeds the generator that seeds every RNG created afterwards, also after the
    first RNG exists (OMPL's src/ompl/util/src/RandomNumbers.cpp); it then logs an error because
    RNGs created before keep their streams. Every OMPL object of a trial is created after this
    call, so that message does not apply here and is held back.
    """
    level = ou.getLogLevel()
    ou.setLogLevel(ou.LOG_NONE)
    try:
        ou.RNG.setSeed(int(seed))
    finally:
        ou.setLogLevel(level)


def trial_seed(problem: PlanningProblem) -> int:
    """The OMPL seed (1 <= seed < 2**32) of a problem: its `seed` combined with its identity
    (world, kind, can or free transit's task, start and goal configurations). Its bytes are exact, as `trial_id`'s are,
    and the world's are those of the `round9` rule: the seeds every run so far drew."""
    ident = repr((problem.world_key(rule=LEGACY_RULE), problem.kind, problem.subject)).encode()
    ident += np.asarray(problem.q_start, float).tobytes()
    ident += b"" if problem.q_goal is None else np.asarray(problem.q_goal, float).tobytes()
    words = np.frombuffer(ident + b"\0" * (-len(ident) % 4), dtype=np.uint32)
    state = np.random.SeedSequence([int(problem.seed) & 0xFFFFFFFF, *words.tolist()]).generate_state(1)
    return int(state[0]) or 1


# --- collision checking ----------------------------------------------------------------------------


def motion_steps(d: np.ndarray, resolution_rad: float, norm: str) -> int:
    """The steps n of a straight motion d = q1 - q0 (rad) checked at samples q0 + (i / n) d,
    i = 1..n: max(1, ceil(|d| / resolution_rad)), |d| the largest joint's move (`linf`) or the
    joint-space L2 norm (`l2`, roboplan's rule: `ceil(distance / max_step_size)` steps)."""
    size = float(np.max(np.abs(d))) if norm == "linf" else math.sqrt(float(np.dot(d, d)))
    return max(1, math.ceil(size / resolution_rad))


def joint_resolution_for_steps(d: np.ndarray, n: int, fallback_rad: float) -> float:
    """A joint resolution at which the world's `motion_samples_free` (which counts steps in the
    largest-joint norm: ceil(max_j |d_j| / resolution)) takes exactly `n` steps of motion d:
    max_j |d_j| / (n - 0.5), so that the ceiling lands on n whatever the rounding. `fallback_rad`
    for a motion of zero length (one step whatever the resolution)."""
    big = float(np.max(np.abs(d)))
    return big / (n - 0.5) if big > 0 else fallback_rad


class BatchMotionValidator(ob.MotionValidator):
    """Checks a straight motion in one call to the world (`CollisionWorld.motion_samples_free`:
    batched python-fcl queries, samples proved free by their neighbours' distances skipped)
    instead of one callback per state. The answer is that of checking every sample.

    With `certify`, a motion whose samples are free must also be proved free along its whole
    length by the exact segment check (`scenes.collision.certify`, the judge's certifier on the same
    world and pairs); an `unproved` segment counts as blocked. The start state is taken as valid
    (as OMPL's DiscreteMotionValidator does).

    `norm` is how a motion's samples are counted (`motion_steps`): `linf` (the validator's rule)
    or `l2` (roboplan's). The world counts in the largest-joint norm, so an `l2` motion is handed
    to it at the joint resolution that gives the same n samples (`joint_resolution_for_steps`).

    Attributes:
        motions: motions checked; certified_calls, certify_s: exact segment checks made and their
            seconds (0 without `certify`).
        accepted: with `count_accepted`, the motions that passed so far (`accepted_samples` gives
            their samples): one per tree edge when read at the end of a tree-growing search.
    """

    def __init__(self, si: ob.SpaceInformation, world, resolution_rad: float, *, certify: bool = False,
                 norm: str = "linf", count_accepted: bool = False) -> None:
        super().__init__(si)
        if norm not in RESOLUTION_NORMS:
            raise ValueError(f"norm must be one of {', '.join(RESOLUTION_NORMS)}, got {norm!r}")
        self.world = world
        self.resolution_rad = resolution_rad
        self.certify = certify
        self.norm = norm
        self.motions = 0
        self.certified_calls = 0
        self.certify_s = 0.0
        self.count_accepted = count_accepted
        # the motions that passed: their steps (l2), or their ends, counted only when asked for
        # (`accepted_samples`: the check's own cost stays what it was)
        self._accepted: list = []

    @property
    def accepted(self) -> int:
        return len(self._accepted)

    def accepted_samples(self, count: int | None = None) -> int:
        """The samples (n each, the end state included) of the first `count` motions that passed
        (all of them by default); 0 without `count_accepted`."""
        items = self._accepted[:count]
        if not items:
            return 0
        if self.norm != "linf":
            return int(sum(items))
        d = np.abs(np.array([b for _, b in items]) - np.array([a for a, _ in items])).max(axis=1)
        return int(np.maximum(1, np.ceil(d / self.resolution_rad)).sum())  # `motion_steps`, all at once

    def motion_free(self, a: np.ndarray, b: np.ndarray) -> bool:
        """Whether the straight motion a -> b passes this validator's check."""
        if self.norm == "linf":
            n = None
            free = self.world.motion_samples_free(a, b, resolution_rad=self.resolution_rad)
        else:
            d = b - a
            n = motion_steps(d, self.resolution_rad, self.norm)
            free = self.world.motion_samples_free(
                a, b, resolution_rad=joint_resolution_for_steps(d, n, self.resolution_rad))
        if not free:
            return False
        if self.certify:
            from scenes.collision.certify import CERTIFIED, certifier

            t0 = time.perf_counter()
            verdict = certifier(self.world).certify(np.stack([a, b])).verdict
            self.certified_calls += 1
            self.certify_s += time.perf_counter() - t0
            if verdict != CERTIFIED:
                return False
        if self.count_accepted:
            self._accepted.append((a, b) if n is None else n)
        return True

    def checkMotion(self, s1, s2) -> bool:  # OMPL's name
        self.motions += 1
        return self.motion_free(np.array(s1[0:DOF]), np.array(s2[0:DOF]))


# --- the OMPL objects of one solve -----------------------------------------------------------------


class OmplProblem:
    """Every OMPL object of one solve: the joint space with the world's checks, the start and goal
    states, the problem definition (with the path-length objective if `optimizing`) and, once
    `attach`ed, the planner. `release` frees them in dependency order.

    Attributes:
        space, bounds, si: the state space, its joint limits and its space information.
        validator: the motion validator (its `motions` counts the motions checked).
        start, goal: the allocated start and goal states.
        pdef: the problem definition; objective: its optimization objective or None.
        planner: the attached planner, or None.
    """

    def __init__(self, world, q_start: np.ndarray, q_goal: np.ndarray, *, resolution_rad: float,
                 optimizing: bool, certify: bool = False, norm: str = "linf", count_accepted: bool = False) -> None:
        lo, hi = world.robot.lower_rad, world.robot.upper_rad
        self.space = ob.RealVectorStateSpace(DOF)
        self.bounds = ob.RealVectorBounds(DOF)
        for i in range(DOF):
            self.bounds.setLow(i, float(lo[i]))
            self.bounds.setHigh(i, float(hi[i]))
        self.space.setBounds(self.bounds)
        self.si = ob.SpaceInformation(self.space)
        self.si.setStateValidityChecker(lambda s: world.is_free(np.array(s[0:DOF])))
        self.validator = BatchMotionValidator(self.si, world, resolution_rad, certify=certify, norm=norm,
                                              count_accepted=count_accepted)
        self.si.setMotionValidator(self.validator)
        self.si.setup()
        self.start, self.goal = self.si.allocState(), self.si.allocState()  # freed by their owners when released
        self.start[0:DOF] = [float(v) for v in q_start]
        self.goal[0:DOF] = [float(v) for v in q_goal]
        self.pdef = ob.ProblemDefinition(self.si)
        self.pdef.setStartAndGoalStates(self.start, self.goal)
        self.objective = ob.PathLengthOptimizationObjective(self.si) if optimizing else None
        if self.objective is not None:
            self.pdef.setOptimizationObjective(self.objective)
        self.planner: ob.Planner | None = None

    def attach(self, planner: ob.Planner) -> None:
        """Give `planner` (made on `si`) this problem and set it up."""
        planner.setProblemDefinition(self.pdef)
        planner.setup()
        self.planner = planner

    def release(self) -> None:
        """Release in dependency order: the planner's data and problem, then the problem
        definition, the space information and the space. Drop any paths and simplifier first."""
        self.planner.clear()
        self.pdef.clearSolutionPaths()
        del self.planner, self.objective, self.pdef, self.start, self.goal, self.validator, self.si, self.space, self.bounds


# --- paths -----------------------------------------------------------------------------------------


def drop_collinear(Q: np.ndarray, *, tol_rad: float = 1e-9) -> np.ndarray:
    """The waypoints without those that lie on the straight segment between their neighbours
    (the rope shortcut leaves such states on straight stretches): the same motion."""
    keep = [0]
    for i in range(1, len(Q) - 1):
        a, b, c = Q[keep[-1]], Q[i], Q[i + 1]
        ac = c - a
        t = float(np.dot(b - a, ac) / max(float(np.dot(ac, ac)), 1e-300))
        if not (0.0 <= t <= 1.0 and float(np.max(np.abs(a + t * ac - b))) <= tol_rad):
            keep.append(i)
    keep.append(len(Q) - 1)
    return Q[keep]


def path_array(path: og.PathGeometric) -> np.ndarray:
    """An OMPL geometric path's states as an (N, 7) array (rad)."""
    return np.array([s[0:DOF] for s in path.getStates()], float).reshape(-1, DOF)
