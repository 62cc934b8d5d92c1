"""The moving-bin section of a run's report, from moving_bin.json alone."""

import dataclasses
import itertools
import math

import numpy as np
import pytest
from synthetic_runs import synthetic_records, write_run

from suite.execution.execution_records import read_moving_bin, write_moving_bin
from suite.execution.moving_bin_records import MovingBinRecord
from suite.report.summary_moving_bin import (
    latency_rows,
    moving_bin_rows,
    moving_bin_table,
    speed_cells,
    stages_cell,
)
from suite.report.summary_moving_bin_paired import (
    bootstrap_mean_ci,
    paired_differences,
    paired_rows,
)

#: The fields the loop's records gained when replans joined on the move (an older file lacks them).
NEW_RECORD_FIELDS = ("bin_seed", "path_index", "latency_mode", "release_mode", "cans_put_down", "cans_not_attempted",
                     "failures_by_stage", "latency_parts_s", "splices_at_rest", "splice_speed_median_rad_s",
                     "releases_moving", "release_speed_median_m_s", "person_min_distance_m", "near_misses_person",
                     "ssm_holds", "error_state")
NEW_EVENT_FIELDS = ("stage", "splice_speed_rad_s", "join_at_rest", "expected_latency_s")


def _records():
    """rrt at 0 and 0.2 m/s and gcs (not applicable), as moving_bin.json held them before the loop
    joined replans on the move (format 1: plain dicts, none of the newer fields)."""
    out = []
    for speed, in_bin, latencies in ((0.0, 2, (0.05,)), (0.2, 1, (0.1, 0.2, 0.5))):
        scenario = {"speed_m_s": speed, "replan_deadline_s": 0.3, "seed": 0}
        events = [{"t_s": 1.0 + i, "can_id": 0, "trigger": "drift", "drift_m": 0.05, "latency_s": lat,
                   "deadline_s": 0.3, "outcome": "spliced" if lat <= 0.3 else "missed", "reason": "",
                   "jump_q_rad": 0.0 if lat <= 0.3 else None, "jump_v_rad_s": 0.0 if lat <= 0.3 else None,
                   "parts_s": {"world": 0.001, "blend": 0.001, "ik": lat / 2, "plan": lat / 4, "validate": lat / 8,
                               "timing": lat / 8}}
                  for i, lat in enumerate(latencies)]
        base = {"scene_seed": 0, "variant": "open", "speed_m_s": speed, "scenario": scenario, "reason": "",
                "bin_mean_speed_m_s": None, "cans_total": 2, "cans_attempted": 0, "cans_in_bin": 0,
                "cans_released": 0, "cans_given_up": 0, "replans": 0, "splices": 0, "deadline_misses": 0,
                "replan_failures": 0, "contacts_bin": 0, "contacts_person": 0, "collisions": 0, "stopped": "",
                "cans": [], "fates": [], "events": [], "contact_events": [], "replay": None}
        out.append(MovingBinRecord.from_json({**base, "planner": "rrt", "status": "ok", "cans_attempted": 2, "cans_in_bin": in_bin,
                    "cans_released": 2, "replans": len(events),
                    "splices": sum(e["outcome"] == "spliced" for e in events),
                    "deadline_misses": sum(e["outcome"] == "missed" for e in events),
                    "contacts_person": int(speed > 0), "events": events,
                    "cans": [{"can_id": 0, "released": True, "grasp_to_release_s": 2.0, "release_offset_m": 0.01,
                              "gave_up": ""},
                             {"can_id": 1, "released": True, "grasp_to_release_s": 3.0, "release_offset_m": 0.02,
                              "gave_up": ""}]}))
        out.append(MovingBinRecord.from_json({**base, "planner": "gcs", "status": "not_applicable",
                                              "reason": "its convex regions are built offline for one fixed world"}))
    return out


def _old(records):
    """The records as read from an older moving_bin.json: none of the newer fields (their defaults)."""
    out = []
    for rec in records:
        r = {k: v for k, v in rec.to_json().items() if k not in NEW_RECORD_FIELDS}
        r["events"] = [{k: v for k, v in e.items() if k not in NEW_EVENT_FIELDS} for e in r["events"]]
        out.append(MovingBinRecord.from_json(r))
    return out


