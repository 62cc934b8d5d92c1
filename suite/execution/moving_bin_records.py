"""What goes into a moving-bin episode and what comes out: the job, its events and its record.

`MovingBinJob` is one planner's episode on one scene at one bin speed (plain picklable values);
`MovingBinRecord` (`to_json`, one entry of moving_bin.json) holds what the episode did: cans in
the bin per can attempted, every online plan (`ReplanEvent`), every can's fate (`CanEpisode`),
splices, releases, the person's distances and contacts. The loop itself is
`suite.execution.moving_bin_episode`; running jobs, `suite.execution.moving_bin`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

from scenes.errors import SuiteError
from scenes.moving_bin import MovingBinScenario
from scenes.scene import Scene
from suite.execution.config import ExecutionConfig

#: moving_bin.json's format: 2 added the non-stopping loop's fields, 3 the escapes and the release's updates (a record
#: without them is of an earlier format, read with their defaults; files before 3 say 1).
FORMAT_VERSION = 3

#: A release counts as on the move above this gripper speed (an estimate of a still bin is noise).
MOVING_RELEASE_M_S = 0.02

#: Kept replan events per record.
MAX_EVENTS = 400

#: Planners the loop cannot run, with the reason (their offline preparation is tied to the world).
NOT_APPLICABLE = {
    "gcs": "its convex regions are built offline for one fixed world",
    "prm-roadmap": "its roadmap is built offline for one fixed world",
    "prm-roadmap-shortcut": "its roadmap is built offline for one fixed world",
}

#: Each planner's declared latency (s) of one online plan in "modelled" mode: the median wall time
#: of its deadline-bound online plans (goal IK, plan, join, validation, swept check) in the
#: measured sweep of docs/moving-bin.md (results/moving-bin/v2-measured: ik 0.0512, rrt 0.0368,
#: trajopt 0.0802 s over 1376, 1057 and 978 plans), rounded up to 5 ms. A planner not named here
#: takes DEFAULT_MODELLED_LATENCY_S unless the scenario declares its own (`modelled_latency_s`).
MODELLED_LATENCY_S = {"ik": 0.055, "rrt": 0.04, "trajopt": 0.085}
DEFAULT_MODELLED_LATENCY_S = 0.15


def modelled_latency(scenario: MovingBinScenario, planner: str) -> float:
    """The planner's declared latency in modelled mode (the scenario's, else the table's)."""
    declared = scenario.modelled_latency_s or {}
    return float(declared.get(planner, MODELLED_LATENCY_S.get(planner, DEFAULT_MODELLED_LATENCY_S)))


#: The counts a record of format 1 (or 2, for the last two) does not have.
COUNTED_SINCE_V2 = ("cans_put_down", "cans_not_attempted", "failures_by_stage", "splices_at_rest", "releases_moving",
                    "near_misses_person", "ssm_holds", "escapes", "release_updates")


def _known(cls, obj: dict[str, Any]) -> dict[str, Any]:
    """The keys of a JSON object that are fields of the dataclass `cls`."""
    names = {f.name for f in dataclasses.fields(cls)}
    return {k: v for k, v in obj.items() if k in names}


def _rounded(out: dict) -> dict:
    for k, v in out.items():
        if isinstance(v, float):
            out[k] = round(v, 6)
    return out


@dataclasses.dataclass(frozen=True)
class ReplanEvent:
    """One online plan: when, why, how long it took and what came of it.

    Attributes:
        t_s: simulated time it started.
        can_id: the can in the gripper (or just released, for a return).
        trigger: "lift" (the first transit), "drift" (the prediction moved during the transit),
            "arrival" (not over the opening on arrival), "resume" (after a protective stop),
            "return", "put_down" (a given-up can carried back to its place), "track" (the
            release re-aimed at a new estimate, `track_feedback`; not a plan: latency 0).
        drift_m: the predicted drop position's distance from the planned one (drift, arrival).
        latency_s: its latency (wall time, or the declared constant in modelled mode).
        deadline_s: its deadline (deadline-bound plans in measured mode), or None.
        outcome: "spliced", "missed" (measured mode: ready after its splice time, dropped: the
            current plan goes on), "failed" (no valid plan: the current plan goes on),
            "planned" (the arm waited at rest for it), "track failed" (no release motion).
        reason, stage: a failure's reason and its stage (`suite.execution.replan.STAGES`).
        jump_q_rad, jump_v_rad_s: the largest joint jump of the command at the splice and where
            the blend meets the new path (spliced only; ~0 by construction).
        splice_speed_rad_s: the largest joint speed of the command at the splice (spliced, track).
        join_at_rest: the join ended at rest (no moving join within the limits).
        expected_latency_s: the latency the splice time was chosen for.
        parts_s: wall time per step (measured mode only).
    """

    t_s: float
    can_id: int
    trigger: str
    drift_m: float | None
    latency_s: float
    deadline_s: float | None
    outcome: str
    reason: str = ""
    stage: str = ""
    jump_q_rad: float | None = None
    jump_v_rad_s: float | None = None
    splice_speed_rad_s: float | None = None
    join_at_rest: bool = False
    expected_latency_s: float | None = None
    parts_s: dict[str, float] = dataclasses.field(default_factory=dict)

    def to_json(self) -> dict:
        out = _rounded(dataclasses.asdict(self))
        out["parts_s"] = {k: round(v, 5) for k, v in self.parts_s.items()}
        return out


