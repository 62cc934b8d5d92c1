"""`python -m suite bench execution`: are the cans recycled in physics, and how fast is the simulation?

For each variant and grasp source, every planner plans and executes `--scenes` generated scenes
of `--cans` cans (one job per planner and scene, planned in the job's own process). Printed per
planner (`suite.report.summary_execution.execution_table`, as in a run's summary): cans in the bin over all scenes,
and among the scenes whose every problem was planned (the figure that judges execution), where
the others ended, unintended contacts, tracking, slip, and the simulation's real-time factor
(simulated / wall time of the simulation alone; one job per core).

Perceived grasps go through the cameras' sensor model (`--sensor kinect-v1`, or today's Gaussian
`--depth-noise-m`; default: the spec's, a perfect sensor) and each pipeline of `--pipeline`
(`paper`, `robust` or both), one grasp source each; ground-truth grasps are the same for all.
"""

from __future__ import annotations

import argparse
import json
import time

from suite.cli.args import add_noise_arguments, nonneg_float, nonneg_int, positive_int
from suite.execution.execution_records import ExecutionRecord


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--planners", default="ik,rrt,trajopt", help="planners (default ik,rrt,trajopt)")
    p.add_argument("--variants", default="open,wall", help="variants (default open,wall)")
    p.add_argument("--grasps", default="truth,perceived", help="grasp sources (default truth,perceived)")
    p.add_argument("--scenes", type=positive_int, default=10, help="scenes per variant (default 10)")
    p.add_argument("--first-seed", type=nonneg_int, default=0, help="first scene seed (default 0)")
    p.add_argument("--cans", type=positive_int, default=5, help="cans per scene (default 5)")
    p.add_argument("--jobs", type=positive_int, default=2, help="worker processes, one simulation each (default 2)")
    p.add_argument("--reperceive", action="store_true", help="closed loop: perceive and plan after each pick")
    p.add_argument("--sensor", default=None, metavar="NAME",
                   help="perceived grasps: the cameras' sensor model (scenes/sensor.py; kinect-v1: Khoshelham & "
                        "Elberink's structured-light calibration; default: the spec's, a perfect sensor)")
    p.add_argument("--depth-noise-m", type=nonneg_float, default=0.0,
                   help="perceived grasps: Gaussian depth noise sigma in metres, 1%% of pixels dropped, instead of "
                        "--sensor (default 0)")
    add_noise_arguments(p)
    p.add_argument("--pipeline", default="paper", metavar="LIST",
                   help="perceived grasps: perception pipelines, each its own grasp source: paper, robust, "
                        "robust-top, or a list such as paper,robust (default paper)")
    p.add_argument("--segmentation", default="color", metavar="NAME",
                   help="perceived grasps: color (the paper's HSV rule, default) or geometric")
    p.add_argument("--worlds", default="perceived", metavar="LIST",
                   help="perceived grasps: the worlds the planners plan in, each its own source: perceived (built "
                        "from the cameras, default), truth, or truth,perceived; truth grasps plan in the truth")
    p.add_argument("--on-failure", default="skip", choices=("skip", "stop"),
                   help="a can that cannot be fully planned: skip it and plan the rest around it (default), or stop")
    p.add_argument("--json", metavar="FILE", default=None, help="also write every execution record to FILE")


def perception_setups(args: argparse.Namespace) -> list:
    """The perceived grasp sources of the arguments, one `PerceptionSetup` per pipeline (raises
    `SuiteError` naming a bad value and what is allowed)."""
    from perception.pipeline import PIPELINES, PerceptionSetup
    from scenes.errors import SuiteError

    names = [n for n in str(args.pipeline).split(",") if n]
    if not names:
        raise SuiteError(f"--pipeline {args.pipeline!r} names no pipeline; allowed: {', '.join(PIPELINES)}")
    if len(set(names)) < len(names):
        raise SuiteError(f"--pipeline {args.pipeline!r} names a pipeline twice")
    return [PerceptionSetup(pipeline=n, segmentation=args.segmentation, sensor=args.sensor or None,
                            depth_noise_m=args.depth_noise_m, correlation_px=args.noise_correlation_px,
                            noise_scale=args.noise_scale) for n in names]


def source_label(grasps: str, setup, world: str = "truth") -> str:
    """A source's name in the printed tables: `truth grasps` or `perceived grasps (robust (top, front,
    back), kinect-v1), perceived world`."""
    return "truth grasps" if setup is None else f"{grasps} grasps ({setup.label()}), {world} world"


