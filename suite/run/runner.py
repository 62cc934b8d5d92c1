"""Run orchestration: scenes -> grasps -> problems -> trials -> trials.jsonl (+ manifest).

The parent process prepares the problems, hands trials to an executor, and is the only writer of
trials.jsonl: one line per finished trial, flushed as it finishes, so an interrupted run loses
at most the trials in flight. `resume` skips trials already recorded.
The run's manifest.json (what ran, with which code, how it ended) is `suite.run.manifest`'s.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import sys
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field

from scenes.errors import SuiteError
from scenes.schema import NonNegInt, Pos, PosInt
from suite.problems import DEFAULT_TIER
from suite.run.records import TrialRecord
from suite.run.trial import TrialSpec, config_dict, make_config, make_trial, run_trial

log = logging.getLogger(__name__)

TRIALS_FILE = "trials.jsonl"
#: Grace beyond a trial's time limit before the parent kills its worker (scene building, timing).
HARD_LIMIT_GRACE_S = 30.0
HARD_LIMIT_FACTOR = 3.0
#: Address-space cap of a worker process (MiB). Drake maps much virtual memory it never touches:
#: a worker that ran 60 trials of ik, rrt and trajopt peaked at 0.63 GiB (VmPeak), so 8 GiB
#: stops only a runaway planner.
DEFAULT_MEMORY_LIMIT_MB = 8192


@dataclasses.dataclass(frozen=True)
class CompareConfig:
    """The settings of a comparison run (CLI flags or a YAML file).

    The annotations are the allowed values: `suite.cli.compare` validates every source against
    them with `scenes.schema.load` before any work starts (numbers strictly: no "3" -> 3, no true -> 1).
    """

    planners: tuple[str, ...] = ("ik", "rrt", "trajopt")
    variant: str = "wall"
    seed: NonNegInt = 0
    scenes: PosInt = 4
    cans: PosInt = 3
    grasps: Literal["perceived", "truth"] = "truth"
    time_limit_s: Pos = 5.0
    jobs: PosInt = 2
    spec: str | None = None
    planner_configs: dict[str, dict[str, Any]] = dataclasses.field(default_factory=dict)
    executor: Literal["local", "dask"] = "local"
    scheduler: str | None = None
    hard_limit_grace_s: Pos = HARD_LIMIT_GRACE_S
    #: a frozen dataset `NAME[:TIER]` to run instead of generated scenes (None: generate them from
    #: variant, seed, scenes, cans and grasps)
    dataset: str | None = DEFAULT_TIER
    #: each worker process's address-space cap, MiB (a trial beyond it: `crash`, `out_of_memory`)
    memory_limit_mb: Annotated[int, Field(ge=256)] = DEFAULT_MEMORY_LIMIT_MB
    #: planning budgets (s): every planner runs every problem at each (empty: time_limit_s alone)
    budgets: tuple[Pos, ...] = ()
    #: what the planners' python-fcl checks run in: the compiled kernels, or the numpy reference
    #: (the same answers; `planners.worlds.planning_world`)
    checker: Literal["compiled", "numpy"] = "compiled"
    #: the clock the budgets are measured on: "wall" (elapsed time) or "cpu" (the CPU time of the
    #: trial's worker process, which other processes on the machine cannot take; docs/timing.md
    #: says which planners honour it)
    budget_clock: Literal["wall", "cpu"] = "wall"
    #: the world the planners plan in (None: the perceived one with perceived grasps, else the
    #: truth; `plan_world_for`); the judge and the physics always use the truth
    world: Literal["truth", "perceived"] | None = None


def check_planner_configs(config: CompareConfig, *, source: str = "") -> None:
    """Each planner's settings in `config.planner_configs` checked against its Config dataclass
    (only checked: the values as given go into the trials, so their ids do not change); `source`
    begins the error line (where the settings came from, e.g. "--config FILE: ")."""
    from planners.registry import planner_class
    from scenes.schema import load

    for name, overrides in config.planner_configs.items():
        try:
            cfg_cls = planner_class(name).Config
        except SuiteError as exc:
            raise SuiteError(f"{source}planner_configs.{name}: {exc}") from None
        load(cfg_cls, overrides, where=source, at=f"planner_configs.{name}")


def worker_init() -> None:
    """Runs once in each worker process: quiet logs, OMPL's process-global seed set once, and the
    built-in planners imported up front (while the parent is still preparing problems). A planner
    behind an optional extra (`OPTIONAL`: roboplan adds 0.15 s and 50 MB to a worker) is imported
    by its first trial, outside the clock (`setup_time_s`)."""
    import importlib
    import multiprocessing

    from planners.registry import BUILTIN, OPTIONAL

    if multiprocessing.parent_process() is not None:  # a worker: the parent alone handles Ctrl-C
        from suite.run.interrupt import ignore_signals

        ignore_signals()
    logging.basicConfig(level=logging.WARNING)
    for target in sorted({t for name, t in BUILTIN.items() if name not in OPTIONAL}):
        try:
            importlib.import_module(target.partition(":")[0])
        except ImportError:  # reported by the trial that needs it
            pass
    try:
        from ompl import util as ou

        ou.RNG.setSeed(1)  # per-trial samplers carry the trial's own seed; this only fixes the rest
        ou.setLogLevel(ou.LOG_WARN)
    except Exception:  # OMPL missing or already seeded: the trial-level seeding still holds
        pass


@dataclasses.dataclass(frozen=True)
class WorkerInit:
    """A worker's start-up (picklable, and equal by value so a Dask worker keeps one sandbox per
    setting): the memory cap, then `worker_init`."""

    memory_limit_mb: int | None = DEFAULT_MEMORY_LIMIT_MB

    def __call__(self) -> None:
        if self.memory_limit_mb:
            from suite.run.trial import limit_memory

            limit_memory(self.memory_limit_mb)
        worker_init()


def scene_grasps(scene, *, grasps: str, perception=None):
    """The grasps to plan for: ground truth, or perceived from the rendered cameras.

    Args:
        perception: with `grasps="perceived"`, a `perception.pipeline.PerceptionSetup` (pipeline,
            segmentation, sensor model); None: the paper's pipeline on the spec's cameras.
    """
    from scenes.grasp_rule import truth_grasp

    if grasps == "truth":
        return [truth_grasp(scene, c) for c in scene.cans]
    from perception.pipeline import perceive, perceive_with

    if perception is None:
        return [d.grasp for d in perceive(scene).detections]
    return [d.grasp for d in perceive_with(scene, setup=perception).detections]


#: the worlds planners may plan in: the truth, or one built from the cameras (`perception.world`)
WORLDS = ("truth", "perceived")


def plan_world_for(grasps: str, world: str | None) -> str:
    """The world planners plan in: as asked, else the perceived one for perceived grasps (a robot
    plans around what it sees) and the truth for ground-truth grasps."""
    if world is None:
        return "perceived" if grasps == "perceived" else "truth"
    if world not in WORLDS:
        from scenes.errors import SuiteError

        raise SuiteError(f"unknown planning world {world!r}; allowed: {', '.join(WORLDS)}")
    if world == "perceived" and grasps != "perceived":
        from scenes.errors import SuiteError

        raise SuiteError("a perceived planning world needs perceived grasps (--grasps perceived)")
    return world


def scene_task(scene, *, grasps: str, perception=None, world: str | None = None):
    """The grasps to plan for and the world to plan in: (grasps, `perception.world.PerceivedWorld`
    or None for the truth). `world` as `plan_world_for`; a perceived world is built from every camera
    of the spec, through `perception`'s sensor (None: the paper's pipeline on the spec's cameras),
    the arm at Drake's default (out of the plate's view)."""
    if plan_world_for(grasps, world) == "truth":
        return scene_grasps(scene, grasps=grasps, perception=perception), None
    from perception.pipeline import PerceptionSetup, noise_rng
    from perception.world import perceive_world

    detections, seen = perceive_world(scene, setup=perception or PerceptionSetup(), rng=noise_rng(scene.seed))
    return [d.grasp for d in detections], seen


def prepare_trials(config: CompareConfig, *, progress=None) -> list[TrialSpec]:
    """One trial per distinct problem and planner (and budget, with `budgets`): the dataset's stored
    problems, or problems of generated scenes (identical problems kept once, each with its
    identity, triviality and difficulty)."""
    from planners.registry import planner_class

    configs = {}
    for name in config.planners:
        cls = planner_class(name)
        configs[name] = config_dict(make_config(cls, config.planner_configs.get(name)))
    trials = []
    for problem, meta in (_dataset_problems(config) if config.dataset else _generated_problems(config, progress)):
        if config.budget_clock != problem.budget_clock:
            problem = problem.with_(budget_clock=config.budget_clock)
        for budget in config.budgets or (None,):
            at = problem if budget is None else problem.with_(time_limit_s=float(budget))
            for name in config.planners:
                trials.append(make_trial(at, planner=name, planner_config=configs[name], run_seed=config.seed,
                                         meta=meta if budget is None else {**meta, "budget_s": float(budget)}))
    return trials


def _dataset_problems(config: CompareConfig):
    from suite.problems.dataset import load_dataset

    ds = load_dataset(config.dataset, time_limit_s=config.time_limit_s)
    for pid, problem in zip(ds.ids, ds.problems):
        yield problem, ds.meta[pid]


def _generated_problems(config: CompareConfig, progress):
    from scenes.generate import generate_scene
    from scenes.spec import load_spec
    from suite.problems.cycle import build_problems
    from suite.problems.identity import problem_id, straight_line

    spec = load_spec(config.spec, variant=config.variant).with_can_count(config.cans)
    seen: set[str] = set()
    for scene_seed in range(config.seed, config.seed + config.scenes):
        scene = generate_scene(spec, seed=scene_seed)
        grasps, looked = scene_task(scene, grasps=config.grasps, world=config.world)
        for problem in build_problems(scene, grasps, time_limit_s=config.time_limit_s, seed=scene_seed, world=looked):
            meta: dict[str, Any] = {"family": scene.variant, "kind": problem.kind}
            if problem.pre_status is None:
                pid = problem_id(problem)
                if pid in seen:
                    continue  # the same problem again: planned and counted once
                seen.add(pid)
                line = straight_line(problem)
                meta.update(problem_id=pid, trivial=line.trivial, difficulty=round(line.collision_fraction, 6),
                            straight_length_rad=line.length_rad)
            yield problem, meta
        if progress is not None:
            progress(scene_seed)


def failure_record(spec: TrialSpec, status: str, message: str, wall_time_s: float) -> TrialRecord:
    """The record of a trial whose worker crashed or was killed: what was asked (`trial_record`,
    the one record builder) and how it ended."""
    from suite.run.trial import failed_record

    return failed_record(spec, status=status, wall_time_s=wall_time_s, stats={"error": message},
                         reason_code="killed" if status == "killed_timeout" else "crash")


NEWLINE = b"\n"


def recorded_trial_ids(path: Path) -> set[str]:
    """Ids of the trials already in a trials.jsonl; a torn last line is cut off the file.

    Raises:
        SuiteError: a line is not a trial record, or was written by a newer record format.
    """
    from suite.run.formats import RECORD_FORMAT_VERSION, check_version

    if not path.exists():
        return set()
    data = path.read_bytes()
    ids = set()
    good_end = 0
    pos = 0
    for line in data.splitlines(keepends=True):
        pos += len(line)
        if not line.endswith(b"\n"):
            break  # torn: the run was killed while writing it
        try:
            rec = json.loads(line)
            ids.add(rec["trial_id"])
        except (ValueError, KeyError, TypeError):
            raise SuiteError(f"{path}: line {data[:pos].count(NEWLINE)} is not a trial record") from None
        check_version(rec, supported=RECORD_FORMAT_VERSION, what="trial record",
                      where=f"{path} line {data[:pos].count(NEWLINE)}")
        good_end = pos
    if good_end < len(data):
        log.warning("%s: dropping a torn last line (%d bytes)", path, len(data) - good_end)
        with open(path, "r+b") as f:
            f.truncate(good_end)
    return ids


def recorded_counts(out: Path, *, total: int | None) -> dict[str, int | None]:
    """The trials recorded so far in run directory `out` (None if its trials.jsonl cannot be read)
    and `total`, the run's trial count if known, as a stopped run's manifest names them."""
    try:
        recorded = len(recorded_trial_ids(out / TRIALS_FILE))
    except (OSError, SuiteError):
        recorded = None
    return {"trials_recorded": recorded, "trials_total": total}


def make_executor(executor: str, *, jobs: int, scheduler: str | None = None,
                  memory_limit_mb: int | None = DEFAULT_MEMORY_LIMIT_MB):
    """The executor named on the command line ("local" or "dask"); its workers cap their memory
    at `memory_limit_mb` MiB (None: no cap)."""
    from suite.run.executors import LocalExecutor

    init = WorkerInit(memory_limit_mb)
    if executor == "local":
        return LocalExecutor(jobs=jobs, init=init)
    if executor == "dask":
        from suite.run.dask_executor import DaskExecutor

        return DaskExecutor(scheduler=scheduler, n_workers=jobs, init=init)
    raise SuiteError(f"unknown executor {executor!r}; allowed: local, dask")


def run_trials(trials: list[TrialSpec], *, out: Path, jobs: int, executor="local",
               scheduler: str | None = None, progress_bar: bool = True,
               hard_limit_grace_s: float = HARD_LIMIT_GRACE_S) -> dict[str, int]:
    """Run trials not yet recorded in out/trials.jsonl and append their records as they finish.

    `executor` is "local", "dask", or an executor already made by `make_executor` (e.g. started
    early so that its workers import while the problems are prepared).

    Returns:
        Counts: {"total", "skipped", "ran"}.
    """
    from tqdm import tqdm

    from suite.run.executors import Job, cap_workers
    from suite.run.interrupt import critical
    from suite.run.journal import TrialsJournal

    path = out / TRIALS_FILE
    done = recorded_trial_ids(path)
    todo = [t for t in trials if t.trial_id not in done]
    by_key = {t.trial_id: t for t in todo}
    if isinstance(executor, str):
        ex = make_executor(executor, jobs=cap_workers(jobs, len(todo)), scheduler=scheduler)
    else:
        ex = executor
    # Trials of one scene go to the same worker where possible: its cached worlds serve them all.
    # The usually long ones (transit and return, where the arm crosses the workspace) go first, so
    # that the last trials of a run are short ones and no worker idles long at the end.
    todo_ordered = sorted(todo, key=lambda t: t.problem.kind not in ("transit", "return"))
    jobs_ = [Job(t.trial_id, run_trial, t, t.problem.time_limit_s * HARD_LIMIT_FACTOR + hard_limit_grace_s,
                 group=t.problem.scene.key()) for t in todo_ordered]
    bar = tqdm(total=len(trials), initial=len(trials) - len(todo), desc="trials", unit="trial",
               disable=not progress_bar, file=sys.stderr, dynamic_ncols=True)
    written: set[str] = set()
    outcomes = ex.run(jobs_)
    try:
        with TrialsJournal(path) as journal:
            for outcome in outcomes:
                spec = by_key.get(outcome.job.key)
                if spec is None or spec.trial_id in written:  # never write a trial twice
                    log.warning("ignoring a second outcome of trial %s", outcome.job.key)
                    continue
                record = outcome.result if outcome.failure is None else failure_record(
                    spec, outcome.failure, outcome.message, outcome.wall_time_s)
                with critical():  # a signal now waits until the line is whole and on disk
                    journal.append(record)
                written.add(spec.trial_id)
                bar.set_postfix_str(f"{spec.planner} {spec.problem.kind}: {record.status}", refresh=False)
                bar.update(1)
    finally:
        outcomes.close()  # an error or signal stops the workers at once (in-flight trials are rerun on resume)
        bar.close()
    return {"total": len(trials), "skipped": len(trials) - len(todo), "ran": len(written)}