def _event(latency_s, *, outcome="spliced", parts=None, stage="", speed=None, at_rest=False, deadline_s=0.3,
           trigger="drift"):
    return {"t_s": 1.0, "can_id": 0, "trigger": trigger, "drift_m": 0.05, "latency_s": latency_s,
            "deadline_s": deadline_s, "outcome": outcome, "reason": "", "jump_q_rad": 0.0 if outcome == "spliced" else None,
            "jump_v_rad_s": 0.0 if outcome == "spliced" else None, "parts_s": dict(parts or {}), "stage": stage,
            "splice_speed_rad_s": speed, "join_at_rest": at_rest, "expected_latency_s": None}


def _record(planner, *, bin_seed, in_bin, attempted, speed=0.2, scene_seed=1000, variant="open", status="ok",
            events=(), **fields):
    """A record as the loop that joins replans on the move writes it (a plain JSON dict)."""
    r = {"planner": planner, "scene_seed": scene_seed, "variant": variant, "speed_m_s": speed,
         "scenario": {"speed_m_s": speed, "replan_deadline_s": 0.3}, "status": status, "reason": "",
         "bin_mean_speed_m_s": speed / 2, "cans_total": attempted, "cans_attempted": attempted, "cans_in_bin": in_bin,
         "cans_released": in_bin, "cans_given_up": attempted - in_bin, "replans": len(events),
         "splices": sum(e["outcome"] == "spliced" for e in events),
         "deadline_misses": sum(e["outcome"] == "missed" for e in events),
         "replan_failures": sum(e["outcome"] == "failed" for e in events), "contacts_bin": 0, "contacts_person": 0,
         "cans": [], "events": list(events), "bin_seed": bin_seed, "path_index": 0, "latency_mode": "measured",
         "release_mode": "moving", "cans_put_down": attempted - in_bin, "cans_not_attempted": 0,
         "failures_by_stage": {}, "latency_parts_s": {}, "splices_at_rest": 0, "splice_speed_median_rad_s": None,
         "releases_moving": in_bin, "release_speed_median_m_s": None, "person_min_distance_m": 0.5,
         "near_misses_person": 0, "ssm_holds": 0, "error_state": None}
    r.update(fields)
    return MovingBinRecord.from_json(r)


def _sweep_records(planners=("ik", "rrt", "trajopt"), speeds=(0.0, 0.1, 0.2, 0.4), paths=3):
    """A small deterministic sweep in the new format: 2 scenes x `paths` bin paths x speeds, 5 cans
    each; a can lands when the episode's shared draw is under the planner's rate at that speed (the
    same draws for every planner: their episodes are paired)."""
    rate = {"ik": (1.0, 0.98, 0.9, 0.6), "rrt": (1.0, 0.98, 0.85, 0.35), "trajopt": (1.0, 0.95, 0.8, 0.5)}
    median = {"ik": 0.06, "rrt": 0.045, "trajopt": 0.08}
    out = []
    for (variant, scene), path, (i, speed) in itertools.product((("open", 1000), ("wall", 1012)), range(paths),
                                                                enumerate(speeds)):
        draws = np.random.default_rng([scene, path, i]).random(5)
        for p in planners:
            rng = np.random.default_rng([scene, path, i, len(p)])
            in_bin = int((draws < rate[p][i]).sum())
            events = []
            for _ in range(5 + int(40 * speed)):
                lat = float(median[p] * rng.lognormal(0.0, 0.6))
                parts = {"world": 0.0002, "ik": 0.45 * lat, "plan": 0.3 * lat, "join": 0.02 * lat,
                         "validate": 0.15 * lat, "person": 0.01 * lat, "timing": 0.07 * lat}
                failed = rng.random() < 0.3 * speed
                outcome = "missed" if lat > 0.3 else "failed" if failed else "spliced"
                events.append(_event(lat, outcome=outcome, parts=parts,
                                     stage=str(rng.choice(["goal_ik", "planner", "join"])) if failed else "",
                                     speed=float(speed * 4 + 0.1 * rng.random()) if outcome == "spliced" else None,
                                     at_rest=bool(outcome == "spliced" and rng.random() < 0.05)))
            stages = {}
            for e in events:
                if e["outcome"] == "failed":
                    stages[e["stage"]] = stages.get(e["stage"], 0) + 1
            out.append(_record(p, bin_seed=1000 * scene + path, path_index=path, in_bin=in_bin, attempted=5,
                               speed=speed, scene_seed=scene, variant=variant, events=events, failures_by_stage=stages,
                               splices_at_rest=sum(e["join_at_rest"] for e in events),
                               near_misses_person=int(rng.poisson(4 * speed)), ssm_holds=int(rng.poisson(2 * speed)),
                               contacts_person=int(rng.random() < speed / 2),
                               cans=[{"can_id": c, "released": c < in_bin, "grasp_to_release_s": 1.5 + 10 * speed,
                                      "release_offset_m": 0.01, "gave_up": ""} for c in range(5)]))
    return out


