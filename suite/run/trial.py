"""One trial: a planner on a problem, then the same validation, timing and scoring for all.

`run_trial` is the function every executor runs (in a worker process); it returns the typed
record (`suite.run.records.TrialRecord`) whose JSON the parent appends to trials.jsonl. The record
is built here as that JSON object (`trial_record`, `judge_result`) and typed when it is whole.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import time
import traceback
from typing import Any

import numpy as np

from planners.base import PlanningProblem, PlanResult, PlanStatus
from suite.run.contention import ContentionProbe
from suite.run.records import TrialRecord, reason_code
from suite.scoring.validate import certify_path, over_limit, structure_reason, validate_path

log = logging.getLogger(__name__)

#: The memory cap of this worker process (MiB), once `limit_memory` has set it.
_MEMORY_LIMIT_MB: int | None = None
#: Planners that have already planned in this process: a trial of one of them is warm (its
#: imports, caches and first solve are paid); the first is cold (`record["warm"]`).
_PLANNED: set[str] = set()


def limit_memory(limit_mb: int) -> None:
    """Cap this process's address space (RLIMIT_AS) at `limit_mb` MiB: a runaway allocation then
    raises MemoryError (recorded as a `crash` with reason `out_of_memory`) instead of swapping
    the machine. Never above the hard limit the process already has."""
    import resource

    global _MEMORY_LIMIT_MB
    _soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    want = int(limit_mb) * 1024 * 1024
    if hard != resource.RLIM_INFINITY:
        want = min(want, hard)
    resource.setrlimit(resource.RLIMIT_AS, (want, hard))
    _MEMORY_LIMIT_MB = want // (1024 * 1024)


@dataclasses.dataclass(frozen=True)
class TrialSpec:
    """Everything a worker needs to run one trial (picklable plain values)."""

    trial_id: str
    planner: str
    planner_config: dict[str, Any]
    problem: PlanningProblem
    #: what the run knows of the problem, copied into its record: problem_id, family, kind,
    #: trivial, difficulty, straight_length_rad, reference_length_rad, split (where known)
    meta: dict[str, Any] = dataclasses.field(default_factory=dict)


def derive_seed(*parts: Any) -> int:
    """A 31-bit seed from a run seed and a trial's identity (stable across machines)."""
    digest = hashlib.sha256("|".join(str(p) for p in parts).encode()).digest()
    return int.from_bytes(digest[:4], "little") & 0x7FFFFFFF


def trial_id(*, problem: PlanningProblem, planner: str, planner_config: dict) -> str:
    """Hash of (scene spec and cans, seed, problem, budget and its clock, planner and its config).
    The wall clock, the clock of every run before budgets had one, is left out, so those trials
    keep their ids."""
    fields = {
        "scene": problem.scene.key(),
        "scene_seed": problem.scene.seed,
        "can": problem.can_id,
        "problem": problem.kind,
        "seed": problem.seed,
        "time_limit_s": problem.time_limit_s,
        "planner": planner,
        "config": planner_config,
    }
    if problem.budget_clock != "wall":
        fields["budget_clock"] = problem.budget_clock
    if problem.task_index is not None:  # a free transit, numbered by its task (its "can" is None)
        fields["task"] = problem.task_index
    blob = json.dumps(fields, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:20]


def make_config(planner_cls, overrides: dict[str, Any] | None, *, tuned: bool = True):
    """The planner's Config dataclass: its class defaults, overlaid with the settings `tune` chose
    (planners/configs/NAME.yaml, unless `tuned` is False), overlaid with `overrides`; unknown
    fields, or values their schema refuses, are one SuiteError line."""
    from planners.tuned import tuned_settings
    from scenes.schema import load

    name = getattr(planner_cls, "name", None)
    overrides = {**(tuned_settings(name) if tuned and name else {}), **(overrides or {})}
    return load(planner_cls.Config, overrides, where=f"planner {name!r} settings: ")


def config_dict(config) -> dict[str, Any]:
    """A Config as plain JSON values."""
    return json.loads(json.dumps(dataclasses.asdict(config), default=str))


def make_trial(problem: PlanningProblem, *, planner: str, planner_config: dict[str, Any], run_seed: int,
               meta: dict[str, Any] | None = None) -> TrialSpec:
    """The trial of a planner on a problem, its seed derived from the run seed and the problem's
    identity (the one seeding rule of `compare`, `plan` and `execute`)."""
    p = problem.with_(seed=derive_seed(run_seed, problem.scene.key(), problem.subject, problem.kind, planner))
    return TrialSpec(trial_id(problem=p, planner=planner, planner_config=planner_config), planner, planner_config, p,
                     dict(meta or {}))


