"""One convex region of the arm's configuration space grown by Drake's sampled IRIS.

`RegionBuilder` holds a world's Drake collision checkers (`make_checker`: the plan-mode Drake scene
of a problem's collision world, `scenes.drake_scene.add_scene_to_plant`, in a
`RobotDiagramBuilder` because the checker needs a `RobotDiagram`: the held can and the finger
opening are part of the robot, removed cans are gone) and grows one region around a seed with
`IrisNp2` (by default) or `IrisZo`, every option set from `RegionOptions` (`iris_options`). What
IRIS did is read from its own log (`iris_log`: iterations and why it stopped) and the region
measured by its inscribed ellipsoid (`inscribed_volume`). How a world's regions are seeded,
checked, connected and cached is `planners.gcs.regions`.
"""

from __future__ import annotations

import contextlib
import logging
import time

import numpy as np

from planners.gcs.sets import RegionOptions
from scenes.errors import SuiteError

log = logging.getLogger(__name__)

#: Regions grown in this process (tests assert that a cached world grows none).
GROWN_IN_PROCESS = 0


@contextlib.contextmanager
def quiet_drake():
    """IrisNp2 logs a warning for every closest-collision program SNOPT fails to solve (a
    routine event it handles); keep them out of the run's output."""
    logger = logging.getLogger("drake")
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        yield
    finally:
        logger.setLevel(level)


#: Drake's log lines of one IRIS call that say why it stopped (IrisNp2 and IrisZo, Drake 1.51,
#: planning/iris/iris_np2.cc and iris_zo.cc), by the reason recorded in `RegionSet.region_iris`.
STOP_MESSAGES = (
    ("iteration limit", "iteration_limit"), ("iter limit", "iteration_limit"),
    ("relative volume change", "relative_threshold"), ("reldelta vol", "relative_threshold"),
    ("volume change", "absolute_threshold"), ("delta vol", "absolute_threshold"),
    ("seed point is no longer", "seed_left_region"), ("initial seed point not contained", "seed_left_region"),
    ("new ellipsoid center", "center_in_collision"),
)


class _IrisLog(logging.Handler):
    """Collects Drake's log lines during one IRIS call (the call runs with `verbose` on)."""

    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.lines: list[str] = []
        self.errors: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        message = record.getMessage()
        self.lines.append(message)
        if record.levelno >= logging.ERROR:
            self.errors.append(message)

    def summary(self) -> dict:
        """{iterations, stop}: the alternations IRIS began and why it stopped (from its own lines)."""
        iterations = sum(line.startswith(("IrisNp2 iteration ", "IrisZo outer iteration ")) for line in self.lines)
        stop = []
        for line in self.lines:
            low = line.lower()
            for needle, reason in STOP_MESSAGES:
                if needle in low:
                    if reason not in stop:
                        stop.append(reason)
                    break
        return {"iterations": iterations, "stop": stop or ["unknown"]}


@contextlib.contextmanager
def iris_log():
    """Capture Drake's log during one IRIS call (nothing is printed; errors are logged here)."""
    logger = logging.getLogger("drake")
    level, propagate = logger.level, logger.propagate
    handler = _IrisLog()
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    logger.propagate = False
    try:
        yield handler
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)
        logger.propagate = propagate
        for message in handler.errors:
            log.error("IRIS: %s", message)


def inscribed_volume(A: np.ndarray, b: np.ndarray) -> dict:
    """The region's maximum inscribed ellipsoid: its volume (rad^7) and the radius (rad) of the
    ball of the same volume; None for both if it cannot be computed."""
    from math import gamma, pi

    from pydrake.geometry.optimization import HPolyhedron

    try:
        volume = float(HPolyhedron(A, b).MaximumVolumeInscribedEllipsoid().CalcVolume())
    except RuntimeError:  # an empty or degenerate region after the cuts
        return {"volume": None, "radius_rad": None}
    n = A.shape[1]
    unit = pi ** (n / 2) / gamma(n / 2 + 1)
    return {"volume": volume, "radius_rad": (volume / unit) ** (1 / n)}


#: IrisNp2's solvers, built once per process (IRIS's options hold a pointer to one).
_NP2_SOLVERS: dict = {}