def test_moving_bin_cells_count_cans_latency_and_misses(tmp_path):
    records = _records()
    write_moving_bin(tmp_path, records)
    assert read_moving_bin(tmp_path) == records
    rrt = [c for c in speed_cells(records) if c.planner == "rrt"]
    assert [c.speed_m_s for c in rrt] == [0.0, 0.2]
    fast = rrt[1]
    assert (fast.cans_in_bin, fast.cans_attempted, fast.deadline_misses, fast.contacts_person) == (1, 2, 1, 1)
    assert fast.latencies_s == (0.1, 0.2, 0.5) and math.isclose(fast.replans_per_can, 1.5)
    assert fast.ci95[0] < 0.5 < fast.ci95[1]
    headers, rows = moving_bin_rows(records)
    gcs = [r for r in rows if r[0] == "gcs"]
    assert headers[3] == "cans in bin / offered"
    assert len(gcs) == 2 and gcs[0][3].startswith("not applicable: its convex regions")
    assert all(len(r) == len(headers) for r in rows)
    rrt_fast = next(r for r in rows if r[:2] == ["rrt", "0.2"])
    assert rrt_fast[headers.index("missed / failed")] == "1 / 0"


def test_the_headline_is_per_can_offered_and_old_records_render_without_the_new_columns():
    old = _old(_records())
    old[2] = dataclasses.replace(old[2], cans_total=4, cans_attempted=2, cans_given_up=1)  # rrt at 0.2: 2 never tried
    headers, rows = moving_bin_rows(old)
    row = next(r for r in rows if r[:2] == ["rrt", "0.2"])
    assert row[headers.index("cans in bin / offered")] == "1/4 (25% [5, 70])"  # the cans never tried count
    assert row[headers.index("not attempted")] == 2
    assert row[headers.index("given up")] == 1
    for absent in ("given up (put down)", "failed by stage", "splices (at rest)", "drift splice speed (rad/s)",
                   "escapes", "release updates",
                   "released moving / released", "person near misses / SSM holds", "latency", "release"):
        assert absent not in headers
    text = moving_bin_table(old, planners=("rrt", "gcs"))
    assert "| rrt " in text and "not applicable" in text
    assert "Paired differences" not in text  # one planner ran: nobody to pair with


def test_the_main_table_shows_the_loop_on_the_move():
    events = [_event(0.1, speed=0.4), _event(0.12, speed=0.8, at_rest=True), _event(0.5, outcome="missed"),
              _event(0.2, outcome="failed", stage="goal_ik")]
    records = [
        _record("ik", bin_seed=1, in_bin=2, attempted=3, events=events, splices_at_rest=1, near_misses_person=2,
                ssm_holds=1, failures_by_stage={"goal_ik": 3, "planner": 2, "join": 1, "budget": 0},
                splice_speed_median_rad_s=0.6),
        _record("ik", bin_seed=2, in_bin=3, attempted=3, events=[_event(0.1, speed=1.0)], contacts_person=1,
                failures_by_stage={"goal_ik": 0}),
    ]
    headers, rows = moving_bin_rows(records)
    (row,) = rows
    cell = dict(zip(headers, row))
    assert cell["cans in bin / offered"].startswith("5/6 (83% [")
    assert cell["given up (put down)"] == "1 (1)"
    assert cell["missed / failed"] == "1 / 1"
    assert cell["failed by stage"] == "ik 3, join 1, planner 2"
    assert cell["splices (at rest)"] == "3 (1)"
    assert cell["drift splice speed (rad/s)"] == "0.8"  # the median of the splices' 0.4, 0.8, 1.0 (events)
    assert cell["released moving / released"] == "5 / 5"
    assert cell["contacts bin / person"] == "0 / 1"
    assert cell["person near misses / SSM holds"] == "2 / 1"
    assert "latency" not in headers and "release" not in headers and "not attempted" not in headers
    assert stages_cell({}) == "0" and stages_cell(None) == "-"
    # a run mixing modes groups by them and shows them
    mixed = [*records, _record("ik", bin_seed=1, in_bin=3, attempted=3, latency_mode="modelled")]
    headers, rows = moving_bin_rows(mixed)
    assert "latency" in headers and "release" not in headers
    assert [r[headers.index("latency")] for r in rows] == ["measured", "modelled"]


