"""One trial: a planner on a problem, then the same validation, timing and scoring for all.

`run_trial` is the function every executor runs (in a worker process); it returns the plain
JSON record that the parent appends to trials.jsonl.
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
from suite.scoring.validate import validate_path

log = logging.getLogger(__name__)



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
    """Hash of (scene spec and cans, seed, problem, planner and its config)."""
    blob = json.dumps(
        {
            "scene": problem.scene.key(),
            "scene_seed": problem.scene.seed,
            "can": problem.can_id,
            "problem": problem.kind,
            "seed": problem.seed,
            "time_limit_s": problem.time_limit_s,
            "planner": planner,
            "config": planner_config,
        },
        sort_keys=True,
    )
    return hashlib.sha256(blob.encode()).hexdigest()[:20]


def make_config(planner_cls, overrides: dict[str, Any] | None, *, tuned: bool = True):
    """The planner's Config dataclass: its class defaults, overlaid with the settings `tune` chose
    (planners/configs/NAME.yaml, unless `tuned` is False), overlaid with `overrides`; unknown
    fields are a SuiteError."""
    from planners.tuned import tuned_settings
    from scenes.errors import SuiteError

    cfg_cls = planner_cls.Config
    name = getattr(planner_cls, "name", None)
    overrides = {**(tuned_settings(name) if tuned and name else {}), **(overrides or {})}
    fields = {f.name for f in dataclasses.fields(cfg_cls)}
    unknown = set(overrides) - fields
    if unknown:
        raise SuiteError(
            f"unknown setting {sorted(unknown)[0]!r} for planner {planner_cls.name!r}; allowed: {sorted(fields)}"
        )
    return cfg_cls(**overrides)


def config_dict(config) -> dict[str, Any]:
    """A Config as plain JSON values."""
    return json.loads(json.dumps(dataclasses.asdict(config), default=str))


def make_trial(problem: PlanningProblem, *, planner: str, planner_config: dict[str, Any], run_seed: int,
               meta: dict[str, Any] | None = None) -> TrialSpec:
    """The trial of a planner on a problem, its seed derived from the run seed and the problem's
    identity (the one seeding rule of `compare`, `plan` and `execute`)."""
    p = problem.with_(seed=derive_seed(run_seed, problem.scene.key(), problem.can_id, problem.kind, planner))
    return TrialSpec(trial_id(problem=p, planner=planner, planner_config=planner_config), planner, planner_config, p,
                     dict(meta or {}))


def run_problem(problem: PlanningProblem, *, planner: str, planner_config: dict[str, Any], run_seed: int) -> dict[str, Any]:
    """One trial in this process, seeded as `compare` seeds it."""
    return run_trial(make_trial(problem, planner=planner, planner_config=planner_config, run_seed=run_seed))


def run_trial(spec: TrialSpec) -> dict[str, Any]:
    """Plan, validate, time and score one trial; never raises for a planner's failure."""
    from planners.registry import planner_class
    from planners.worlds import collision_world

    problem = spec.problem
    record: dict[str, Any] = {
        "trial_id": spec.trial_id,
        "planner": spec.planner,
        "planner_config": spec.planner_config,
        "scene_seed": problem.scene.seed,
        "scene_key": problem.scene.key(),
        "variant": problem.scene.variant,
        "can_id": problem.can_id,
        "problem": problem.kind,
        "held": problem.held is not None,
        "seed": problem.seed,
        "time_limit_s": problem.time_limit_s,
        "q_start": _list(problem.q_start),
        "q_goal": _list(problem.q_goal),
        **spec.meta,
    }
    t_setup = time.perf_counter()
    world = collision_world(problem)
    result = None
    try:
        cls = planner_class(spec.planner)
        planner = cls(make_config(cls, spec.planner_config))
        if hasattr(planner, "prepare"):  # world-only set-up, outside the clock for every planner alike
            planner.prepare(problem)
    except Exception as exc:  # a bad config or a planner bug is this trial's error, not the run's
        result = _error_result(spec, exc)
    record["setup_time_s"] = time.perf_counter() - t_setup
    t0 = time.perf_counter()
    if result is None:
        try:
            result = planner.plan(problem)
        except Exception as exc:
            result = _error_result(spec, exc)
    planning_time_s = time.perf_counter() - t0
    status = PlanStatus(result.status)
    stats = dict(result.stats)
    path = None if result.path is None else np.asarray(result.path, float)
    metrics: dict[str, float] = {}
    if status == PlanStatus.SUCCESS:
        reason = validate_path(problem, path, world)
        if reason is not None:
            status = PlanStatus.INVALID_SOLUTION
            stats["invalid_reason"] = reason
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
        path=None if path is None or status not in (PlanStatus.SUCCESS, PlanStatus.TIMING_FAILED)
        else path.round(10).tolist(),
        metrics=metrics,
        stats=_jsonable(stats),
    )
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
