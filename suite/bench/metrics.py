"""Benchmark: TOPP-RA timing plus all metrics of one 50-waypoint path (budget: 30 ms median).

Two fixed 50-waypoint paths in the default scene, both deterministic:
- "smooth": samples of a cubic spline through four via configurations (what trajectory
  optimization returns);
- "polyline": three straight segments between four via configurations, sampled at equal arc
  length with the corners kept (what a sampling planner returns after OMPL's interpolate()).
"""

from __future__ import annotations

import logging
import statistics
import time

import numpy as np
from scipy.interpolate import CubicSpline

from scenes.collision.world import CollisionWorld
from scenes.generate import generate_scene
from scenes.ik import Q_READY
from scenes.spec import load_spec
from suite.scoring.metrics import score

log = logging.getLogger(__name__)

BUDGET_MS = 30.0
N_WAYPOINTS = 50
SCENE_SEED = 1


def bench_paths(n: int = N_WAYPOINTS, *, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """The benchmark's joint paths (n, 7), rad, around the ready configuration."""
    via = Q_READY + rng.uniform(-0.8, 0.8, size=(4, 7))
    smooth = CubicSpline(np.linspace(0.0, 1.0, 4), via)(np.linspace(0.0, 1.0, n))
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(via, axis=0), axis=1))])
    ss = np.union1d(np.linspace(0.0, s[-1], n - 2), s)
    polyline = np.column_stack([np.interp(ss, s, via[:, j]) for j in range(7)])
    return {"smooth": smooth, "polyline": polyline}


def run_bench(repeats: int) -> dict:
    """Time `metrics.score` (TOPP-RA included) on the benchmark paths and print the medians.

    Args:
        repeats: timed calls per path (after one warm-up call).

    Returns:
        {"budget_ms": ..., "paths": {name: {"median_ms" (wall), "cpu_median_ms" (this process's
        CPU time, less sensitive to other load on the machine), "timing_median_ms", "waypoints",
        "metrics"}}, "median_ms": the worst path's wall median, "within_budget": bool}.
    """
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    scene = generate_scene(load_spec(), seed=SCENE_SEED, check_reachable=False)
    world = CollisionWorld(scene)
    paths = bench_paths(rng=np.random.default_rng(SCENE_SEED))
    out: dict = {"budget_ms": BUDGET_MS, "paths": {}}
    for name, path in paths.items():
        X_goal = world.robot.gripper_pose(path[-1])
        metrics = score(path=path, world=world, X_WG_goal=X_goal)  # warm-up
        total, cpu, timing = [], [], []
        for _ in range(repeats):
            t0, c0 = time.perf_counter(), time.process_time()
            metrics = score(path=path, world=world, X_WG_goal=X_goal)
            total.append((time.perf_counter() - t0) * 1e3)
            cpu.append((time.process_time() - c0) * 1e3)
            timing.append(metrics["timing_time_s"] * 1e3)
        out["paths"][name] = {
            "waypoints": len(path),
            "median_ms": statistics.median(total),
            "cpu_median_ms": statistics.median(cpu),
            "timing_median_ms": statistics.median(timing),
            "metrics": metrics,
        }
        print(
            f"metrics bench {name:8s} {len(path)} waypoints: timing + metrics median "
            f"{statistics.median(total):.1f} ms wall, {statistics.median(cpu):.1f} ms CPU "
            f"(TOPP-RA {statistics.median(timing):.1f} ms) over {repeats} runs, "
            f"duration {metrics['duration_s']:.3f} s"
        )
    out["median_ms"] = max(p["median_ms"] for p in out["paths"].values())
    out["within_budget"] = out["median_ms"] <= BUDGET_MS
    print(f"metrics bench: worst median {out['median_ms']:.1f} ms (budget {BUDGET_MS:.0f} ms)")
    return out


if __name__ == "__main__":
    run_bench(20)
