"""The GCS paper's own IRIS regions as data, and what they are worth in our world.

Source: RobotLocomotion/gcs-science-robotics at 3d781488 (BSD-3-Clause), file
`data/prm_comparison/IRIS.reg`, added in ab077211 (2023-03-16): the final (Science Robotics)
generation's 9 regions (TS, CS, BS, LB, RB, C, L, R, AS; BS is an exact copy of CS), a Python
pickle of a dict name -> pydrake `HPolyhedron`. The arXiv v1 generation's 8 regions were never
committed (docs/gcs-paper-sources.md, section 7e).

- `convert` decodes that pickle ONCE (`python -m suite paper gcs-arm convert-regions --reg-file
  IRIS.reg`) with a restricted unpickler that builds nothing but numpy arrays and (A, b) records:
  no pydrake and no other code runs. It writes `scenes/datasets/gcs-arm/paper-regions/`:
  `regions.npz` (plain arrays: `names`, and `A_<name>`, `b_<name>` per region, {q : A q <= b}),
  `source.json` (repository, commit, path, the file's git blob id, checked) and the repository's
  `LICENSE.TXT`. No pickle is read at run time (`load_paper_regions` loads with
  allow_pickle=False).
- `paper_region_set` makes them a `planners.gcs.sets.RegionSet` of the gcs-arm world, named by the
  same world hash as `gcs`'s own set at the paper's settings, with its edges computed as the
  paper's code does (`IntersectsWith`, through `planners.gcs.regions.update_edges`) and marked built from the world, so that `gcs`, given its
  directory as `regions_dir` and `build_regions: false`, plans on them.
- `collision_fractions`: uniform samples of each region (hit-and-run) judged by the python-fcl world.
- `linear_gcs`: the paper's `LinearGCS` formulation, written here from its equations on Drake's
  `GraphOfConvexSets` (costs on edges), for its relaxation gap.
"""

from __future__ import annotations

import hashlib
import io
import json
import pickle
from pathlib import Path
from typing import Any

import numpy as np

from scenes.errors import SuiteError

SOURCE = {
    "repository": "RobotLocomotion/gcs-science-robotics",
    "commit": "3d781488136362c700b22db640b0a47806e3e38b",
    "path": "data/prm_comparison/IRIS.reg",
    "added_in": "ab077211170e8fe1ec9a9abf99c55d5d5d4e2f12",
    "git_blob": "3193666af5f36307d2e4d1b45eaa1055d4c11bc3",
    "license": "BSD-3-Clause, Copyright (c) 2023, MIT Robot Locomotion Group (LICENSE.TXT beside this file)",
    "generation": "final (Science Robotics); the arXiv v1 regions were never committed",
}
#: The region names in the file's order.
NAMES = ("TS", "CS", "BS", "LB", "RB", "C", "L", "R", "AS")
PAPER_REGIONS_DIR = Path(__file__).resolve().parents[2] / "scenes" / "datasets" / "gcs-arm" / "paper-regions"
REGIONS_FILE = "regions.npz"


def git_blob_id(data: bytes) -> str:
    """Git's object id of a file's bytes (what `git rev-parse COMMIT:PATH` prints)."""
    return hashlib.sha1(b"blob %d\0" % len(data) + data).hexdigest()


class _HPolyhedronRecord:
    """What the pickle's `pydrake.geometry.optimization.HPolyhedron` objects unpickle to here: their
    state (A, b), nothing else."""

    def __setstate__(self, state) -> None:
        A, b = state[:2] if isinstance(state, tuple) else (state["A"], state["b"])
        self.A, self.b = np.asarray(A, float), np.asarray(b, float)


class _Unpickler(pickle.Unpickler):
    """Builds numpy arrays and `_HPolyhedronRecord`s only; any other global is refused."""

    def find_class(self, module: str, name: str):
        if (module, name) == ("pydrake.geometry.optimization", "HPolyhedron"):
            return _HPolyhedronRecord
        if module in ("numpy.core.multiarray", "numpy._core.multiarray") and name == "_reconstruct":
            from numpy.core.multiarray import _reconstruct  # noqa: PLC0415 (numpy 2 keeps this alias)

            return _reconstruct
        if module == "numpy" and name in ("ndarray", "dtype"):
            return getattr(np, name)
        raise SuiteError(f"IRIS.reg: refusing to unpickle {module}.{name}; allowed: HPolyhedron and numpy arrays")