@dataclasses.dataclass(frozen=True)
class CanEpisode:
    """One can's run with the moving bin: released over the bin, or given up (and put down)."""

    can_id: int
    released: bool
    grasp_to_release_s: float | None
    release_offset_m: float | None  # the gripper's true distance (xy) from the bin centre when the opening starts
    gave_up: str = ""
    release_speed_m_s: float | None = None  # the gripper's speed at release (0 from rest)
    put_down: bool = False  # given up and put back on the plate

    def to_json(self) -> dict:
        out = dataclasses.asdict(self)
        for k in ("grasp_to_release_s", "release_offset_m", "release_speed_m_s"):
            out[k] = None if out[k] is None else round(out[k], 4)
        return out


@dataclasses.dataclass(frozen=True)
class MovingBinRecord:
    """One planner's episode on one scene at one bin speed (`to_json` for moving_bin.json).

    status is "ok", "not_applicable" (the planner cannot run the loop: `reason`) or "error"
    (`error_state`: where the simulation was). speed_m_s is the bin's cruise speed;
    bin_mean_speed_m_s its mean over the episode. bin_seed is the seed of this episode's bin
    path (and estimate noise), drawn from the run seed, the scene and path_index: every planner
    meets the same paths. Wall-clock fields (wall_time_s, latency_parts_s, events' parts_s) are
    None or empty in modelled mode, so two runs give the same record on any machine."""

    planner: str
    scene_seed: int
    variant: str
    speed_m_s: float | None
    scenario: dict[str, Any]
    status: str
    reason: str = ""
    bin_seed: int | None = None
    path_index: int = 0
    latency_mode: str = "measured"
    release_mode: str | None = "moving"  # None: an older record (released at rest)
    bin_mean_speed_m_s: float | None = None
    cans_total: int = 0
    cans_attempted: int = 0
    cans_in_bin: int = 0
    cans_released: int = 0
    cans_given_up: int = 0
    cans_put_down: int | None = 0
    cans_not_attempted: int | None = 0
    replans: int = 0
    splices: int = 0
    splices_at_rest: int | None = 0
    splice_speed_median_rad_s: float | None = None
    deadline_misses: int = 0
    replan_failures: int = 0
    failures_by_stage: dict[str, int] | None = dataclasses.field(default_factory=dict)
    replan_latency_median_s: float | None = None
    replan_latency_p95_s: float | None = None
    plan_latency_median_s: float | None = None
    latency_parts_s: dict[str, list[float]] = dataclasses.field(default_factory=dict)
    splice_jump_q_rad: float | None = None
    splice_jump_v_rad_s: float | None = None
    grasp_to_release_median_s: float | None = None
    releases_moving: int | None = 0
    release_updates: int | None = 0
    release_speed_median_m_s: float | None = None
    contacts_bin: int = 0
    contacts_person: int = 0
    person_min_distance_m: float | None = None
    near_misses_person: int | None = 0
    ssm_holds: int | None = 0
    escapes: int | None = 0
    collisions: int = 0
    sim_time_s: float = 0.0
    wall_time_s: float | None = 0.0
    stopped: str = ""
    error_state: dict[str, Any] | None = None
    cans: tuple[CanEpisode, ...] = ()
    fates: tuple[dict, ...] = ()
    events: tuple[ReplanEvent, ...] = ()
    contact_events: tuple[dict, ...] = ()
    replay: str | None = None
    #: keys of the JSON object this version does not name (kept, and written back after the fields)
    extra: dict[str, Any] = dataclasses.field(default_factory=dict, repr=False)

    @property
    def replans_per_can(self) -> float | None:
        return self.replans / self.cans_attempted if self.cans_attempted else None

    @classmethod
    def from_json(cls, obj: dict[str, Any]) -> MovingBinRecord:
        """A record of moving_bin.json, of this format or an earlier one (its missing fields at
        their defaults; `replans_per_can` is worked out, not read)."""
        known = {k: v for k, v in _known(cls, obj).items() if k != "extra"}
        known["extra"] = {k: v for k, v in obj.items() if k not in known and k != "replans_per_can"}
        # a count an earlier format did not keep is None (not recorded), not 0: the tables leave it out
        known.update((name, None) for name in COUNTED_SINCE_V2 if name not in obj)
        if "release_mode" not in obj:  # written before releases on the move: the arm released at rest
            known["release_mode"] = None
        if "scenario" not in obj:  # a worker's death recorded before its record named the scenario
            known.update(scenario={}, speed_m_s=obj.get("speed_m_s"))
        known["cans"] = tuple(CanEpisode(**_known(CanEpisode, c)) for c in obj.get("cans") or ())
        known["events"] = tuple(ReplanEvent(**_known(ReplanEvent, e)) for e in obj.get("events") or ())
        for name in ("fates", "contact_events"):
            known[name] = tuple(obj.get(name) or ())
        try:
            return cls(**known)
        except TypeError as exc:
            raise SuiteError(f"a moving-bin record of {obj.get('planner')!r} on seed {obj.get('scene_seed')!r} "
                             f"is not one: {exc}") from None

    def to_json(self) -> dict:
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "extra"}
        out["cans"] = [c.to_json() for c in self.cans]
        out["events"] = [e.to_json() for e in self.events]
        out["fates"] = list(self.fates)
        out["contact_events"] = list(self.contact_events)
        out["replans_per_can"] = self.replans_per_can
        out["latency_parts_s"] = {k: [round(x, 5) for x in v] for k, v in self.latency_parts_s.items()}
        return {**_rounded(out), **{k: v for k, v in self.extra.items() if k not in out}}