def _paired_records():
    """ik and rrt at 0.2 m/s on five shared bin paths (ik ahead on each), plus what must not pair."""
    a = [(3, 5), (4, 5), (2, 5), (5, 5), (4, 4)]  # ik: 0.6, 0.8, 0.4, 1.0, 1.0
    b = [(2, 5), (2, 5), (1, 5), (3, 5), (3, 4)]  # rrt: 0.4, 0.4, 0.2, 0.6, 0.75
    out = []
    for seed, ((ka, na), (kb, nb)) in enumerate(zip(a, b)):
        out.append(_record("ik", bin_seed=seed, in_bin=ka, attempted=na))
        out.append(_record("rrt", bin_seed=seed, in_bin=kb, attempted=nb))
    out += [
        _record("ik", bin_seed=99, in_bin=0, attempted=5),  # rrt never met this path
        _record("rrt", bin_seed=98, in_bin=5, attempted=5),  # nor ik this one
        _record("ik", bin_seed=7, in_bin=0, attempted=5),
        _record("rrt", bin_seed=7, in_bin=0, attempted=0),  # no can attempted: no rate
        _record("ik", bin_seed=8, in_bin=0, attempted=5),
        _record("rrt", bin_seed=8, in_bin=5, attempted=5, status="error"),  # an error delivers none: 0 of 5
        _record("ik", bin_seed=0, in_bin=0, attempted=5, path_index=1),  # another path of the same seed
        _record("ik", bin_seed=0, in_bin=0, attempted=5, scene_seed=1012),  # another scene
        _record("ik", bin_seed=0, in_bin=0, attempted=5, release_mode="rest"),  # another release mode
        _record("ik", bin_seed=0, in_bin=5, attempted=5, speed=0.4),  # one shared episode at 0.4
        _record("rrt", bin_seed=0, in_bin=0, attempted=5, speed=0.4),
    ]
    return out


def test_paired_differences_pair_episodes_by_their_bin_path(monkeypatch):
    import suite.report.summary_moving_bin_paired as smb

    monkeypatch.setattr(smb, "MIN_PAIRED", 2)  # the arithmetic over few episodes (the rule: its own test)
    monkeypatch.setattr(smb, "MIN_SCENES", 1)
    records = _paired_records()
    diffs = paired_differences(records, planners=("ik", "rrt"))
    at_02 = next(d for d in diffs if d.speed_m_s == 0.2)
    # by hand, seeds 0-4 then 8 (ik 0 of 5, rrt's error 0 of 5): 1.45 / 6
    d = np.array([0.6 - 0.4, 0.8 - 0.4, 0.4 - 0.2, 1.0 - 0.6, 1.0 - 0.75, 0.0])
    assert (at_02.planner_a, at_02.planner_b, at_02.n) == ("ik", "rrt", 6)
    assert math.isclose(at_02.mean_pp, 100 * 1.45 / 6)
    lo, hi = at_02.ci_pp
    assert 0.0 <= lo < 100 * 1.45 / 6 < hi <= 40.0  # within the smallest and largest d
    assert at_02.established and (at_02.a_ahead, at_02.b_ahead) == (5, 0)
    assert (lo, hi) == tuple(100 * v for v in bootstrap_mean_ci(d))  # seeded: the same every time
    at_04 = next(d for d in diffs if d.speed_m_s == 0.4)
    assert at_04.n == 1 and at_04.ci_pp is None and at_04.established is None
    pooled = next(d for d in diffs if d.speed_m_s is None)
    assert pooled.n == 7 and math.isclose(pooled.mean_pp, 100 * (d.sum() + 1.0) / 7)
    # the other order of the planners flips the sign
    flipped = next(x for x in paired_differences(records, planners=("rrt", "ik")) if x.speed_m_s == 0.2)
    assert flipped.planner_a == "rrt" and math.isclose(flipped.mean_pp, -100 * 1.45 / 6) and flipped.established
    headers, rows = paired_rows(records, ("ik", "rrt"))
    assert headers[:3] == ["A - B", "speed (m/s)", "episodes paired"]
    cells = {r[1]: dict(zip(headers, r)) for r in rows}
    assert cells["0.2"]["mean difference (pp)"] == "+24.2" and cells["0.2"]["established"] == "yes"
    assert cells["0.4"]["episodes paired"] == "1 (1 scenes)" and cells["0.4"]["mean difference (pp)"] == "-"
    assert cells["0.4"]["established"] == "-"
    assert cells["all"]["episodes paired"].startswith("7 (")
    # a still bin asks for no replanning: its episodes are not pooled
    still = [_record(p, bin_seed=50, in_bin=k, attempted=5, speed=0.0) for p, k in (("ik", 5), ("rrt", 0))]
    pooled = next(d for d in paired_differences([*records, *still], planners=("ik", "rrt")) if d.speed_m_s is None)
    assert pooled.n == 7