def run_problem(problem: PlanningProblem, *, planner: str, planner_config: dict[str, Any], run_seed: int) -> TrialRecord:
    """One trial in this process, seeded as `compare` seeds it."""
    return run_trial(make_trial(problem, planner=planner, planner_config=planner_config, run_seed=run_seed))


def trial_record(spec: TrialSpec) -> dict[str, Any]:
    """The fields of a trial's record that describe what was asked (before any planning)."""
    from suite.run.formats import record_format_version

    problem = spec.problem
    return {
        "format_version": record_format_version(budget_clock=problem.budget_clock),
        "trial_id": spec.trial_id,
        "planner": spec.planner,
        "planner_config": spec.planner_config,
        "scene_seed": problem.scene.seed,
        "scene_key": problem.scene.key(),
        "variant": problem.scene.variant,
        "can_id": problem.can_id,
        **({} if problem.task_index is None else {"task_index": problem.task_index}),
        "problem": problem.kind,
        "held": problem.held is not None,
        "seed": problem.seed,
        "time_limit_s": problem.time_limit_s,
        "budget_clock": problem.budget_clock,
        "q_start": _list(problem.q_start),
        "q_goal": _list(problem.q_goal),
        **spec.meta,
    }


def run_trial(spec: TrialSpec) -> TrialRecord:
    """Plan, validate, time and score one trial; never raises for a planner's failure.

    A MemoryError anywhere in the trial (the worker's memory cap, see `limit_memory`) gives a
    `crash` record with `stats.reason = "out_of_memory"`, and the worker asks to be replaced.
    """
    t0 = time.perf_counter()
    try:
        return _run_trial(spec)
    except MemoryError as exc:
        from suite.run.executors import retire_worker

        retire_worker()  # a process that ran out of memory may be left in a bad state
        return failed_record(spec, status=PlanStatus.CRASH.value, wall_time_s=time.perf_counter() - t0,
                             stats={"reason": "out_of_memory", "error": f"MemoryError: {exc}"[:200],
                                    "memory_limit_mb": _MEMORY_LIMIT_MB}, reason_code="out_of_memory")


def failed_record(spec: TrialSpec, *, status: str, wall_time_s: float, stats: dict[str, Any],
                  reason_code: str) -> TrialRecord:
    """The record of a trial that ended without a plan to judge (out of memory, a crashed or
    killed worker): `trial_record`'s fields, then the status, its cause and the wall time (its CPU
    time is not known)."""
    record = trial_record(spec)
    record.update(status=status, planning_time_s=wall_time_s, planning_cpu_time_s=None, path=None, metrics={},
                  stats=stats, reason_code=reason_code)
    return TrialRecord.from_json(record)


def _run_trial(spec: TrialSpec) -> TrialRecord:
    from planners.registry import planner_class
    from planners.worlds import collision_world, planning_world

    problem = spec.problem
    planned = problem.for_planner()  # in its plan world (a perceived one) if it has one; judged in the truth
    record = trial_record(spec)
    t_setup = time.perf_counter()
    world = collision_world(problem)  # the judge's (numpy reference)
    checks = planning_world(planned)  # the planners' (compiled unless SUITE_CHECKER=numpy); compiles here, in set-up
    result = None
    try:
        cls = planner_class(spec.planner)
        planner = cls(make_config(cls, spec.planner_config))
        planner.prepare(planned)  # world-only set-up, outside the clock for every planner alike
    except MemoryError:
        raise
    except Exception as exc:  # a bad config or a planner bug is this trial's error, not the run's
        result = _error_result(spec, exc)
    record["setup_time_s"] = time.perf_counter() - t_setup
    checks0, query0, fcl0 = checks.checks, checks.query_s, checks.fcl_calls
    probe = ContentionProbe.start()
    # CPU time of the whole process, not of this thread: OMPL's PRM and Drake's GCS plan in threads
    # of their own, and a worker process runs one trial at a time (`planners.base.CLOCKS`).
    t0, c0 = time.perf_counter(), time.process_time()
    if result is None:
        try:
            result = planner.plan(planned)
        except MemoryError:
            raise
        except Exception as exc:
            result = _error_result(spec, exc)
    planning_time_s = time.perf_counter() - t0
    planning_cpu_time_s = time.process_time() - c0
    record["contention"] = probe.stop(wall_s=planning_time_s, cpu_s=planning_cpu_time_s)
    fcl = (checks.checks - checks0, checks.query_s - query0)
    record["checker"] = checks.engine
    record["fcl_collide_calls"] = checks.fcl_calls - fcl0  # the pairs nothing cheaper decided, while planning
    record["warm"] = spec.planner in _PLANNED  # False: this worker's first trial of the planner
    _PLANNED.add(spec.planner)
    judged = TrialRecord.from_json(judge_result(record, spec=spec, world=world, result=result,
                                                planning_time_s=planning_time_s, planning_cpu_time_s=planning_cpu_time_s))
    if problem.plan_world is not None:
        _perceived_verdict(judged, problem, planned, result, world)
    judged.attribution = attribute(judged.stats, planning_time_s, fcl)
    return judged


