"""`perceive --evaluate --sweep DIR`: both pipelines at every noise level of the sweep, on the same
scenes and the same noise draws, one evaluation JSON per run and the noise-sweep figure.

The sweep renders the top camera only, so its robust pipeline runs without its side check (as
`robust-top` does; it logs so once); every JSON names the cameras."""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import time
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)

#: Gaussian depth noise levels (metres), each with 1% of the pixels dropped (today's option)
GAUSSIAN_LEVELS_M = (0.0, 0.001, 0.002, 0.003, 0.004, 0.005, 0.006, 0.008, 0.010)
#: the structured-light model's disparity error, in multiples of Khoshelham & Elberink's (1/2 step)
STRUCTURED_LIGHT_SCALES = (1.0, 2.0, 4.0, 6.0)
#: the pipelines swept (on the top camera's frames alone)
SWEEP_PIPELINES = ("paper", "robust")


def sweep_sensors():
    """(name, sensor or None) of every level of the sweep."""
    from scenes.sensor import SENSOR_PRESETS, SensorSpec

    out = [(f"gaussian-{1e3 * s:g}mm", SensorSpec(kind="gaussian", depth_sigma_m=s) if s > 0 else None)
           for s in GAUSSIAN_LEVELS_M]
    base = SENSOR_PRESETS["kinect-v1"]
    for k in STRUCTURED_LIGHT_SCALES:
        out.append((f"kinect-v1-x{k:g}", base.with_noise(scale=k)))
    return out


def run_sweep(args: argparse.Namespace) -> int:
    from perception.evaluate import aggregate, match_scene
    from perception.grasps import PerceptionParams
    from perception.observe import observe, sense
    from perception.pipeline import GRASP_CAMERA, detect, noise_rng
    from scenes.errors import SuiteError
    from scenes.generate import generate_scene
    from suite.cli.args import spec_from_args
    from suite.report.plots_perception import noise_sweep_figure

    out = Path(args.sweep)
    out.mkdir(parents=True, exist_ok=True)
    spec = spec_from_args(args)
    frames, skipped, seed = [], [], args.seed - 1
    while len(frames) < args.scenes:
        seed += 1
        if len(skipped) > args.scenes:
            raise SuiteError(f"the generator could not draw {len(skipped)} of the scenes from seed {args.seed}")
        try:
            scene = generate_scene(spec, seed=seed)
        except SuiteError as exc:
            log.warning("seed %d skipped: %s", seed, exc)
            skipped.append(seed)
            continue
        frames.append((scene, observe(scene, cameras=[GRASP_CAMERA])[GRASP_CAMERA]))
    plate_z = float(frames[0][1].X_WC[2, 3] - spec.plate_top_z_m)  # the top camera's distance to the plate
    params = PerceptionParams(segmentation=args.segmentation)
    for name, sensor in sweep_sensors():
        for pipeline in SWEEP_PIPELINES:
            matches, records, proc_s = [], [], []
            for scene, clean in frames:
                image = clean if sensor is None else sense(clean, sensor=sensor, rng=noise_rng(scene.seed))
                t0 = time.perf_counter()
                dets, _, _ = detect(image, scene.spec, params=params, pipeline=pipeline)
                proc_s.append(time.perf_counter() - t0)
                m = match_scene(dets, scene)
                matches.append(m)
                records.append(m.record(scene.seed))
            acc = aggregate(matches)
            sigma = 0.0 if sensor is None else sensor.depth_sigma_at_m(plate_z)
            doc = {"variant": spec.variant, "seeds": [args.seed, seed], "segmentation": args.segmentation,
                   "pipeline": pipeline, "cameras": [GRASP_CAMERA], "sensor": name,
                   "sensor_model": None if sensor is None else dataclasses.asdict(sensor),
                   "depth_sigma_at_plate_m": round(sigma, 6), "plate_distance_m": round(plate_z, 4),
                   "skipped_seeds": skipped, "evaluation": acc.to_json(),
                   "timing_s": {"process_median": round(float(np.median(proc_s)), 4)}, "scenes": records}
            (out / f"{pipeline}-{name}.json").write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
            print(f"{pipeline:6s} {name:18s} sigma at plate {1e3 * sigma:4.1f} mm: recall {acc.recall:.3f}, "
                  f"precision {acc.precision:.3f}, xy p95 {acc.xy_error_p95_mm:.2f} mm, yaw p95 "
                  f"{acc.yaw_error_p95_deg:.2f} deg, distractor grasps {acc.distractor_grasps}, "
                  f"{1e3 * np.median(proc_s):.0f} ms/frame", flush=True)
    png = noise_sweep_figure(out, out / "noise_sweep.png")
    print(f"wrote {len(sweep_sensors()) * len(SWEEP_PIPELINES)} evaluations and {png}")
    return 0