def test_the_interval_resamples_scenes_not_episodes():
    """Episodes of one scene move together: resampling scenes gives a wider interval than
    resampling their episodes as if independent (here two scenes with opposite signs)."""
    d = np.array([0.4, 0.4, 0.4, 0.4, -0.2, -0.2, -0.2, -0.2])
    scenes = ["a"] * 4 + ["b"] * 4
    lo_ep, hi_ep = bootstrap_mean_ci(d)
    lo_sc, hi_sc = bootstrap_mean_ci(d, clusters=scenes)
    assert hi_sc - lo_sc > hi_ep - lo_ep
    assert lo_sc == pytest.approx(-0.2) and hi_sc == pytest.approx(0.4)  # all of a, all of b, or a mix


def test_a_difference_over_too_few_episodes_is_never_established():
    import suite.report.summary_moving_bin_paired as smb

    records = _paired_records()
    at_02 = next(d for d in paired_differences(records, planners=("ik", "rrt")) if d.speed_m_s == 0.2)
    assert at_02.n == 6 < smb.MIN_PAIRED and at_02.ci_pp[0] > 0 and at_02.established is None
    cells = {r[1]: r for r in paired_rows(records, ("ik", "rrt"))[1]}
    assert cells["0.2"][-1].startswith("too few")


def test_a_difference_whose_interval_holds_zero_is_not_established(monkeypatch):
    import suite.report.summary_moving_bin_paired as smb

    monkeypatch.setattr(smb, "MIN_PAIRED", 2)
    monkeypatch.setattr(smb, "MIN_SCENES", 1)
    rates = [(5, 5, 0, 5), (0, 5, 5, 5), (4, 4, 3, 4), (3, 4, 4, 4), (2, 2, 2, 2)]  # d = +1, -1, +.25, -.25, 0
    records = []
    for seed, (ka, na, kb, nb) in enumerate(rates):
        records += [_record("ik", bin_seed=seed, in_bin=ka, attempted=na),
                    _record("trajopt", bin_seed=seed, in_bin=kb, attempted=nb)]
    (diff,) = paired_differences(records, planners=("ik", "trajopt"))
    assert diff.n == 5 and math.isclose(diff.mean_pp, 0.0, abs_tol=1e-9)
    assert diff.ci_pp[0] < 0 < diff.ci_pp[1] and diff.established is False
    assert paired_rows(records, ("ik", "trajopt"))[1][0][-1] == "no"
    # the same cans in the bin on every path: an interval [0, 0] holds 0
    same = [_record(p, bin_seed=seed, in_bin=4, attempted=5) for seed in range(4) for p in ("ik", "trajopt")]
    (diff,) = paired_differences(same)
    assert (diff.n, diff.mean_pp, diff.ci_pp, diff.established) == (4, 0.0, (0.0, 0.0), False)


