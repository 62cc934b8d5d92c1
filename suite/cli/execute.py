"""`python -m suite execute`: plan one scene with one planner and execute it in physics."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from scenes.errors import SuiteError
from suite.cli.args import add_planning_arguments, nonneg_float, positive_float, scene_from_args, settings_file


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_planning_arguments(p)
    p.add_argument("--reperceive", action="store_true",
                   help="closed loop: render, perceive and plan the next can after each pick")
    p.add_argument("--on-failure", default="skip", choices=("skip", "stop"),
                   help="a can that cannot be fully planned: skip it and plan the rest around it (default), or stop")
    p.add_argument("--out", required=True, help="directory for execution.json and replay_<planner>.html")
    p.add_argument("--no-replay", action="store_true", help="do not record the Meshcat replay")
    p.add_argument("--time-step-s", type=positive_float, default=None,
                   help="the simulation's time step (default 0.002)")
    p.add_argument("--contact-model", default=None,
                   help="point or hydroelastic_with_fallback (default: hydroelastic finger pads)")
    p.add_argument("--moving-bin", type=nonneg_float, default=None, metavar="SPEED",
                   help="a moving bin held by a person at this speed (m/s; docs/moving-bin.md), the transit and "
                        "return planned online: DIR/moving_bin.json and DIR/replay_moving_bin_NAME.html")
    p.add_argument("--moving-bin-scenario", default=None, metavar="YAML",
                   help="with --moving-bin: the scenario's other settings (scenes.moving_bin.MovingBinScenario)")


def print_outcomes(records) -> None:
    """One line per execution: where the cans went, contacts, tracking, timing."""
    for r in records:
        if r.error is not None:
            print(f"{r.planner:<10} seed {r.scene_seed:<4} error: {r.error}")
            continue
        clear = "-" if r.clear_time_s is None else f"{r.clear_time_s:.1f} s"
        print(f"{r.planner:<10} seed {r.scene_seed:<4} in bin {r.cans_in_bin}/{r.cans_total}  "
              f"plate {r.cans_on_plate}  elsewhere {r.cans_elsewhere}  collisions {r.collisions}  "
              f"peak tracking {r.peak_tracking_error_rad * 1e3:.1f} mrad  cleared {clear}  "
              f"sim {r.sim_time_s:.1f} s in {r.wall_time_s:.1f} s ({r.real_time_factor:.2f}x real time)"
              + (f"  stopped: {r.stopped}" if r.stopped else ""))


def run(args: argparse.Namespace) -> int:
    from planners.registry import planner_class
    from suite.execution.config import CONTACT_MODELS, ExecutionConfig
    from suite.execution.execution_records import write_execution
    from suite.execution.job_spec import ExecutionJob
    from suite.execution.jobs import run_jobs
    from suite.run.trial import config_dict, make_config

    cls = planner_class(args.planner)  # unknown names fail here, listing the known ones
    overrides = {}
    if args.time_step_s is not None:
        if args.time_step_s > 0.01:
            raise SuiteError(f"--time-step-s must be at most 0.01 for stable grasps, got {args.time_step_s}")
        overrides["time_step_s"] = args.time_step_s
    if args.contact_model is not None:
        if args.contact_model not in CONTACT_MODELS:
            raise SuiteError(f"unknown --contact-model {args.contact_model!r}; allowed: {', '.join(CONTACT_MODELS)}")
        overrides["contact_model"] = args.contact_model
    from suite.run.interrupt import Interrupted, SignalGuard

    out = Path(args.out)
    with SignalGuard():
        try:
            try:
                out.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise SuiteError(f"--out {str(out)!r} cannot be created: {exc.strerror}") from None
            scene = scene_from_args(args)
            if args.moving_bin is not None or args.moving_bin_scenario is not None:
                return _moving_bin(args, scene, out, cls, ExecutionConfig(**overrides))
            job = ExecutionJob(
                planner=args.planner, planner_config=config_dict(make_config(cls, None)), scene=scene,
                grasps=args.grasps, time_limit_s=args.time_limit_s, seed=args.seed, reperceive=args.reperceive,
                on_failure=args.on_failure, replay_path=None if args.no_replay else str(out / f"replay_{args.planner}.html"),
                config=ExecutionConfig(**overrides),
            )
            print(f"planning and executing {len(scene.cans)} can(s) of {scene.variant} seed {scene.seed} "
                  f"with {args.planner}...", file=sys.stderr)
            records = run_jobs([job], workers=1, progress_bar=False)
        except Interrupted as exc:
            print(f"interrupted by {exc.name}: nothing written to {out}", file=sys.stderr)
            return exc.exit_code
    path = write_execution(out, records)
    print_outcomes(records)
    print(f"wrote {path}" + ("" if args.no_replay else f" and {job.replay_path}"), file=sys.stderr)
    return 0 if all(r.error is None for r in records) else 1


def _moving_bin(args: argparse.Namespace, scene, out: Path, cls, config) -> int:
    """`execute --moving-bin SPEED`: plan the scene's approaches, descents and lifts, then run the
    moving-bin loop in physics."""
    from scenes.moving_bin import make_scenario
    from scenes.moving_bin_check import check_scenario
    from suite.execution.execution_records import write_moving_bin
    from suite.execution.jobs import run_jobs
    from suite.execution.moving_bin import plan_scene_job, run_moving_bin_job
    from suite.run.trial import config_dict, make_config

    if args.moving_bin is None:
        raise SuiteError("--moving-bin-scenario needs --moving-bin SPEED")
    if args.reperceive:
        raise SuiteError("--moving-bin cannot go with --reperceive: run them apart")
    values = settings_file(args.moving_bin_scenario, flag="--moving-bin-scenario") if args.moving_bin_scenario else {}
    if "speed_m_s" in values:
        raise SuiteError(f"--moving-bin-scenario {args.moving_bin_scenario}: field 'speed_m_s' is set by --moving-bin")
    where = f"--moving-bin-scenario {args.moving_bin_scenario}: " if args.moving_bin_scenario else "moving bin: "
    scenario = make_scenario({**values, "speed_m_s": args.moving_bin}, where=where)
    check_scenario(scenario, scene.spec)
    replay = None if args.no_replay else str(out / f"replay_moving_bin_{args.planner}.html")
    print(f"planning {len(scene.cans)} can(s) of {scene.variant} seed {scene.seed} with {args.planner}, then the "
          f"moving bin at {args.moving_bin:g} m/s...", file=sys.stderr)
    job = plan_scene_job(scene, scenario, planner=args.planner, planner_config=config_dict(make_config(cls, None)),
                         time_limit_s=args.time_limit_s, seed=args.seed, replay_path=replay, config=config)
    (record,) = run_jobs([job], workers=1, progress_bar=False, run=run_moving_bin_job)
    path = write_moving_bin(out, [record])
    print_moving_bin([record])
    print(f"wrote {path}" + (f" and {replay}" if replay else ""), file=sys.stderr)
    return 0 if record.status != "error" else 1


def print_moving_bin(records) -> None:
    """One line per moving-bin episode."""
    def f(v, fmt):
        return "-" if v is None else format(v, fmt)

    for r in records:
        head = f"{r.planner:<10} seed {r.scene_seed:<4} bin {r.speed_m_s:g} m/s"
        if r.status != "ok":
            print(f"{head}  {r.status}: {r.reason}")
            continue
        print(f"{head}  in bin {r.cans_in_bin}/{r.cans_total}  replans {r.replans} "
              f"(spliced {r.splices}, missed {r.deadline_misses}, failed {r.replan_failures})  "
              f"latency median {f(r.replan_latency_median_s, '.3f')} s p95 {f(r.replan_latency_p95_s, '.3f')} s  "
              f"contacts bin {r.contacts_bin} person {r.contacts_person}  "
              f"grasp-release {f(r.grasp_to_release_median_s, '.2f')} s"
              + (f"  stopped: {r.stopped}" if r.stopped else ""))
