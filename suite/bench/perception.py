"""Speed of the perception pass: `python -m suite bench perception`.

Processing (everything after rendering: crop, mask, components, back-projection, normals,
grasps) is timed per 640x480 top-camera frame; rendering is reported separately, as is the
one-off cost of building the Drake scene with its cameras.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

#: scenes the frames are drawn from (seed, seed+1, ...), and frames rendered per scene
BENCH_SCENES = 5


def add_arguments(p: argparse.ArgumentParser) -> None:
    from suite.cli.args import nonneg_int, positive_int

    p.add_argument("--seed", type=nonneg_int, default=0, help="first scene seed (default 0)")
    p.add_argument("--frames", type=positive_int, default=20, help="frames to time (default 20)")
    p.add_argument("--segmentation", choices=("color", "geometric"), default="color",
                   help="segmentation to time (default color, the paper's)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")


def measure(*, seed: int = 0, frames: int = 20, segmentation: str = "color") -> dict:
    """Time rendering and processing of `frames` top-camera frames from `BENCH_SCENES` scenes.

    Returns:
        Milliseconds: medians and p95 of processing and rendering per frame, and the median
        scene build (Drake diagram with cameras).
    """
    from perception.grasps import PerceptionParams, detect_cans
    from perception.observe import observe
    from scenes.drake_scene import build_drake_scene
    from scenes.generate import generate_scene
    from scenes.spec import load_spec

    spec = load_spec()
    params = PerceptionParams(segmentation=segmentation)
    build_ms, render_ms, process_ms = [], [], []
    per_scene = max(1, -(-frames // BENCH_SCENES))
    done = 0
    for i in range(BENCH_SCENES):
        if done >= frames:
            break
        # Reachability does not change what the camera sees: skip the generator's IK check.
        scene = generate_scene(spec, seed=seed + i, check_reachable=False)
        t0 = time.perf_counter()
        ds = build_drake_scene(scene, mode="sim", cameras=True)
        build_ms.append(1e3 * (time.perf_counter() - t0))
        for _ in range(min(per_scene, frames - done)):
            t0 = time.perf_counter()
            image = observe(scene, cameras=["top"], drake_scene=ds)["top"]
            t1 = time.perf_counter()
            detect_cans(image, spec, params)
            t2 = time.perf_counter()
            render_ms.append(1e3 * (t1 - t0))
            process_ms.append(1e3 * (t2 - t1))
            done += 1
    # The first frame pays for imports and warm caches; it is reported in the max only.
    return {
        "frames": done,
        "segmentation": segmentation,
        "frame_px": [spec.cameras.width_px, spec.cameras.height_px],
        "process_median_ms": round(float(np.median(process_ms[1:] or process_ms)), 2),
        "process_p95_ms": round(float(np.percentile(process_ms[1:] or process_ms, 95)), 2),
        "process_max_ms": round(float(np.max(process_ms)), 2),
        "render_median_ms": round(float(np.median(render_ms[1:] or render_ms)), 2),
        "render_p95_ms": round(float(np.percentile(render_ms[1:] or render_ms, 95)), 2),
        "scene_build_median_ms": round(float(np.median(build_ms)), 1),
    }


def run(args: argparse.Namespace) -> int:
    """Print the perception speed figures (see `measure`)."""
    from scenes.errors import SuiteError

    frames = getattr(args, "frames", 20) or 20
    if frames < 1:
        raise SuiteError(f"--frames must be a positive integer, got {frames}")
    r = measure(seed=getattr(args, "seed", 0) or 0, frames=frames,
                segmentation=getattr(args, "segmentation", "color") or "color")
    if getattr(args, "json", False):
        print(json.dumps({"perception": r}))
        return 0
    w, h = r["frame_px"]
    print(f"perception ({r['segmentation']} segmentation), {r['frames']} top-camera frames of {w}x{h}:")
    print(f"  processing (crop .. grasps): median {r['process_median_ms']:.1f} ms, p95 {r['process_p95_ms']:.1f} ms, "
          f"first/max {r['process_max_ms']:.1f} ms")
    print(f"  rendering (RenderEngineVtk): median {r['render_median_ms']:.1f} ms, p95 {r['render_p95_ms']:.1f} ms")
    print(f"  scene build with cameras: median {r['scene_build_median_ms']:.0f} ms")
    return 0