def convert(data: bytes) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The regions of IRIS.reg's bytes: name -> (A, b).

    Raises:
        SuiteError: not the file of the recorded commit (its git blob id differs), or not 9 regions
            of 7 joints.
    """
    blob = git_blob_id(data)
    if blob != SOURCE["git_blob"]:
        raise SuiteError(f"IRIS.reg has git blob id {blob}; expected {SOURCE['git_blob']} "
                         f"({SOURCE['repository']}@{SOURCE['commit'][:8]}:{SOURCE['path']})")
    import warnings

    with warnings.catch_warnings():  # numpy 2's DeprecationWarning for the numpy.core alias
        warnings.simplefilter("ignore", DeprecationWarning)
        raw = _Unpickler(io.BytesIO(data)).load()
    out = {}
    for name, rec in raw.items():
        if not isinstance(rec, _HPolyhedronRecord) or rec.A.ndim != 2 or rec.A.shape[1] != 7 or rec.b.shape != rec.A.shape[:1]:
            raise SuiteError(f"IRIS.reg: region {name!r} is not a 7-D H-polyhedron")
        out[str(name)] = (rec.A, rec.b)
    if tuple(out) != NAMES:
        raise SuiteError(f"IRIS.reg holds regions {list(out)}; expected {list(NAMES)}")
    return out


def write_paper_regions(data: bytes, license_text: str, out: Path = PAPER_REGIONS_DIR) -> Path:
    """Convert IRIS.reg (`data`) into `out`: regions.npz, source.json and LICENSE.TXT."""
    regions = convert(data)
    out.mkdir(parents=True, exist_ok=True)
    arrays = {"names": np.array(list(regions), dtype="<U8")}
    for name, (A, b) in regions.items():
        arrays[f"A_{name}"], arrays[f"b_{name}"] = A, b
    np.savez_compressed(out / REGIONS_FILE, **arrays)
    (out / "LICENSE.TXT").write_text(license_text)
    info = {**SOURCE, "converted_by": "python -m suite paper gcs-arm convert-regions (suite/paper/paper_regions.py)",
            "regions": {n: {"faces": int(len(b))} for n, (_, b) in regions.items()},
            "note": "BS is an exact copy of CS (same A and b), as in the source file"}
    (out / "source.json").write_text(json.dumps(info, indent=1) + "\n")
    return out / REGIONS_FILE


def load_paper_regions(directory: Path = PAPER_REGIONS_DIR) -> tuple[list[str], list[np.ndarray], list[np.ndarray]]:
    """(names, A, b) of the paper's regions, from plain arrays (no pickle).

    Raises:
        SuiteError: the converted file is missing (run the conversion).
    """
    path = Path(directory) / REGIONS_FILE
    if not path.exists():
        raise SuiteError(f"{path} is missing; convert the paper's IRIS.reg with "
                         "`python -m suite paper gcs-arm convert-regions --reg-file IRIS.reg`")
    with np.load(path, allow_pickle=False) as z:
        names = [str(n) for n in z["names"]]
        return names, [z[f"A_{n}"] for n in names], [z[f"b_{n}"] for n in names]


def paper_region_set(problem, options) -> Any:
    """The paper's regions as the `RegionSet` of `problem`'s world at region options `options`
    (named by `world_hash(problem, options)`, marked built from the world, no build time)."""
    from pydrake.geometry.optimization import HPolyhedron

    from planners.gcs.regions import update_edges
    from planners.gcs.sets import WORLD_BUILT, RegionSet, world_hash

    names, A, b = load_paper_regions()
    # a point of each region: its Chebyshev centre (the file keeps no seeds)
    seeds = [HPolyhedron(a, c).ChebyshevCenter() for a, c in zip(A, b)]
    rs = RegionSet(world_hash(problem, options), list(A), list(b), seeds, [0.0] * len(A), 0.0, [], [], "paper",
                   [WORLD_BUILT], [{"name": n, "source": f"{SOURCE['repository']}@{SOURCE['commit'][:8]}:{SOURCE['path']}"}
                                   for n in names])
    update_edges(rs, 0)  # the paper's `findEdgesViaOverlaps`: both directions of each intersecting pair
    rs.edges.sort()
    return rs


def write_paper_region_set(problem, options, directory: Path) -> Path:
    """`paper_region_set` saved into `directory` (a `regions_dir` for `gcs`)."""
    rs = paper_region_set(problem, options)
    path = Path(directory) / f"{rs.world_hash}.npz"
    rs.save(path)
    return path


def collision_fractions(problem, names: list[str], A: list, b: list, *, samples: int = 2000, mixing_steps: int = 20,
                        seed: int = 0) -> dict[str, dict]:
    """Per region {q : A q <= b}: `samples` uniform samples (Drake's hit-and-run
    `HPolyhedron.UniformSample` from its Chebyshev centre, `mixing_steps` steps apart) judged by
    the python-fcl world of `problem` (the validator's), and how many lie outside our joint limits."""
    from pydrake.common import RandomGenerator
    from pydrake.geometry.optimization import HPolyhedron

    from planners.gcs.solve import uniform_samples
    from planners.worlds import collision_world
    from scenes.robot_model import load_robot

    world = collision_world(problem)
    robot = load_robot(problem.scene.spec.robot)
    lo, hi = robot.lower_rad, robot.upper_rad
    out = {}
    for name, a, c in zip(names, A, b):
        Q = uniform_samples(HPolyhedron(a, c), samples, RandomGenerator(seed), mixing_steps=mixing_steps)
        free = world.states_free(Q)
        outside = ~np.all((Q >= lo - 1e-9) & (Q <= hi + 1e-9), axis=1)
        out[name] = {"samples": len(Q), "collide": int((~free).sum()), "fraction": float((~free).mean()),
                     "outside_limits": int(outside.sum()), "faces": int(len(c))}
    return out


# --- the paper's LinearGCS, from its equations ----------------------------------------------------


def linear_gcs(A: list, b: list, edges: list, start: np.ndarray, goal: np.ndarray, *, max_rounded_paths: int = 10,
               seed: int = 0, preprocessing: bool = True) -> dict[str, Any]:
    """The paper's shortest-path formulation (its `LinearGCS`, section 7f of gcs-paper-sources.md),
    on Drake's `GraphOfConvexSets`, solved with Clarabel:

    - a vertex per region i holding a point x_i in X_i;
    - for each edge (u, v) of `edges`: cost |x_u - x_v|_2 and the constraint x_v in X_u (so the
      segment x_u -> x_v lies in X_u);
    - a source vertex {start}, with an edge to every region holding start and x_v = start on it
      (no cost); a target vertex {goal}, with an edge from every region holding goal, cost |x_u - goal|_2.

    Returns the relaxation's cost (`relaxed_rad`), the rounded cost (`rounded_rad`: Drake's
    randomized rounding, `max_rounded_paths` paths, each re-solved on its fixed path, the cheapest
    kept) and the rounded path's waypoints; `None` costs where start or goal is in no region.
    Costs live on the edges here; `gcs` (GcsTrajectoryOptimization) puts them on the vertices.
    """
    from pydrake.geometry.optimization import GraphOfConvexSets, GraphOfConvexSetsOptions, HPolyhedron, Point
    from pydrake.solvers import Binding, ClarabelSolver, Constraint, Cost, L2NormCost, LinearConstraint

    n = len(start)
    g = GraphOfConvexSets()
    polys = [HPolyhedron(a, c) for a, c in zip(A, b)]
    verts = [g.AddVertex(p, f"r{i}") for i, p in enumerate(polys)]
    length = L2NormCost(np.hstack([-np.eye(n), np.eye(n)]), np.zeros(n))
    for i, j in edges:
        e = g.AddEdge(verts[i], verts[j], f"r{i}->r{j}")
        e.AddCost(Binding[Cost](length, np.concatenate([e.xu(), e.xv()])))
        e.AddConstraint(Binding[Constraint](LinearConstraint(A[i], np.full(len(b[i]), -np.inf), b[i]), e.xv()))
    source, target = g.AddVertex(Point(start), "source"), g.AddVertex(Point(goal), "target")
    out: dict[str, Any] = {"start_regions": [i for i, p in enumerate(polys) if p.PointInSet(start)],
                           "goal_regions": [i for i, p in enumerate(polys) if p.PointInSet(goal)]}
    if not out["start_regions"] or not out["goal_regions"]:
        out.update(relaxed_rad=None, rounded_rad=None)
        return out
    for i in out["start_regions"]:
        e = g.AddEdge(source, verts[i], f"source->r{i}")
        for k in range(n):
            e.AddConstraint(e.xu()[k] == e.xv()[k])
    for i in out["goal_regions"]:
        e = g.AddEdge(verts[i], target, f"r{i}->target")
        e.AddCost(Binding[Cost](length, np.concatenate([e.xu(), e.xv()])))
    opts = GraphOfConvexSetsOptions()
    opts.solver = ClarabelSolver()
    opts.convex_relaxation = True
    opts.preprocessing = preprocessing
    opts.max_rounded_paths = 0
    relaxed = g.SolveShortestPath(source, target, opts)
    out["relaxation_status"] = relaxed.get_solution_result().name
    out["relaxed_rad"] = float(relaxed.get_optimal_cost()) if relaxed.is_success() else None
    opts.max_rounded_paths = max_rounded_paths
    opts.rounding_seed = seed
    rounded = g.SolveShortestPath(source, target, opts)
    out["rounded_status"] = rounded.get_solution_result().name
    if not rounded.is_success():
        out["rounded_rad"] = None
        return out
    out["rounded_rad"] = float(rounded.get_optimal_cost())
    path = g.GetSolutionPath(source, target, rounded)
    names = {v.id(): v.name() for v in g.Vertices()}
    out["region_path"] = [int(names[e.v().id()][1:]) for e in path if e.v().id() != target.id()]
    out["waypoints"] = [start.tolist()] + [rounded.GetSolution(e.xv()).tolist() for e in path[1:]]
    return out