def _perceived_verdict(record: TrialRecord, problem, planned, result: PlanResult, judge_world) -> None:
    """A trial planned in another world than the judge's: which world each check used, and, for a
    path the judge rejected for a collision that is free in the planner's world, its
    perception-induced failure (`stats.perception_induced`: where, what it struck, why)."""
    from planners.worlds import collision_world
    from suite.scoring.perception_failure import perception_induced

    record.worlds = {"planned": problem.plan_world.source, "judged": "truth", "physics": "truth"}
    reason = str(record.stats.get("invalid_reason", ""))
    if record.status == PlanStatus.INVALID_SOLUTION.value and reason.startswith("collision"):
        found = perception_induced(problem, result.path, judge_world, collision_world(planned))
        if found is not None:
            record.stats["perception_induced"] = found


def attribute(stats: dict[str, Any], planning_time_s: float,
              fcl: tuple[int, float] | None = None) -> dict[str, Any] | None:
    """Where a planning time went: the collision and distance queries, and the rest.

    `fcl` is (state checks, seconds) the python-fcl world answered during `plan()` (clocked around
    each call; every planner checks motions with it: the sampling planners all the time, `ik`
    between knots, `trajopt` and `gcs` on their results); without it, the planner's own
    `stats.collision_checks` / `stats.collision_query_s`. `stats.drake_distance_queries` /
    `stats.drake_distance_query_s` are the distance queries SNOPT made through Drake's constraint
    (`ik`, `trajopt`: counted exactly, timed by replaying a sample of them; `planners.drake_queries`).
    `stats.roboplan_checks_min` / `stats.roboplan_query_s_min` are `roboplan-rrt`'s state checks
    in C++, which roboplan does not count: a lower bound (`planners.roboplan_rrt`).

    Returns {engine, queries, query_s, s_per_query, other_s, query_share, parts: {engine: {queries,
    query_s, timing}}}, or None when nothing was counted.
    """
    parts: dict[str, dict[str, Any]] = {}
    n, q_s = fcl if fcl is not None else (stats.get("collision_checks"), stats.get("collision_query_s"))
    if isinstance(n, int) and isinstance(q_s, (int, float)):
        parts["python-fcl"] = {"queries": n, "query_s": float(q_s), "timing": "clocked"}
    dn, d_s = stats.get("drake_distance_queries"), stats.get("drake_distance_query_s")
    if isinstance(dn, int) and dn > 0 and isinstance(d_s, (int, float)):
        parts["drake"] = {"queries": dn, "query_s": float(d_s), "timing": "replayed"}
    rn, r_s = stats.get("roboplan_checks_min"), stats.get("roboplan_query_s_min")
    if isinstance(rn, int) and rn > 0 and isinstance(r_s, (int, float)):
        # roboplan counts none of its checks: the edges kept in its trees, at a cost per check
        # measured outside the clock (planners.roboplan_rrt): a lower bound
        parts["roboplan"] = {"queries": rn, "query_s": float(r_s), "timing": "lower_bound"}
    if not parts or not planning_time_s > 0:
        return None
    n_all = sum(p["queries"] for p in parts.values())
    s_all = sum(p["query_s"] for p in parts.values())
    return {"engine": "+".join(parts), "queries": n_all, "query_s": s_all,
            "s_per_query": s_all / n_all if n_all else None, "other_s": max(planning_time_s - s_all, 0.0),
            "query_share": min(s_all / planning_time_s, 1.0), "parts": parts}


#: A success returned later than its budget by more than this share of it plus LATE_GRACE_S is a
#: timeout (clock checks between iterations overshoot by milliseconds; more is a late answer).
LATE_GRACE_SHARE = 0.05
LATE_GRACE_S = 0.01


def late_after_s(time_limit_s: float) -> float:
    """The planning time after which a success counts as a timeout (s, on the budget's clock)."""
    return time_limit_s * (1 + LATE_GRACE_SHARE) + LATE_GRACE_S


