"""Collision-aware inverse kinematics for one gripper pose, on a "plan"-mode Drake scene.

Used to check that generated cans are graspable and to compute the goal configurations every
planner shares. Deterministic: the restarts come from a generator seeded by the caller.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.solvers import SnoptSolver, SolverOptions

#: A comfortable arm configuration with the gripper over the table (Drake's examples' "ready").
Q_READY = np.array([-1.57, 0.1, 0.0, -1.2, 0.0, 1.6, 0.0])


@dataclasses.dataclass(frozen=True)
class IkOptions:
    """Tolerances of a pose IK (metres, radians) and its restarts."""

    position_tolerance_m: float = 1e-3
    orientation_tolerance_rad: float = 1e-2
    min_distance_m: float = 1e-3
    influence_distance_m: float = 0.05
    near_sigmas_rad: tuple[float, ...] = (0.1, 0.25, 0.5)
    restarts: int = 4
    major_iterations: int = 150
    #: The rotation about the world's vertical is free (the gripper's axis that X_WG points
    #: straight down keeps pointing down within the orientation tolerance): a drop over a bin, where
    #: the yaw does not matter.
    free_yaw: bool = False


class PoseIk:
    """Solves gripper-pose IK on one plan-mode `DrakeScene` (built once, solved many times)."""

    def __init__(self, drake_scene) -> None:
        self.plant = drake_scene.plant
        self.diagram = drake_scene.diagram
        self.context = self.diagram.CreateDefaultContext()
        self.plant_context = self.plant.GetMyMutableContextFromRoot(self.context)
        self.G = self.plant.GetFrameByName("body", drake_scene.wsg)
        self.lower = self.plant.GetPositionLowerLimits()
        self.upper = self.plant.GetPositionUpperLimits()
        self.solver = SnoptSolver()

    def solve(
        self,
        X_WG: np.ndarray,
        *,
        q_seed: np.ndarray,
        rng: np.random.Generator,
        options: IkOptions = IkOptions(),
    ) -> np.ndarray | None:
        """A collision-free configuration reaching X_WG, or None.

        Tries q_seed first, then seeds perturbed around it (so that a solution on the same IK
        branch is found when one exists), then `options.restarts` random seeds within the joint
        limits; it stops at the first success of the near seeds, and otherwise keeps the random
        restarts' solution closest to q_seed.
        """
        X = RigidTransform(X_WG)
        solver_options = SolverOptions()
        # A failing solve otherwise grinds on for a second; real solutions come in far fewer.
        solver_options.SetOption(SnoptSolver.id(), "Major iterations limit", options.major_iterations)
        best, best_d = None, np.inf
        q0 = np.asarray(q_seed, float)
        near = [np.clip(q0 + rng.normal(0.0, sigma, 7), self.lower, self.upper) for sigma in options.near_sigmas_rad]
        far = [rng.uniform(self.lower, self.upper) for _ in range(options.restarts)]
        seeds = [q0] + near + far
        n_near = 1 + len(near)
        # One program for all seeds: only the initial guess changes between the solves.
        ik = InverseKinematics(self.plant, self.plant_context)
        q = ik.q()
        tol = np.full(3, options.position_tolerance_m)
        ik.AddPositionConstraint(self.G, np.zeros(3), self.plant.world_frame(),
                                 X.translation() - tol, X.translation() + tol)
        if options.free_yaw:
            down = np.array([0.0, 0.0, -1.0])
            ik.AddAngleBetweenVectorsConstraint(self.plant.world_frame(), down, self.G,
                                                X.rotation().inverse().multiply(down), 0.0,
                                                options.orientation_tolerance_rad)
        else:
            ik.AddOrientationConstraint(self.G, RotationMatrix(), self.plant.world_frame(),
                                        X.rotation(), options.orientation_tolerance_rad)
        ik.AddMinimumDistanceLowerBoundConstraint(options.min_distance_m,
                                                  options.influence_distance_m)
        prog = ik.get_mutable_prog()
        prog.AddQuadraticErrorCost(np.eye(7), np.asarray(q_seed, float), q)
        for i, seed in enumerate(seeds):
            prog.SetInitialGuess(q, seed)
            result = self.solver.Solve(prog, None, solver_options)
            if result.is_success():
                sol = result.GetSolution(q)
                d = float(np.linalg.norm(sol - q_seed))
                if d < best_d:
                    best, best_d = sol, d
                if i < n_near:
                    break  # the seed or a seed near it: on q_seed's branch
        return best


#: The GCS paper's IK recipe (gcs-science-robotics reproduction/prm_comparison/helpers.py): the
#: gripper frame's origin exactly at the target, its orientation within 1 mrad, the cost
#: |q - q0|^2, q0 as the initial guess, no collision constraint, Drake's default solver.
PAPER_ORIENTATION_TOLERANCE_RAD = 1e-3


def paper_ik(drake_scene, X_WG: np.ndarray, q0: np.ndarray) -> np.ndarray | None:
    """The configuration the GCS paper's IK recipe gives for gripper pose X_WG, or None if the
    solver fails. Deterministic (one solve from q0)."""
    from pydrake.solvers import Solve

    plant = drake_scene.plant
    context = plant.CreateDefaultContext()
    G = plant.GetFrameByName("body", drake_scene.wsg)
    X = RigidTransform(np.asarray(X_WG, float))
    ik = InverseKinematics(plant, context)
    q = ik.q()
    p = X.translation()
    ik.AddPositionConstraint(G, np.zeros(3), plant.world_frame(), p, p)
    ik.AddOrientationConstraint(G, RotationMatrix(), plant.world_frame(), X.rotation(),
                                PAPER_ORIENTATION_TOLERANCE_RAD)
    prog = ik.get_mutable_prog()
    q0 = np.asarray(q0, float)
    prog.AddQuadraticErrorCost(np.eye(len(q0)), q0, q)
    prog.SetInitialGuess(q, q0)
    result = Solve(prog)
    return np.asarray(result.GetSolution(q), float) if result.is_success() else None
