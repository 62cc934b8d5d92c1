"""`python -m suite bench collision`: python-fcl state checks against Drake's collision checker.

Both engines answer the same question on the same model, scene and configurations (uniform in
the joint limits), timed side by side in one loop so that machine load hits both alike:
`CollisionWorld.is_free` (forward kinematics + every check) against
`SceneGraphCollisionChecker.CheckConfigCollisionFree` on a plan-mode Drake scene built by the
same `scenes.drake_scene.add_scene_to_plant`.
"""

from __future__ import annotations

import argparse
import logging
import time

import numpy as np

from suite.cli.args import nonneg_int, positive_int

log = logging.getLogger(__name__)

VARIANTS = ("open", "wall")
CONFIG_SEED = 20240611  # the configurations' generator seed (fixed: figures are comparable run to run)


def drake_checker(scene, *, held=None, gripper_opening_m: float | None = None, edge_step_size: float = 0.01):
    """Drake's `SceneGraphCollisionChecker` on the plan-mode scene (positions = the 7 arm joints).

    The checker needs a `RobotDiagram`, so the plant is built by `add_scene_to_plant` (the core
    of `build_drake_scene(scene, mode="plan", cameras=False)`) into a `RobotDiagramBuilder`.
    No padding: it answers exactly "do the shapes touch".
    """
    from pydrake.planning import RobotDiagramBuilder, SceneGraphCollisionChecker

    from scenes.drake_scene import add_scene_to_plant

    builder = RobotDiagramBuilder(time_step=0.0)
    iiwa, wsg = add_scene_to_plant(
        builder.plant(), builder.scene_graph(), scene, mode="plan", gripper_opening_m=gripper_opening_m, held=held
    )
    return SceneGraphCollisionChecker(
        model=builder.Build(),
        robot_model_instances=[iiwa, wsg],
        edge_step_size=edge_step_size,
        env_collision_padding=0.0,
        self_collision_padding=0.0,
    )


def _scene_graph_query(scene):
    """`has_collisions(q)` straight from the plan-mode scene graph (SetPositions, then
    QueryObject.HasCollisions): Drake's leanest single-state route, for reference."""
    from scenes.drake_scene import build_drake_scene

    ds = build_drake_scene(scene, mode="plan", cameras=False)
    context = ds.diagram.CreateDefaultContext()
    plant, plant_context = ds.plant, ds.plant.GetMyContextFromRoot(context)
    port, sg_context = ds.scene_graph.get_query_output_port(), ds.scene_graph.GetMyContextFromRoot(context)

    def has_collisions(q) -> bool:
        plant.SetPositions(plant_context, q)
        return port.Eval(sg_context).HasCollisions()

    return has_collisions


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--configs", type=positive_int, default=2000, help="random configurations per variant (default 2000)")
    p.add_argument("--seed", type=nonneg_int, default=0, help="scene seed (default 0)")
    p.add_argument("--cans", type=nonneg_int, default=5, help="cans on the plate (default 5)")
    p.add_argument("--rounds", type=positive_int, default=3,
                   help="timing rounds; a configuration's time is its fastest round (default 3)")
    p.add_argument("--variants", nargs="+", choices=VARIANTS, default=list(VARIANTS), help="scene variants (default both)")


def _median_us(times_s: list[float]) -> float:
    return float(np.median(times_s)) * 1e6


