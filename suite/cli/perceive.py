"""`python -m suite perceive`: render the cameras and detect the cans (the paper's Section III)."""

from __future__ import annotations

import argparse
import json
import logging
import sys

import numpy as np

from scenes.sensor import SENSOR_PRESETS
from suite.cli.args import add_noise_arguments, add_scene_arguments, nonneg_float, positive_int, scene_from_args, spec_from_args

log = logging.getLogger(__name__)


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_scene_arguments(p)
    p.add_argument("--json", action="store_true", help="print the detections (and evaluation) as JSON")
    p.add_argument("--images", metavar="DIR", help="write debug images (crops, masks, components, normals, grasps) to DIR")
    p.add_argument("--evaluate", action="store_true", help="match detections to the ground truth and print accuracy")
    p.add_argument("--scenes", type=positive_int, default=1,
                   help="with --evaluate: evaluate N scenes from seed on (seeds the generator cannot draw are "
                        "skipped and named) and print the aggregate (default 1)")
    p.add_argument("--depth-noise-m", type=nonneg_float, default=0.0,
                   help="Gaussian depth noise sigma in metres, with 1%% of depth pixels dropped (default 0)")
    p.add_argument("--segmentation", choices=("color", "geometric"), default="color",
                   help="color: the paper's HSV rule (default); geometric: colour-free RANSAC plane removal")
    p.add_argument("--pipeline", choices=("paper", "robust", "robust-top"), default="paper",
                   help="paper: the seed paper's, top camera (default); robust: denoised depth, robust fits and a "
                        "confidence that refuses unsupported detections, top camera and the side cameras for its "
                        "side check (docs/perception.md); robust-top: the robust pipeline on the top camera alone")
    p.add_argument("--sensor", choices=sorted(SENSOR_PRESETS), default=None,
                   help="the cameras' sensor model (scenes/sensor.py): kinect-v1 is Khoshelham & Elberink's "
                        "structured-light calibration (default: the spec's, a perfect sensor)")
    add_noise_arguments(p)
    p.add_argument("--world-image", metavar="FILE",
                   help="also build the world the planners would plan in from every camera (perception.world) and "
                        "draw it beside the truth to FILE (PNG), with its build time")
    p.add_argument("--sweep", metavar="DIR",
                   help="with --evaluate --scenes N: every pipeline at every noise level of the sweep "
                        "(Gaussian and structured-light), one JSON per run and noise_sweep.png in DIR")


def _params(args: argparse.Namespace):
    from perception.grasps import PerceptionParams

    return PerceptionParams(segmentation=args.segmentation)


def _setup(args: argparse.Namespace):
    """The `PerceptionSetup` of the arguments (raises `SuiteError` naming a bad value)."""
    from perception.pipeline import PerceptionSetup
    from scenes.errors import SuiteError

    if args.sensor is not None and args.depth_noise_m > 0:
        raise SuiteError(f"--sensor {args.sensor} cannot go with --depth-noise-m {args.depth_noise_m}: choose one sensor model")
    corr, scale = getattr(args, "noise_correlation_px", 0.0), getattr(args, "noise_scale", 1.0)
    if (corr > 0 or scale != 1) and args.sensor is None and not args.depth_noise_m > 0:
        raise SuiteError(f"--noise-correlation-px {corr:g} and --noise-scale {scale:g} need a sensor model: "
                         "--sensor NAME or --depth-noise-m M")
    return PerceptionSetup(pipeline=args.pipeline, segmentation=args.segmentation, sensor=args.sensor,
                           depth_noise_m=args.depth_noise_m, correlation_px=corr, noise_scale=scale)


def _sensor(args: argparse.Namespace):
    """The sensor of the arguments: --sensor or --depth-noise-m's Gaussian, correlated and scaled as
    --noise-correlation-px and --noise-scale say (None: the spec's)."""
    return _setup(args).sensor_spec()


def _sensor_fields(args: argparse.Namespace) -> dict:
    """The run's sensor in an evaluation's JSON: its name, and its noise's correlation and scale."""
    setup = _setup(args)
    if setup.sensor_spec() is None:
        return {}
    return {**({"sensor": args.sensor} if args.sensor else {}), "noise_correlation_px": setup.correlation_px,
            "noise_scale": setup.noise_scale}