@dataclasses.dataclass(frozen=True)
class MovingBinJob:
    """One planner's moving-bin episode on one scene (picklable plain values).

    Attributes:
        planner, planner_config: the planner and its settings.
        scene: the scene at the start (an `open` or `wall` station).
        scenario: the bin's motion, sensing and the loop's settings (its `seed`: this episode's
            bin path, `episode_seed`).
        cans: per can in picking order, (can id, its five paths or None where a problem failed,
            first failed status): the approach, descend and lift are executed as planned.
        q_home: where the first approach starts.
        time_limit_s: the planning budget of a motion the arm waits for at rest (the first
            transit, the return, a put-down), and every plan's cap in modelled mode.
        seed: the run seed.
        path_index: which of the scene's bin paths this is.
        replay_path: where to write the Meshcat replay, or None.
        config: the simulation settings.
    """

    planner: str
    planner_config: dict[str, Any]
    scene: Scene
    scenario: MovingBinScenario
    cans: tuple[tuple[int, tuple[Any, ...], str], ...]
    q_home: tuple[float, ...]
    time_limit_s: float
    seed: int
    replay_path: str | None = None
    config: ExecutionConfig = ExecutionConfig()
    path_index: int = 0

    def record(self, status: str, reason: str, **kw) -> MovingBinRecord:
        """A record of this job that did not run the loop (not applicable, an error)."""
        s = self.scenario
        return MovingBinRecord(self.planner, self.scene.seed, self.scene.variant, s.speed_m_s, s.to_json(), status,
                               reason, bin_seed=s.seed, path_index=self.path_index, latency_mode=s.latency_mode,
                               release_mode=s.release, cans_total=len(self.scene.cans), **kw)


def episode_seed(run_seed: int, scene_seed: int, path_index: int, scenario_seed: int = 0) -> int:
    """The bin path's seed of one episode: from the run seed, the scene, the path's index and the
    scenario's own seed (the same for every planner, so their episodes are paired)."""
    state = np.random.SeedSequence([int(run_seed) & 0xFFFFFFFF, int(scene_seed), int(path_index), int(scenario_seed),
                                    52])
    return int(state.generate_state(1)[0] % 2**31)


def quantile(values: Sequence[float], q: float) -> float | None:
    return float(np.quantile(values, q)) if len(values) else None