def test_the_latency_table_comes_from_the_events_step_times():
    parts = [{"world": 0.001, "ik": 0.02, "plan": 0.03, "join": 0.004, "validate": 0.01, "timing": 0.005},
             {"world": 0.003, "ik": 0.04, "plan": 0.05, "join": 0.002, "validate": 0.02, "timing": 0.007},
             {"world": 0.002, "ik": 0.06, "plan": 0.07, "join": 0.006, "validate": 0.03, "timing": 0.009}]
    ev = [_event(sum(p.values()), parts=p) for p in parts]
    records = [
        _record("ik", bin_seed=0, in_bin=1, attempted=1, events=ev[:2],
                latency_parts_s={"ik": [9.0, 9.0]}),  # the events win over the record's summary
        _record("ik", bin_seed=1, in_bin=1, attempted=1,
                events=[ev[2], _event(1.0, parts={"plan": 5.0}, deadline_s=None, trigger="return")]),
        _record("rrt", bin_seed=0, in_bin=1, attempted=1, latency_parts_s={"ik": [0.01, 0.03], "plan": [0.02, 0.05]},
                replan_latency_median_s=0.05, replan_latency_p95_s=0.09),
        _record("rrt", bin_seed=1, in_bin=1, attempted=1, latency_parts_s={"ik": [0.03, 0.07], "plan": [0.04, 0.06]},
                replan_latency_median_s=0.07, replan_latency_p95_s=0.12),
        _record("trajopt", bin_seed=0, in_bin=1, attempted=1, latency_mode="modelled", events=ev),
    ]
    headers, rows = latency_rows(records, ("ik", "rrt", "trajopt"))
    assert headers == ["planner", "over", "world", "ik", "plan", "join", "validate", "timing", "total"]
    by = {r[0]: dict(zip(headers, r)) for r in rows}
    assert set(by) == {"ik", "rrt"}  # modelled latency: no step times shown
    assert by["ik"]["over"] == "3 replans"  # the return (not deadline-bound) left out
    ik_p95 = 1000 * np.quantile([0.02, 0.04, 0.06], 0.95)
    assert by["ik"]["ik"] == f"40 / {ik_p95:.3g}"  # median 40 ms over the three replans
    assert by["ik"]["join"].startswith("4 / ")
    assert by["rrt"]["over"] == "2 episodes"  # no step times in the events: the records' summaries
    assert by["rrt"]["ik"] == "20 / 70" and by["rrt"]["world"] == "-" and by["rrt"]["total"] == "60 / 120"
    text = moving_bin_table(records, planners=("ik", "rrt", "trajopt"))
    assert "Replan latency per step" in text and "the median of their medians" in text
    only_modelled = [r for r in records if r.planner == "trajopt"]
    assert latency_rows(only_modelled) == ([], [])
    assert "Replan latency per step" not in moving_bin_table(only_modelled)


def test_the_figure_is_drawn_from_new_and_old_records(tmp_path):
    from suite.report.plots_moving_bin import plot_moving_bin

    new = plot_moving_bin(_sweep_records(), planners=("ik", "rrt", "trajopt"), path=tmp_path / "new.png")
    old = plot_moving_bin(_old(_records()), planners=("rrt", "gcs"), path=tmp_path / "old.png")
    assert new.stat().st_size > 20_000 and old.stat().st_size > 20_000
    assert plot_moving_bin(_records()[1::2], planners=("gcs",), path=tmp_path / "none.png") is None


def test_the_report_gains_a_moving_bin_section(tmp_path):
    from suite.report.write import write_report

    run = write_run(tmp_path / "run", synthetic_records(variants=("open",), cans=1, planners=("rrt",)),
                    planners=("rrt", "gcs"), cans=1)
    write_moving_bin(run, _records() + _sweep_records(planners=("ik", "rrt"), speeds=(0.2,), paths=1))
    table = write_report(run)
    assert "Moving bin:" in table
    summary = (run / "summary.md").read_text()
    assert "## Moving bin" in summary and "Paired differences between planners" in summary
    assert "| rrt - ik " in summary  # the run's planners first (its manifest: rrt, gcs)
    assert (run / "plots" / "moving_bin.png").stat().st_size > 10_000
    html = (run / "report.html").read_text()
    assert 'id="moving_bin"' in html and "moving_bin.png" in html and "not applicable" in html
    assert "Paired differences between planners" in html and "rrt - ik" in html