def world_list(text: str) -> list[str]:
    """The --worlds list (raises `SuiteError` naming a bad value and what is allowed)."""
    from scenes.errors import SuiteError
    from suite.run.runner import WORLDS

    worlds = [w for w in str(text).split(",") if w]
    bad = [w for w in worlds if w not in WORLDS]
    if not worlds or bad:
        raise SuiteError(f"--worlds {text!r}: {bad[0] if bad else 'no world'}; allowed: {', '.join(WORLDS)}")
    return list(dict.fromkeys(worlds))


def _source(grasps: str | None, perception: dict | None, planned: str) -> tuple:
    """A grasp source as a key: the grasps, the perception setup's JSON and the world planned in."""
    return (grasps, json.dumps(perception, sort_keys=True), planned)


def _source_of(record: ExecutionRecord) -> tuple:
    """The grasp source an execution record was run with (`_source`)."""
    return _source(record.grasps, record.perception, (record.worlds or {}).get("planned", "truth"))


def run(args: argparse.Namespace) -> int:
    from planners.registry import parse_planner_list, planner_class
    from scenes.errors import SuiteError
    from scenes.generate import generate_scene
    from scenes.spec import available_variants, load_spec
    from suite.execution.job_spec import ExecutionJob
    from suite.execution.jobs import run_jobs
    from suite.run.trial import config_dict, make_config

    planners = parse_planner_list(args.planners)
    variants = [v for v in args.variants.split(",") if v]
    for v in variants:
        if v not in available_variants(None):
            raise SuiteError(f"unknown variant {v!r}; allowed: {available_variants(None)}")
    grasp_modes = [g for g in args.grasps.split(",") if g]
    for g in grasp_modes:
        if g not in ("truth", "perceived"):
            raise SuiteError(f"unknown grasp source {g!r}; allowed: truth, perceived")
    setups = perception_setups(args)
    worlds = world_list(args.worlds)
    # every source: (grasps, perception setup or None for the truth, the world planned in)
    sources = [(g, s, w) for g in grasp_modes for s in ((None,) if g == "truth" else setups)
               for w in (("truth",) if g == "truth" else worlds)]
    configs = {p: config_dict(make_config(planner_class(p), None)) for p in planners}
    jobs = []
    for variant in variants:
        spec = load_spec(variant=variant).with_can_count(args.cans)
        for seed in range(args.first_seed, args.first_seed + args.scenes):
            scene = generate_scene(spec, seed=seed)
            for grasps, setup, world in sources:
                for p in planners:
                    jobs.append(ExecutionJob(p, configs[p], scene, grasps, 5.0, seed, reperceive=args.reperceive,
                                             perception=setup, world=world, on_failure=args.on_failure))
    print(f"{len(jobs)} executions ({len(planners)} planners x {len(variants)} variants x {args.scenes} scenes "
          f"x {len(sources)} grasp sources, {args.cans} cans each, on failure {args.on_failure}) on {args.jobs} worker(s)")
    t0 = time.perf_counter()
    records = run_jobs(jobs, workers=args.jobs)
    print(f"done in {time.perf_counter() - t0:.0f} s wall")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"executions": [r.to_json() for r in records]}, f, indent=1)
    from suite.report.summary_execution import execution_table
    from suite.report.summary_perceived import paired_lines, perceived_world_lines

    for variant in variants:
        for grasps, setup, world in sources:
            print(f"\n{variant}, {source_label(grasps, setup, world)}{' (closed loop)' if args.reperceive else ''}:")
            want = _source(grasps, None if setup is None else setup.to_json(), world)
            subset = [r for r in records if r.variant == variant and _source_of(r) == want]
            print(execution_table(subset, planners=planners, tablefmt="simple"))
            if world == "perceived":
                print("\n".join(perceived_world_lines(subset, planners=planners)))
        base = [r for r in records if r.variant == variant and _source_of(r)[0] == "truth"]
        for grasps, setup, world in sources:
            if grasps == "truth" or not base:
                continue
            want = _source(grasps, setup.to_json(), world)
            other = [r for r in records if r.variant == variant and _source_of(r) == want]
            print(f"\n{variant}: {source_label(grasps, setup, world)}, "
                  "cans in the bin per scene (paired against truth grasps in the true world):")
            print("\n".join(paired_lines(base, other, planners=planners)))
            if world == "perceived" and "truth" in worlds:  # the world's own share: same grasps, same order
                same = _source(grasps, setup.to_json(), "truth")
                mid = [r for r in records if r.variant == variant and _source_of(r) == same]
                print(f"\n{variant}: {source_label(grasps, setup, world)}, paired against the same grasps "
                      "in the true world:")
                print("\n".join(paired_lines(mid, other, planners=planners)))
    return 0