def _bench_variant(variant: str, args: argparse.Namespace) -> dict:
    from scenes.collision.world import CollisionWorld
    from scenes.generate import generate_scene
    from scenes.spec import load_spec

    scene = generate_scene(load_spec(None, variant=variant).with_can_count(args.cans), seed=args.seed)
    t0 = time.perf_counter()
    world = CollisionWorld(scene)
    build_fcl_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    checker = drake_checker(scene)
    build_drake_s = time.perf_counter() - t0
    has_collisions = _scene_graph_query(scene)
    Q = world.robot.random_configurations(np.random.default_rng(CONFIG_SEED), args.configs)
    for q in Q[:50]:  # warm up all (caches, first-call costs)
        world.is_free(q)
        checker.CheckConfigCollisionFree(q)
        has_collisions(q)

    perf = time.perf_counter
    times = np.empty((args.rounds, len(Q), 3))
    free_fcl, free_drake, free_query = [], [], []
    for r in range(args.rounds):
        for m, q in enumerate(Q):  # interleaved: all see the same machine load (and caches the others left)
            t0 = perf()
            a = world.is_free(q)
            t1 = perf()
            b = checker.CheckConfigCollisionFree(q)
            t2 = perf()
            c = not has_collisions(q)
            t3 = perf()
            times[r, m] = (t1 - t0, t2 - t1, t3 - t2)
            if r == 0:
                free_fcl.append(a)
                free_drake.append(b)
                free_query.append(c)
    free_fcl, free_drake = np.array(free_fcl), np.array(free_drake)
    best = times.min(axis=0)  # per configuration, the least disturbed round
    t_fcl, t_drake, t_query = best.T
    if not np.array_equal(free_query, free_drake):
        log.warning("%s: QueryObject.HasCollisions differs from the collision checker", variant)

    t0 = perf()
    batch = world.states_free(Q)
    batch_fcl_us = (perf() - t0) / len(Q) * 1e6
    t0 = perf()
    batch_drake = np.array(checker.CheckConfigsCollisionFree(Q, parallelize=False))
    batch_drake_us = (perf() - t0) / len(Q) * 1e6
    if not np.array_equal(batch, free_fcl) or not np.array_equal(batch_drake, free_drake):
        log.warning("%s: batched answers differ from single-state answers", variant)

    n_clear = min(len(Q), 300)
    t_clear = []
    for q in Q[:n_clear]:
        t0 = perf()
        world.clearance(q)
        t_clear.append(perf() - t0)

    return {
        "variant": variant,
        "configs": len(Q),
        "free_rate": float(free_fcl.mean()),
        "agreement": float((free_fcl == free_drake).mean()),
        "disagreements": int((free_fcl != free_drake).sum()),
        "fcl_us": _median_us(t_fcl),
        "drake_us": _median_us(t_drake),
        "fcl_first_us": _median_us(times[0, :, 0]),
        "drake_first_us": _median_us(times[0, :, 1]),
        "fcl_free_us": _median_us([t for t, f in zip(t_fcl, free_fcl) if f]),
        "fcl_coll_us": _median_us([t for t, f in zip(t_fcl, free_fcl) if not f]),
        "query_us": _median_us(t_query),
        "batch_fcl_us": batch_fcl_us,
        "batch_drake_us": batch_drake_us,
        "clearance_us": _median_us(t_clear),
        "build_fcl_s": build_fcl_s,
        "build_drake_s": build_drake_s,
    }


def run(args: argparse.Namespace) -> int:
    rows = [_bench_variant(v, args) for v in args.variants]
    print(f"collision state checks: {args.configs} random configurations per variant (uniform in the joint "
          f"limits, seed {CONFIG_SEED}), scene seed {args.seed}, {args.cans} cans; medians over configurations of "
          f"each one's fastest of {args.rounds} rounds (1st pass: the first round alone), all engines interleaved")
    print("  drake us: SceneGraphCollisionChecker.CheckConfigCollisionFree; ratio = fcl / drake; "
          "HasCollisions us: SetPositions + QueryObject.HasCollisions on the plan-mode diagram; "
          "batch: per configuration, states_free vs CheckConfigsCollisionFree (one thread)")
    head = ("variant", "free", "agree", "fcl is_free us", "drake us", "ratio", "1st pass fcl/drake us",
            "fcl free/coll us", "HasCollisions us", "batch fcl/drake us", "clearance us", "build fcl/drake s")
    lines = [head]
    for r in rows:
        lines.append((
            r["variant"], f"{r['free_rate']:.3f}", f"{r['agreement']:.4f} ({r['disagreements']})",
            f"{r['fcl_us']:.1f}", f"{r['drake_us']:.1f}", f"{r['fcl_us'] / r['drake_us']:.2f}",
            f"{r['fcl_first_us']:.1f} / {r['drake_first_us']:.1f}",
            f"{r['fcl_free_us']:.1f} / {r['fcl_coll_us']:.1f}", f"{r['query_us']:.1f}",
            f"{r['batch_fcl_us']:.1f} / {r['batch_drake_us']:.1f}", f"{r['clearance_us']:.1f}",
            f"{r['build_fcl_s']:.3f} / {r['build_drake_s']:.3f}",
        ))
    widths = [max(len(str(line[i])) for line in lines) for i in range(len(head))]
    for line in lines:
        print("  ".join(str(c).rjust(w) for c, w in zip(line, widths)))
    return 0