#: the code an evaluation runs: its JSON names HEAD, "+dirty" when a tracked file of these differs
#: from it (other files of a shared checkout do not change what it computes)
CODE_PATHS = ("perception", "scenes", "suite/cli/perceive.py", "suite/cli/args.py")


def code_commit() -> str | None:
    """HEAD, with "+dirty" when a tracked file of `CODE_PATHS` differs from it (None outside git)."""
    import subprocess
    from pathlib import Path

    here = Path(__file__).resolve().parents[2]
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=here, capture_output=True, text=True, timeout=5,
                              check=False).stdout.strip()
        changed = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", *CODE_PATHS], cwd=here,
                                 capture_output=True, text=True, timeout=10, check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    if not head:
        return None
    return head + "+dirty" if changed.returncode == 0 and changed.stdout.strip() else head


def run(args: argparse.Namespace) -> int:
    from perception.evaluate import aggregate, match_scene
    from perception.pipeline import GRASP_CAMERA, noise_rng, perceive
    from scenes.errors import SuiteError

    if args.scenes > 1 and not args.evaluate:
        raise SuiteError(f"--scenes {args.scenes} needs --evaluate (several scenes are only evaluated)")
    if args.scenes > 1 and (args.images or args.world_image):
        raise SuiteError("--images and --world-image draw one scene; use them without --scenes")
    if args.sweep:
        if not args.evaluate:
            raise SuiteError(f"--sweep {args.sweep} needs --evaluate (a sweep is evaluated against the ground truth)")
        from suite.cli.perceive_sweep import run_sweep

        return run_sweep(args)
    if args.scenes > 1:
        return _run_many(args)

    scene = scene_from_args(args)
    spec = scene.spec
    # noise_rng: the same draws as executions on perceived grasps (`PerceptionSetup`)
    res = perceive(scene, depth_noise_m=args.depth_noise_m, rng=noise_rng(scene.seed), all_cameras=bool(args.images),
                   params=_params(args), pipeline=args.pipeline, sensor=_sensor(args))
    out: dict = {
        "detections": [d.to_json() for d in res.detections],
        "timing_s": {"render": round(res.render_time_s, 4), "process": round(res.process_time_s, 4)},
    }
    acc = None
    on_distractor: dict[int, str] = {}
    if args.evaluate:
        m = match_scene(res.detections, scene)
        acc = aggregate([m])
        on_distractor = dict(m.distractor_grasps)
        out["evaluation"] = acc.to_json()
        out["distractor_grasps"] = m.record(scene.seed)["distractor_grasps"]
    if args.images:
        from perception.debug_images import write_debug_images

        write_debug_images(args.images, frames=res.frames, detections=res.detections, spec=spec,
                           grasp_camera=GRASP_CAMERA, truth=scene.cans)
    if args.json:
        print(json.dumps(out))
        return 0
    if res.plate_noise_m is not None:
        print(f"depth noise measured on the plate: {1e3 * res.plate_noise_m:.2f} mm")
    print(f"scene seed {scene.seed}, variant {scene.variant}: {len(res.detections)} cans detected "
          f"(render {1e3 * res.render_time_s:.0f} ms, process {1e3 * res.process_time_s:.1f} ms)")
    for d in res.detections:
        x, y, z = d.p_WC_m
        kind = f"lying, axis yaw {d.axis_yaw_rad:+.3f} rad" if d.lying else "upright"
        gx, gy, gz = d.grasp.X_WG[:3, 3]
        flag = f"  ON DISTRACTOR {on_distractor[d.id]}" if d.id in on_distractor else ""
        print(f"  can {d.id}: {kind:28s} centre ({x:+.4f}, {y:+.4f}, {z:.4f}) m, grasp at ({gx:+.4f}, {gy:+.4f}, {gz:.4f}) m, {d.n_points} points{flag}")
    if acc is not None:
        for line in acc.lines():
            print("  " + line)
    if args.images:
        print(f"debug images written to {args.images}")
    if args.world_image:
        _world_image(args, scene)
    return 0


