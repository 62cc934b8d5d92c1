"""Speed of the perception pass: `python -m suite bench perception`.

Processing (everything after rendering: crop, mask, components, back-projection, normals,
grasps) is timed per 640x480 top-camera frame; rendering is reported separately, as is the
one-off cost of building the Drake scene with its cameras.

`--pipeline both` times the paper's and the robust pipeline on the same frames, interleaved (one
frame through each in turn, so a shared machine's load falls on both alike), optionally under a
sensor model (`--sensor`, `--depth-noise-m`), and prints each one's median and their ratio. The
robust pipeline's time includes its side check on the `front` and `back` frames (rendering them is
in the rendering figure).
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

#: scenes the frames are drawn from (seed, seed+1, ...), and frames rendered per scene
BENCH_SCENES = 5


def add_arguments(p: argparse.ArgumentParser) -> None:
    from suite.cli.args import add_noise_arguments, nonneg_int, positive_int

    p.add_argument("--seed", type=nonneg_int, default=0, help="first scene seed (default 0)")
    p.add_argument("--frames", type=positive_int, default=20, help="frames to time (default 20)")
    p.add_argument("--segmentation", choices=("color", "geometric"), default="color",
                   help="segmentation to time (default color, the paper's)")
    p.add_argument("--pipeline", choices=("paper", "robust", "robust-top", "both"), default="paper",
                   help="pipeline to time (default paper); both: the two on the same frames, interleaved, "
                        "and the robust one's median over the paper's")
    p.add_argument("--variant", default=None, help="scene family the frames are drawn from (default: the spec's)")
    p.add_argument("--sensor", choices=("kinect-v1",), default=None,
                   help="time on frames through this sensor model (scenes/sensor.py)")
    p.add_argument("--depth-noise-m", type=float, default=0.0,
                   help="time on frames with this Gaussian depth noise sigma, metres (default 0)")
    add_noise_arguments(p)
    p.add_argument("--repeats", type=positive_int, default=1,
                   help="times each frame goes through each pipeline (the median is over all; default 1)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")


def measure(*, seed: int = 0, frames: int = 20, segmentation: str = "color", pipelines: tuple[str, ...] = ("paper",),
            variant: str | None = None, sensor=None, repeats: int = 1) -> dict:
    """Time rendering and processing of `frames` top-camera frames from `BENCH_SCENES` scenes.

    Args:
        seed, frames, segmentation: the first scene seed, frames to time, the segmentation.
        pipelines: the pipelines timed on every frame, in turn (`perception.pipeline.PIPELINES`).
        variant: the scene family (None: the spec's default).
        sensor: a `scenes.sensor.SensorSpec` the frames go through (None: clean renders).
        repeats: passes of each frame through each pipeline.

    Returns:
        Milliseconds: medians and p95 of processing (the first pipeline's; every pipeline's median
        under `process_median_ms_by_pipeline`) and rendering per frame, and the median scene build
        (Drake diagram with cameras).
    """
    from perception.grasps import PerceptionParams
    from perception.observe import observe, sense
    from perception.pipeline import detect
    from perception.side_view import SIDE_CAMERAS
    from scenes.drake_scene import build_drake_scene
    from scenes.generate import generate_scene
    from scenes.spec import load_spec

    spec = load_spec(variant=variant) if variant else load_spec()
    params = PerceptionParams(segmentation=segmentation)
    build_ms, render_ms = [], []
    by_pipeline: dict[str, list[float]] = {p: [] for p in pipelines}
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
            cams = ["top"] + (list(SIDE_CAMERAS) if "robust" in pipelines else [])  # robust-top: the top only
            images = observe(scene, cameras=cams, drake_scene=ds)
            render_ms.append(1e3 * (time.perf_counter() - t0))
            if sensor is not None:
                rng = np.random.default_rng([scene.seed, done])
                images = {n: sense(im, sensor=sensor, rng=rng) for n, im in images.items()}
            side = {n: im for n, im in images.items() if n in SIDE_CAMERAS}
            for _ in range(repeats):
                for name in pipelines:
                    t1 = time.perf_counter()
                    detect(images["top"], scene.spec, params=params, pipeline=name, side_images=side)
                    by_pipeline[name].append(1e3 * (time.perf_counter() - t1))
            done += 1
    # The first frame pays for imports and warm caches; it is reported in the max only.
    warm = {p: v[repeats:] or v for p, v in by_pipeline.items()}
    med = {p: round(float(np.median(v)), 2) for p, v in warm.items()}
    process_ms = warm[pipelines[0]]
    return {
        "frames": done,
        "segmentation": segmentation,
        "variant": spec.variant,
        "sensor": None if sensor is None else sensor.kind,
        "repeats": repeats,
        "process_median_ms_by_pipeline": med,
        "frame_px": [spec.cameras.width_px, spec.cameras.height_px],
        "process_median_ms": round(float(np.median(process_ms)), 2),
        "process_p95_ms": round(float(np.percentile(process_ms, 95)), 2),
        "process_max_ms": round(float(np.max(by_pipeline[pipelines[0]])), 2),
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
    pipeline = getattr(args, "pipeline", "paper") or "paper"
    pipelines = ("paper", "robust") if pipeline == "both" else (pipeline,)
    sensor_name, noise_m = getattr(args, "sensor", None), getattr(args, "depth_noise_m", 0.0) or 0.0
    if sensor_name and noise_m > 0:
        raise SuiteError(f"--sensor {sensor_name} cannot go with --depth-noise-m {noise_m}: choose one sensor model")
    if noise_m < 0:
        raise SuiteError(f"--depth-noise-m must be >= 0, got {noise_m}")
    sensor = None
    corr, scale = getattr(args, "noise_correlation_px", 0.0) or 0.0, getattr(args, "noise_scale", 1.0) or 1.0
    if (corr > 0 or scale != 1) and not (sensor_name or noise_m > 0):
        raise SuiteError(f"--noise-correlation-px {corr:g} and --noise-scale {scale:g} need a sensor model: "
                         "--sensor NAME or --depth-noise-m M")
    if sensor_name or noise_m > 0:
        from scenes.sensor import SENSOR_PRESETS, SensorSpec

        sensor = SENSOR_PRESETS[sensor_name] if sensor_name else SensorSpec(kind="gaussian", depth_sigma_m=noise_m)
        if corr > 0 or scale != 1:
            sensor = sensor.with_noise(scale=scale, correlation_px=corr)
    r = measure(seed=getattr(args, "seed", 0) or 0, frames=frames,
                segmentation=getattr(args, "segmentation", "color") or "color", pipelines=pipelines,
                variant=getattr(args, "variant", None), sensor=sensor, repeats=getattr(args, "repeats", 1) or 1)
    if getattr(args, "json", False):
        print(json.dumps({"perception": r}))
        return 0
    w, h = r["frame_px"]
    print(f"perception ({r['segmentation']} segmentation), {r['frames']} top-camera frames of {w}x{h}:")
    print(f"  processing (crop .. grasps): median {r['process_median_ms']:.1f} ms, p95 {r['process_p95_ms']:.1f} ms, "
          f"first/max {r['process_max_ms']:.1f} ms")
    med = r["process_median_ms_by_pipeline"]
    if len(med) > 1:
        noise = f"sensor {sensor_name}" if sensor_name else f"Gaussian depth noise {1e3 * noise_m:g} mm"
        print(f"  per pipeline ({r['variant']} scenes, {noise}, {r['repeats']} passes a frame, interleaved): "
              + ", ".join(f"{p} median {v:.1f} ms" for p, v in med.items())
              + f"; robust / paper {med['robust'] / med['paper']:.2f}x")
    print(f"  rendering (RenderEngineVtk): median {r['render_median_ms']:.1f} ms, p95 {r['render_p95_ms']:.1f} ms")
    print(f"  scene build with cameras: median {r['scene_build_median_ms']:.0f} ms")
    return 0