def judge_result(record: dict[str, Any], *, spec: TrialSpec, world, result: PlanResult,
                 planning_time_s: float, planning_cpu_time_s: float | None = None) -> dict[str, Any]:
    """Complete a trial record from a planner's result: a claimed solution is validated, timed
    with TOPP-RA and scored, identically for the suite's planners and imported external ones. A
    claimed solution returned after the budget (`late_after_s`, on the problem's budget clock: the
    planning wall time, or with a CPU budget the planning CPU time) is a TIMEOUT (`stats.late_by_s`).

    The path is judged as it is stored (rounded to 1e-10 rad), so that a stored path re-scored
    or re-imported gives exactly the record's metrics.

    Args:
        record: the trial's record so far (`trial_record`); updated in place.
        spec: the trial (its problem and the reference figures in its meta).
        world: the problem's python-fcl collision world.
        result: what the planner returned (SUCCESS with a path is a claimed solution).
        planning_time_s: the planner's wall time, s.
        planning_cpu_time_s: its process's CPU time, s (None: not measured; a CPU budget is then
            judged on the wall time, the larger of the two for a single-threaded planner).

    Returns:
        The record, with status, planning_time_s, planning_cpu_time_s, path, metrics, certification (the exact
        verdict of every claimed path that has the right shape, ends and limits; None otherwise)
        and stats.
    """
    problem = spec.problem
    status = PlanStatus(result.status)
    stats = dict(result.stats)
    path = None if result.path is None else np.asarray(result.path, float).round(10)
    metrics: dict[str, float] = {}
    certification = None
    on_cpu = problem.budget_clock == "cpu" and planning_cpu_time_s is not None
    budget_time_s = planning_cpu_time_s if on_cpu else planning_time_s  # the late rule's clock is the budget's
    shaped = status == PlanStatus.SUCCESS and structure_reason(problem, path, world) is None
    limit = over_limit(path) if shaped else None
    if limit is not None:
        status = PlanStatus.INVALID_SOLUTION
        stats["reason"] = "path_over_limit"
        stats["limit"] = limit
        stats["invalid_reason"] = (f"path over the judge's limit: {limit['value']} {limit['limit'].replace('_', ' ')} "
                                   f"> {limit['max']} (suite.scoring.validate)")
    elif status == PlanStatus.SUCCESS:
        if shaped:  # the exact verdict, beside the 0.01 rad rule
            certification = certify_path(path, world)
        reason = validate_path(problem, path, world)
        if reason is not None:
            status = PlanStatus.INVALID_SOLUTION
            stats["invalid_reason"] = reason
        elif budget_time_s > late_after_s(problem.time_limit_s):
            # A solve that cannot be interrupted (SNOPT, a GCS solve, OMPL between its checks) may
            # return a valid path after the budget: credited, it would measure the clock checks,
            # not the planner. It is neither timed nor scored.
            status = PlanStatus.TIMEOUT
            stats["late_by_s"] = budget_time_s - problem.time_limit_s
            what = " of CPU time" if on_cpu else ""
            stats["reason"] = (f"a valid path came {budget_time_s:.3g} s{what} into a {problem.time_limit_s:g} s"
                               f"{' CPU' if on_cpu else ''} budget (it does not count)")
        else:
            from suite.scoring.metrics import record_metrics, score
            from suite.scoring.timing import time_parameterize

            timed = time_parameterize(path, robot=world.robot)
            if timed.status != "ok":
                status = PlanStatus.TIMING_FAILED
                stats["timing_reason"] = timed.reason
            scored = score(path=path, world=world, X_WG_goal=problem.X_WG_goal, timed=timed,
                           reference_length_rad=spec.meta.get("reference_length_rad"),
                           reference_ee_length_m=spec.meta.get("reference_ee_length_m"))
            metrics = record_metrics(scored)  # NaN (undefined, or timing failed) stored as null
    record.update(
        status=status.value,
        planning_time_s=planning_time_s,
        planning_cpu_time_s=planning_cpu_time_s,
        path=None if path is None or status not in (PlanStatus.SUCCESS, PlanStatus.TIMING_FAILED)
        else path.tolist(),
        metrics=metrics,
        certification=certification,
        stats=_jsonable(stats),
    )
    record["reason_code"] = reason_code(TrialRecord.from_json(record))  # a fresh record: worked out, not read
    return record


def _error_result(spec: TrialSpec, exc: Exception) -> PlanResult:
    """A planner that raised: an ERROR result carrying the exception and its traceback."""
    log.debug("planner %s raised on %s", spec.planner, spec.problem.name, exc_info=True)
    return PlanResult(PlanStatus.ERROR, None, {"error": f"{type(exc).__name__}: {exc}",
                                               "traceback": traceback.format_exc(limit=5)})


def _list(q) -> list[float] | None:
    if q is None:
        return None
    q = np.asarray(q, float)
    return None if not np.all(np.isfinite(q)) else q.round(12).tolist()


def _jsonable(obj):
    return json.loads(json.dumps(obj, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o)))