def episode_record(ep, monitor, fates, wall: float) -> MovingBinRecord:
    """The record of a finished episode `ep` (`suite.execution.moving_bin_episode.Episode`) from its
    events and cans, the physics monitor, the cans' fates and the wall time of the simulation."""
    from suite.execution.replan import STAGES

    deadline_bound = [e for e in ep.events if e.trigger in ("drift", "arrival", "resume")]
    lat = [e.latency_s for e in deadline_bound]
    plans = [e.latency_s for e in ep.events if e.trigger in ("lift", "return", "put_down")]
    spliced = [e for e in deadline_bound if e.outcome == "spliced"]
    released = [c for c in ep.cans if c.released]
    failed = [e for e in deadline_bound if e.outcome == "failed"]
    stages = {s: sum(e.stage == s for e in failed) for s in STAGES}
    parts: dict[str, list[float]] = {}
    if not ep.modelled:
        for name in ("world", "ik", "plan", "join", "validate", "person"):
            xs = [e.parts_s[name] for e in deadline_bound if name in e.parts_s]
            if xs:
                parts[name] = [quantile(xs, 0.5), quantile(xs, 0.95)]
    job, s = ep.job, ep.s
    return MovingBinRecord(
        planner=job.planner, scene_seed=job.scene.seed, variant=job.scene.variant,
        speed_m_s=s.speed_m_s, scenario=s.to_json(), status="ok", bin_seed=s.seed, path_index=job.path_index,
        latency_mode=s.latency_mode, release_mode=s.release,
        bin_mean_speed_m_s=ep.path.mean_speed_m_s(ep.stream.duration_s),
        cans_total=len(job.scene.cans), cans_attempted=len(ep.attempted),
        cans_in_bin=sum(f.where == "bin" for f in fates), cans_released=len(released),
        cans_given_up=sum(1 for c in ep.cans if not c.released),
        cans_put_down=sum(1 for c in ep.cans if c.put_down),
        cans_not_attempted=len(job.scene.cans) - len(ep.attempted),
        replans=len(deadline_bound), splices=len(spliced),
        splices_at_rest=sum(e.join_at_rest for e in spliced),
        splice_speed_median_rad_s=quantile([e.splice_speed_rad_s for e in spliced], 0.5),
        deadline_misses=sum(e.outcome == "missed" for e in deadline_bound),
        replan_failures=len(failed), failures_by_stage={k: v for k, v in stages.items() if v},
        replan_latency_median_s=quantile(lat, 0.5), replan_latency_p95_s=quantile(lat, 0.95),
        plan_latency_median_s=quantile(plans, 0.5), latency_parts_s=parts,
        splice_jump_q_rad=max((e.jump_q_rad for e in spliced), default=None),
        splice_jump_v_rad_s=max((e.jump_v_rad_s for e in spliced), default=None),
        grasp_to_release_median_s=quantile([c.grasp_to_release_s for c in released], 0.5),
        releases_moving=sum(1 for c in released if (c.release_speed_m_s or 0) > 0),
        release_updates=sum(1 for e in ep.events if e.trigger == "track" and e.outcome == "spliced"),
        release_speed_median_m_s=quantile([c.release_speed_m_s or 0.0 for c in released], 0.5),
        contacts_bin=monitor.moving_contacts["bin"], contacts_person=monitor.moving_contacts["person"],
        person_min_distance_m=None if not np.isfinite(ep.person_min) else ep.person_min,
        near_misses_person=ep.near_misses, ssm_holds=ep.ssm_holds, escapes=ep.escapes_total,
        collisions=monitor.n_episodes, sim_time_s=ep.stream.duration_s,
        wall_time_s=None if ep.modelled else wall,
        stopped=ep.stopped, cans=tuple(ep.cans), fates=tuple(f.to_json() for f in fates),
        events=tuple(ep.events[:MAX_EVENTS]), contact_events=tuple(e.to_json() for e in monitor.events),
    )


def error_state(ep, t: float) -> dict:
    """Where episode `ep`'s simulation was when it failed: enough to replay it to that instant."""
    st = ep.stream
    out: dict = {"sim_time_s": float(t), "mode": ep.mode, "can_id": ep.can_id}
    try:
        q, v, a = st.state(t)
        out["command"] = {"q": q.tolist(), "v": v.tolist(), "a": a.tolist()}
        out["segments"] = [(s.phase, round(s.t0_s, 4), round(s.duration_s, 4)) for s in st.segments[-6:]]
        p, vb = ep.path.at(t)
        out["bin_drive"] = {"xy": np.asarray(p).tolist(), "v": np.asarray(vb).tolist()}
        sim = ep.sim
        out["arm_q"] = sim.plant.GetPositions(sim.pc, sim.iiwa).tolist()
        out["bin_q"] = sim.plant.GetPositions(sim.pc, sim.moving_bin).tolist()
    except Exception as exc:  # the state of a broken simulation may itself be unreadable
        out["unreadable"] = f"{type(exc).__name__}: {exc}"
    out["events"] = [e.to_json() for e in ep.events[-3:]]
    return out
