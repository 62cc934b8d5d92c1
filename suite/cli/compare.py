"""`python -m suite compare`: run every planner on every problem, then table, plots and exports.

The command reads its flags (over a --config file, and a resumed run's manifest) into one
`suite.run.runner.CompareConfig`, every value checked before any work; the run itself is the
runner's (trials), `suite.execution.run_plans`' (physics, with --execute) and `suite.report`'s
(summary, plots, report.html), all with the run directory locked.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime as dt
import sys
import time
from pathlib import Path


from suite.cli.args import nonneg_int, positive_float, positive_int, settings_file
from scenes.errors import SuiteError
from scenes.schema import load
from suite.problems import DEFAULT_TIER
from suite.run.comparison import HOW_IT_RUNS
from suite.run.runner import TRIALS_FILE, CompareConfig, check_planner_configs, recorded_counts

RESULTS_DIR = Path("results")
#: Flags that describe generated scenes (they cannot be combined with --dataset).
GENERATED_FLAGS = ("variant", "scenes", "cans", "grasps", "world")
#: CompareConfig's settings a flag of the same name sets as it is (--planners and --dataset are
#: read apart: a list, and the choice between stored and generated problems).
FLAG_SETTINGS = tuple(f.name for f in dataclasses.fields(CompareConfig)
                      if f.name not in ("planners", "dataset", "planner_configs", "hard_limit_grace_s"))
#: The problems a --moving-bin run plans when no scenes are named: the default tier's open and wall.
DEFAULT_TIER_MOVING = f"{DEFAULT_TIER}:family=open+wall"


def add_arguments(p: argparse.ArgumentParser) -> None:
    d = CompareConfig()
    p.add_argument("--planners", default=None, help=f"comma-separated planner names (default {','.join(d.planners)})")
    p.add_argument("--dataset", default=None, metavar="NAME[:TIER[:FILTERS]]",
                   help=f"run a frozen dataset's stored problems (default {d.dataset}); TIER may be a split (tune, "
                        "test); FILTERS keep some families or kinds, e.g. recycle-v2:test:family=wall,kind=transit "
                        "(the scene flags below select generated scenes instead)")
    p.add_argument("--variant", default=None, help=f"generated scenes of this variant or family (default {d.variant})")
    p.add_argument("--seed", type=nonneg_int, default=None,
                   help=f"run seed, and first scene seed of generated scenes (default {d.seed})")
    p.add_argument("--scenes", type=positive_int, default=None, help=f"number of generated scenes (default {d.scenes})")
    p.add_argument("--cans", type=positive_int, default=None, help=f"cans per generated scene (default {d.cans})")
    p.add_argument("--grasps", choices=("perceived", "truth"), default=None,
                   help=f"generated scenes' grasps from perception or from ground truth (default {d.grasps})")
    p.add_argument("--world", choices=("perceived", "truth"), default=None,
                   help="the world the planners plan in: built from the cameras, or the truth (default: perceived "
                        "with perceived grasps, else truth); the judge and the physics use the truth")
    p.add_argument("--time-limit-s", type=positive_float, default=None,
                   help=f"planning budget per problem, seconds (default {d.time_limit_s})")
    p.add_argument("--budgets", type=budget_list, default=None, metavar="B1,B2,...",
                   help="run every planner at each of these planning budgets (seconds), e.g. 0.05,0.2,1,5: "
                        "success and length against budget (replaces --time-limit-s)")
    p.add_argument("--budget-clock", default=None, metavar="wall|cpu",
                   help=f"the clock the planning budgets run on: wall (elapsed time) or cpu (the CPU time of the "
                        f"trial's worker process: other processes on the machine cannot spend it; the planners that "
                        f"cannot honour it are named in docs/timing.md) (default {d.budget_clock})")
    p.add_argument("--jobs", type=positive_int, default=None,
                   help=f"worker processes, at most one per pending trial (default {d.jobs})")
    p.add_argument("--memory-limit-mb", type=positive_int, default=None,
                   help=f"address-space cap of each worker process, MiB; a trial beyond it is recorded as a crash "
                        f"(out_of_memory) (default {d.memory_limit_mb})")
    p.add_argument("--checker", default=None, choices=("compiled", "numpy"),
                   help=f"what the planners' python-fcl checks run in: the compiled kernels or the numpy reference, "
                        f"the same answers (default {d.checker}); the judge always uses the numpy reference")
    p.add_argument("--out", default=None, help="run directory (default results/<UTC timestamp>)")
    p.add_argument("--resume", action="store_true", help="continue the run in --out, skipping recorded trials")
    p.add_argument("--config", default=None, metavar="YAML", help="settings from a YAML file (flags override it)")
    p.add_argument("--spec", default=None, metavar="YAML", help="scene spec file (default scenes/specs/default.yaml)")
    p.add_argument("--executor", default=None, choices=("local", "dask"), help="where trials run (default local)")
    p.add_argument("--scheduler", default=None, help="Dask scheduler address tcp://HOST:PORT (with --executor dask)")
    p.add_argument("--execute", action="store_true",
                   help="execute each planner's plans in physics (Drake) and count the cans recycled")
    p.add_argument("--reperceive", action="store_true",
                   help="with --execute: closed loop, perceive and plan again after each pick")
    p.add_argument("--moving-bin", type=speed_list, default=None, metavar="V1,V2,...",
                   help="with --execute: a moving bin held by a person (docs/moving-bin.md) at each of these speeds "
                        "(m/s; 0 is the static bin through the same replanning loop), on the run's open and wall "
                        "scenes, instead of the static execution: moving_bin.json and a 'Moving bin' report section "
                        f"(default scenes: {DEFAULT_TIER_MOVING})")
    p.add_argument("--moving-bin-scenes", type=positive_int, default=2, metavar="N",
                   help="with --moving-bin: how many of the run's open and wall scenes (an open, then a wall, ...; "
                        "default 2)")
    p.add_argument("--moving-bin-paths", type=positive_int, default=1, metavar="K",
                   help="with --moving-bin: bin paths per scene, each seeded from the run seed, the scene and its "
                        "index, the same for every planner (default 1)")
    p.add_argument("--moving-bin-scenario", default=None, metavar="YAML",
                   help="with --moving-bin: the scenario's other settings (scenes.moving_bin.MovingBinScenario: "
                        "acceleration, region, estimate latency/rate/noise, drift tolerance, replan deadline, "
                        "latency_mode measured|modelled, release moving|rest, ...)")
    p.add_argument("--no-plots", action="store_true", help="skip drawing the plots")
    p.add_argument("--wide", action="store_true",
                   help="print every metric with its quartiles in the terminal table (about 250 columns)")
    p.add_argument("--no-html", action="store_true", help="skip writing report.html (the one-page report of the run)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def speed_list(text: str) -> tuple[float, ...]:
    """"0,0.05,0.1" -> (0.0, 0.05, 0.1): bin speeds (m/s), non-negative, finite, distinct, ascending."""
    from scenes.schema import NonNeg

    return _number_list(text, tp=NonNeg, not_a="a speed in m/s", each="bin speed {} (m/s)",
                        twice="--moving-bin {} names a speed twice")


def moving_bin_scenario(args: argparse.Namespace, config: CompareConfig):
    """The scenario of --moving-bin (its YAML's settings, every field checked), checked against the
    open and wall stations of the run's spec (region, reach): one SuiteError line before any work."""
    from scenes.moving_bin import MOVING_BIN_FAMILIES, make_scenario
    from scenes.moving_bin_check import check_scenario
    from scenes.spec import load_spec

    if not args.execute:
        raise SuiteError("--moving-bin runs in physics: add --execute")
    if args.reperceive or args.budgets:
        raise SuiteError(f"--moving-bin cannot go with {'--reperceive' if args.reperceive else '--budgets'}: "
                         "run them apart")
    values = {}
    if args.moving_bin_scenario:
        values = settings_file(args.moving_bin_scenario, flag="--moving-bin-scenario")
        if "speed_m_s" in values:
            raise SuiteError(f"--moving-bin-scenario {args.moving_bin_scenario}: field 'speed_m_s' is set by "
                             "--moving-bin")
    where = f"--moving-bin-scenario {args.moving_bin_scenario}: " if args.moving_bin_scenario else "moving bin: "
    scenario = make_scenario(values, where=where)
    if not config.dataset and config.variant not in MOVING_BIN_FAMILIES:
        raise SuiteError(f"a moving bin runs on the {' and '.join(MOVING_BIN_FAMILIES)} families, not --variant "
                         f"{config.variant!r}")
    for family in MOVING_BIN_FAMILIES:
        check_scenario(scenario, load_spec(config.spec, variant=family))
    return scenario


def budget_list(text: str) -> tuple[float, ...]:
    """"0.05,0.2,1,5" -> (0.05, 0.2, 1.0, 5.0): positive, finite, distinct, in ascending order."""
    from scenes.schema import Pos

    return _number_list(text, tp=Pos, not_a="a number of seconds", each="budget {} (seconds)",
                        twice="--budgets {} names a budget twice")


def _number_list(text: str, *, tp, not_a: str, each: str, twice: str) -> tuple[float, ...]:
    """A flag's comma-separated numbers, each allowed by `scenes.schema` type `tp`, distinct, in
    ascending order; `each` and `twice` word the refusals ({} is the bad part, or the whole text)."""
    from scenes.schema import refusal

    values = []
    for part in text.split(","):
        try:
            v = float(part)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{part.strip()!r} in {text!r} is not {not_a}") from None
        why = refusal(tp, v)
        if why is not None:
            raise argparse.ArgumentTypeError(f"{each.format(repr(part.strip()))}: {why}")
        values.append(v)
    if len(set(values)) != len(values):
        raise argparse.ArgumentTypeError(twice.format(repr(text)))
    return tuple(sorted(values))


def resolve_config(args: argparse.Namespace) -> CompareConfig:
    """Defaults < --config file < flags; every value checked before any trial runs."""
    from planners.base import BUDGET_CLOCKS
    from planners.registry import parse_planner_list
    from scenes.spec import available_variants

    values = dataclasses.asdict(CompareConfig())
    given: dict[str, tuple[str, object]] = {}  # setting -> (where it was given, value)
    source = ""
    if args.config:
        from_file = settings_file(args.config, flag="--config")
        values.update(from_file)
        source = f"--config {args.config}: "
        given.update({k: (f"--config {args.config} {k}", v) for k, v in from_file.items()})
    if args.budget_clock is not None and args.budget_clock not in BUDGET_CLOCKS:
        raise SuiteError(f"--budget-clock {args.budget_clock!r}: allowed: {', '.join(BUDGET_CLOCKS)}")
    for key in FLAG_SETTINGS:
        v = getattr(args, key)
        if v is not None:
            values[key] = v
            given[key] = (f"--{key.replace('_', '-')}", v)
    # --seed is also the run seed, so it goes with either; the others describe generated scenes.
    generated = [f"--{k}" for k in GENERATED_FLAGS if getattr(args, k) is not None]
    if args.dataset is not None and generated:
        raise SuiteError(f"--dataset runs stored problems; {generated[0]} selects generated scenes: use one or the other")
    if args.dataset is not None:
        values["dataset"] = args.dataset
        given["dataset"] = ("--dataset", args.dataset)
    elif getattr(args, "moving_bin", None) and not generated and not args.resume and "dataset" not in given:
        values["dataset"] = DEFAULT_TIER_MOVING
    elif generated:
        values["dataset"] = None
        given["dataset"] = (generated[0], None)
    planners = args.planners if args.planners is not None else values["planners"]
    if isinstance(planners, (list, tuple)):
        planners = ",".join(str(p) for p in planners)
    values["planners"] = tuple(parse_planner_list(str(planners)))
    if args.planners is not None:
        given["planners"] = ("--planners", values["planners"])
    if args.budgets and args.time_limit_s is not None:
        raise SuiteError("--budgets sets the planning budgets; --time-limit-s sets one: use one or the other")
    if args.budgets and (args.execute or args.reperceive):
        raise SuiteError("--execute runs one plan per problem; with --budgets there is one per budget: run them apart")
    if args.resume and args.out:
        values = _resumed_settings(Path(args.out), values, given)
    if isinstance(values.get("budgets"), list):  # from a YAML file or a manifest
        values["budgets"] = tuple(float(b) if isinstance(b, int) and not isinstance(b, bool) else b
                                  for b in values["budgets"])
    if isinstance(values["time_limit_s"], int) and not isinstance(values["time_limit_s"], bool):
        values["time_limit_s"] = float(values["time_limit_s"])
    config = load(CompareConfig, values, where=source)
    check_planner_configs(config, source=source)
    if config.dataset:
        from suite.problems.dataset import check_selection

        check_selection(config.dataset)  # a bad tier or filter fails here, before the run starts
    else:
        variants = available_variants(config.spec)
        if config.variant not in variants:
            raise SuiteError(f"unknown variant {config.variant!r}; allowed: {variants}")
        from suite.run.runner import plan_world_for

        plan_world_for(config.grasps, config.world)  # --world perceived needs perceived grasps
    return config


def _resumed_settings(out: Path, values: dict, given: dict[str, tuple[str, object]]) -> dict:
    """The settings of the run being resumed, from its manifest; a setting given now that
    contradicts them is one error line (nothing is appended to a run of another configuration)."""
    from suite.run.manifest import MANIFEST_FILE, read_run_manifest

    path = out / MANIFEST_FILE
    manifest = read_run_manifest(out)  # a newer manifest format is one error line
    if manifest is None:
        return values  # an old run without a manifest: the flags stand (prepare_out checks the rest)
    stored = manifest.get("config")
    if not isinstance(stored, dict):
        raise SuiteError(f"--resume: {path} is not a readable run manifest")
    stored = dict(stored)
    stored.setdefault("dataset", None)  # runs made before datasets generated their scenes
    # how the run executes may change on resume (the records do not depend on it); what it runs may not
    for key in HOW_IT_RUNS:
        if key in given:
            stored.pop(key, None)
    resumed = {**values, **{k: v for k, v in stored.items() if k in values}}
    resumed["planners"] = tuple(resumed["planners"])

    def same(a, b) -> bool:
        if isinstance(a, (list, tuple)) or isinstance(b, (list, tuple)):
            return list(a or []) == list(b or [])
        if isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
            return float(a) == float(b)
        return a == b

    for key, (where, value) in given.items():
        if key in stored and not same(value, stored[key]):
            shown = ",".join(value) if isinstance(value, tuple) else value
            raise SuiteError(f"--resume: {where} {shown!r} contradicts the run's {key} = {stored[key]!r} "
                             f"({path}); resume without it, or start a new run with another --out")
    return resumed


def run_dir(args: argparse.Namespace) -> Path:
    """The run directory: --out, or with --resume the interrupted run's (it must name one), else a
    new one under results/ named by the time. What it holds is checked once it is locked
    (`suite.run.comparison.run_comparison`)."""
    if args.resume:
        if not args.out:
            raise SuiteError("--resume needs --out naming the interrupted run's directory")
        out = Path(args.out)
        if not out.is_dir():
            raise SuiteError(f"--resume: {str(out)!r} holds no {TRIALS_FILE} to resume")
        return out
    stamp = dt.datetime.now(dt.timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    return Path(args.out) if args.out else RESULTS_DIR / stamp


def resume_command(out: Path) -> str:
    """The command that continues the run in `out` (its settings come from its manifest)."""
    import shlex

    return shlex.join(["python", "-m", "suite", "compare", "--resume", "--out", str(out)])


def run(args: argparse.Namespace) -> int:
    from suite.run.comparison import run_comparison
    from suite.run.interrupt import Interrupted
    config = resolve_config(args)
    scenario = moving_bin_scenario(args, config) if getattr(args, "moving_bin", None) else None
    out = run_dir(args)
    t0 = time.perf_counter()
    try:
        return run_comparison(config, out=out, command=sys.argv[1:], resume=args.resume,
                              progress_bar=not args.no_progress, resume_hint=resume_command(out),
                              check_trials=None if scenario is None else _moving_bin_trials,
                              then=lambda done: _execute_and_report(args, done, scenario=scenario, t0=t0))
    except Interrupted as exc:
        kept = recorded_counts(out, total=None)["trials_recorded"]  # counted in trials.jsonl itself
        print(f"interrupted by {exc.name}: {kept} trial(s) recorded in {out} are kept; "
              f"resume with: {resume_command(out)}", file=sys.stderr)
        return exc.exit_code


def _moving_bin_trials(trials) -> None:
    if not any(t.problem.scene.variant in ("open", "wall") for t in trials):
        raise SuiteError("--moving-bin runs on open and wall scenes; this run has none (select them, e.g. "
                         f"--dataset {DEFAULT_TIER_MOVING}, or --variant open)")


def _execute_and_report(args: argparse.Namespace, done, *, scenario, t0: float) -> int:
    """After the trials, with the run directory still locked: execution in physics if asked, then
    the report (summary, plots, report.html)."""
    trials, out, config, counts = done.trials, done.out, done.config, done.counts
    if scenario is not None:
        from suite.execution.run_plans import execute_moving_bin

        execute_moving_bin(trials, out, config, speeds=args.moving_bin, scenario=scenario,
                           scenes=args.moving_bin_scenes, paths=args.moving_bin_paths,
                           progress_bar=not args.no_progress)
    elif args.execute or args.reperceive:
        from suite.execution.run_plans import execute_run

        execute_run(trials, out, config, reperceive=args.reperceive, progress_bar=not args.no_progress)
    from suite.report.write import write_report

    table = write_report(out, plots=not args.no_plots, html=not args.no_html, wide=args.wide)
    print(table)
    if not args.no_html:
        from suite.report.html import REPORT_FILE

        print(f"\nreport: {out / REPORT_FILE}")
    print(f"\n{counts['ran']} trials run, {counts['skipped']} already recorded; "
          f"{time.perf_counter() - t0:.1f} s wall; results in {out}", file=sys.stderr)
    return 0