def _world_image(args: argparse.Namespace, scene) -> None:
    """Build the scene's perceived world (the same setup and noise draws) and draw it beside the truth."""
    from perception.pipeline import noise_rng
    from perception.world import perceive_world
    from suite.report.plots_perceived_world import perceived_world_figure

    _, world = perceive_world(scene, setup=_setup(args), rng=noise_rng(scene.seed))
    s = world.summary()
    print(f"perceived world: {s['boxes']} voxel boxes ({1e3 * s['voxel_m']:g} mm voxels, {s['voxels']} occupied), "
          f"{s['cans']} cans padded {1e3 * s['can_padding_m']:g} mm, built in {s['build_time_s']:.2f} s; "
          f"drawn to {perceived_world_figure(scene, world, args.world_image)}")


def _run_many(args: argparse.Namespace) -> int:
    """Evaluate `--scenes` scenes from `--seed` on and print the aggregate figures.

    A detection matches a can when their centres are within the can radius in xy; a grasp within
    half a can radius of a distractor's footprint is a grasp on that distractor.
    """
    from perception.evaluate import aggregate, lookalike_lines, match_lookalikes, match_scene
    from perception.pipeline import noise_rng, perceive, side_cameras
    from scenes.errors import SuiteError
    from scenes.generate import generate_scene

    commit = code_commit()  # before the run: the code imported is the code of this moment
    spec = spec_from_args(args)
    sensor = _sensor(args)
    cameras = ("top",) + tuple(c for c in side_cameras(args.pipeline) if c in spec.cameras.poses)
    matches, records, proc_s, render_s, skipped, looks = [], [], [], [], [], []
    seed = args.seed - 1
    while len(matches) < args.scenes:
        seed += 1
        if len(skipped) > args.scenes:
            raise SuiteError(f"the generator could not draw {len(skipped)} of the scenes from seed {args.seed}; "
                             "try fewer cans or a smaller --min-gap-m")
        try:
            scene = generate_scene(spec, seed=seed)
        except SuiteError as exc:  # the generator cannot draw this seed's scene: not perception's failure
            log.warning("seed %d skipped: %s", seed, exc)
            skipped.append(seed)
            continue
        res = perceive(scene, depth_noise_m=args.depth_noise_m, rng=noise_rng(seed), params=_params(args),
                       pipeline=args.pipeline, sensor=sensor)
        m = match_scene(res.detections, scene)
        matches.append(m)
        looks.append(match_lookalikes(res.detections, scene))
        records.append({**m.record(seed), "hourglass_grasps": looks[-1].hourglass_grasps,
                        "dented_grasped": len(looks[-1].dented_xy_error_m),
                        **({} if res.plate_noise_m is None else {"plate_noise_m": round(res.plate_noise_m, 6)})})
        proc_s.append(res.process_time_s)
        render_s.append(res.render_time_s)
        missed = m.n_truth - len(m.pairs)
        extra = m.n_detected - len(m.pairs)
        if missed or extra or not all(m.kind_correct):
            log.info("seed %d: %d missed, %d extra (%d on distractors), %d lying/upright wrong", seed, missed, extra,
                     len(m.distractor_grasps), sum(not k for k in m.kind_correct))
    acc = aggregate(matches)
    timing = {"render_median": round(float(np.median(render_s)), 4), "process_median": round(float(np.median(proc_s)), 4)}
    if args.json:
        print(json.dumps({"variant": spec.variant, "seeds": [args.seed, seed],
                          "depth_noise_m": args.depth_noise_m, "segmentation": args.segmentation,
                          **({"pipeline": args.pipeline} if args.pipeline != "paper" else {}),
                          "cameras": list(cameras), **_sensor_fields(args), "git_commit": commit,
                          "command": " ".join(["python -m suite", *sys.argv[1:]]), "skipped_seeds": skipped,
                          "evaluation": acc.to_json(),
                          **({"lookalikes": lookalike_lines(looks)} if lookalike_lines(looks) else {}), "timing_s": timing,
                          "scenes": records}))
        return 0
    print(f"variant {spec.variant}, seeds {args.seed}..{seed}, {_setup(args).label()}"
          + (f", skipped seeds (no scene) {skipped}" if skipped else ""))
    for line in acc.lines() + lookalike_lines(looks):
        print("  " + line)
    for rec in records:
        if rec["distractor_grasps"]:
            names = ", ".join(g["distractor"] for g in rec["distractor_grasps"])
            print(f"    seed {rec['seed']}: {len(rec['distractor_grasps'])} grasps on distractors ({names})")
    print(f"  median time per scene: render {1e3 * timing['render_median']:.0f} ms, "
          f"process {1e3 * timing['process_median']:.1f} ms")
    return 0