def iris_options(o: RegionOptions, containment: np.ndarray | None = None):
    """Drake's IRIS options from `o`: every option IRIS reads is set here (none is left to Drake's
    default); `containment` (7, m) are points the region must contain."""
    from pydrake.common import Parallelism
    from pydrake.planning import IrisNp2Options, IrisZoOptions
    from pydrake.solvers import IpoptSolver, SnoptSolver

    opts = IrisNp2Options() if o.iris == "np2" else IrisZoOptions()
    s = opts.sampled_iris_options
    s.num_particles = o.num_particles
    s.epsilon, s.delta, s.tau = o.epsilon, o.delta, o.tau
    s.max_iterations = o.max_iterations
    s.termination_threshold = o.termination_threshold
    s.relative_termination_threshold = o.relative_termination_threshold
    s.max_iterations_separating_planes = o.max_iterations_separating_planes
    s.max_separating_planes_per_iteration = o.max_separating_planes_per_iteration
    s.configuration_space_margin = o.configuration_space_margin_rad
    s.mixing_steps = o.mixing_steps
    s.require_sample_point_is_contained = o.require_sample_point_is_contained
    s.remove_all_collisions_possible = o.remove_all_collisions_possible
    s.relax_margin = o.relax_margin
    s.random_seed = o.random_seed
    s.parallelism = Parallelism(o.threads)
    s.sample_particles_in_parallel = o.sample_particles_in_parallel
    s.verbose = True  # its lines say how many iterations ran and why it stopped (`iris_log`)
    if containment is not None:
        s.containment_points = containment
    if o.iris == "np2":
        opts.sampling_strategy = o.sampling_strategy  # pydrake names the strategies "greedy" and "ray"
        r = opts.ray_sampler_options
        r.ray_search_num_steps = o.ray_search_num_steps
        r.num_particles_to_walk_towards = o.num_particles_to_walk_towards
        r.only_walk_toward_collisions = o.only_walk_toward_collisions
        opts.add_hyperplane_if_solve_fails = o.add_hyperplane_if_solve_fails
        solver = _NP2_SOLVERS.setdefault(o.np2_solver, SnoptSolver() if o.np2_solver == "snopt" else IpoptSolver())
        if not solver.available():
            raise SuiteError(f"gcs np2_solver={o.np2_solver!r} is not available in this Drake build")
        opts.solver = solver  # held in _NP2_SOLVERS: the options keep only a pointer
    else:
        opts.bisection_steps = o.bisection_steps
    return opts


def make_checker(problem, *, padding_m: float, edge_step_rad: float = 0.01):
    """Drake's SceneGraphCollisionChecker on the problem's plan-mode scene."""
    from pydrake.planning import RobotDiagramBuilder, SceneGraphCollisionChecker

    from scenes.drake_scene import add_scene_to_plant

    builder = RobotDiagramBuilder(time_step=0.0)
    iiwa, wsg = add_scene_to_plant(
        builder.plant(), builder.scene_graph(), problem.scene.without_cans(problem.removed_can_ids),
        mode="plan", gripper_opening_m=problem.gripper_opening_m, held=problem.held,
    )
    with quiet_drake():  # its "Allocating contexts ..." info line, once per checker
        return SceneGraphCollisionChecker(
            model=builder.Build(), robot_model_instances=[iiwa, wsg], edge_step_size=edge_step_rad,
            env_collision_padding=padding_m, self_collision_padding=0.0,
        )


class RegionBuilder:
    """Grows the regions of one world (holds its two Drake collision checkers)."""

    def __init__(self, problem, options: RegionOptions):
        from pydrake.geometry.optimization import HPolyhedron

        self.options = options
        self.checkers = [make_checker(problem, padding_m=options.padding_m)]
        if options.padding_m > 0:
            self.checkers.append(make_checker(problem, padding_m=0.0))
        plant = self.checkers[0].plant()
        self.domain = HPolyhedron.MakeBox(plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits())

    def grow(self, q: np.ndarray, *, containment: np.ndarray | None = None, ellipsoid=None):
        """One region around q, or None if q collides in every checker or IRIS fails.

        Args:
            q: the seed (the starting ellipsoid's centre).
            containment: (7, m) configurations the region must contain (their hull must be free).
            ellipsoid: the starting ellipsoid (centred at q); a hypersphere of `seed_radius_rad`
                by default.

        Returns (A, b, seconds, {iterations, stop}: from IRIS's own log). Containment that IRIS
        refuses is dropped and the region grown without it."""
        from pydrake.geometry.optimization import Hyperellipsoid
        from pydrake.planning import IrisNp2, IrisZo

        global GROWN_IN_PROCESS
        o = self.options
        fn = IrisNp2 if o.iris == "np2" else IrisZo
        start = ellipsoid if ellipsoid is not None else Hyperellipsoid.MakeHypersphere(o.seed_radius_rad, q)
        for checker in self.checkers:
            if not checker.CheckConfigCollisionFree(q):
                continue
            for contain in ([None] if containment is None else [containment, None]):
                t0 = time.perf_counter()
                try:
                    with iris_log() as lines:
                        region = fn(checker, start, self.domain, iris_options(self.options, contain))
                except RuntimeError as exc:  # IRIS refuses (e.g. a containment point in collision)
                    log.debug("IRIS failed at %s: %s", q, exc)
                    continue
                GROWN_IN_PROCESS += 1
                region = region.ReduceInequalities()
                return region.A(), region.b(), time.perf_counter() - t0, lines.summary()
        return None

