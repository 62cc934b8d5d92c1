"""The moving-bin section of a run's report, from moving_bin.json alone."""

import math

from synthetic_runs import synthetic_records, write_run

from scenes.moving_bin import make_scenario
from suite.execution.jobs import read_moving_bin, write_moving_bin
from suite.execution.moving_bin import CanEpisode, MovingBinRecord, ReplanEvent
from suite.report.summary_moving_bin import moving_bin_rows, speed_cells


def _records():
    out = []
    for speed, in_bin, latencies in ((0.0, 2, (0.05,)), (0.2, 1, (0.1, 0.2, 0.5))):
        scenario = make_scenario({"speed_m_s": speed}).to_json()
        events = tuple(ReplanEvent(1.0 + i, 0, "drift", 0.05, lat, 0.3, "spliced" if lat <= 0.3 else "missed",
                                   jump_q_rad=0.0 if lat <= 0.3 else None, jump_v_rad_s=0.0 if lat <= 0.3 else None)
                       for i, lat in enumerate(latencies))
        out.append(MovingBinRecord(
            planner="rrt", scene_seed=0, variant="open", speed_m_s=speed, scenario=scenario, status="ok",
            cans_total=2, cans_attempted=2, cans_in_bin=in_bin, cans_released=2, replans=len(events),
            splices=sum(e.outcome == "spliced" for e in events),
            deadline_misses=sum(e.outcome == "missed" for e in events), contacts_person=int(speed > 0),
            cans=(CanEpisode(0, True, 2.0, 0.01), CanEpisode(1, True, 3.0, 0.02)), events=events).to_json())
        out.append(MovingBinRecord("gcs", 0, "open", speed, scenario, "not_applicable",
                                   "its convex regions are built offline for one fixed world", cans_total=2).to_json())
    return out


def test_moving_bin_cells_count_cans_latency_and_misses(tmp_path):
    records = _records()
    write_moving_bin(tmp_path, records)
    assert read_moving_bin(tmp_path) == records
    rrt = [c for c in speed_cells(records) if c.planner == "rrt"]
    assert [c.speed_m_s for c in rrt] == [0.0, 0.2]
    fast = rrt[1]
    assert (fast.cans_in_bin, fast.cans_total, fast.deadline_misses, fast.contacts_person) == (1, 2, 1, 1)
    assert fast.latencies_s == (0.1, 0.2, 0.5) and math.isclose(fast.replans_per_can, 1.5)
    assert fast.ci95[0] < 0.5 < fast.ci95[1]
    headers, rows = moving_bin_rows(records)
    gcs = [r for r in rows if r[0] == "gcs"]
    assert len(gcs) == 2 and gcs[0][3].startswith("not applicable: its convex regions")


def test_the_report_gains_a_moving_bin_section(tmp_path):
    from suite.report.write import write_report

    run = write_run(tmp_path / "run", synthetic_records(variants=("open",), cans=1, planners=("rrt",)),
                    planners=("rrt", "gcs"), cans=1)
    write_moving_bin(run, _records())
    table = write_report(run)
    assert "Moving bin:" in table
    assert "## Moving bin" in (run / "summary.md").read_text()
    assert (run / "plots" / "moving_bin.png").stat().st_size > 10_000
    html = (run / "report.html").read_text()
    assert 'id="moving_bin"' in html and "moving_bin.png" in html and "not applicable" in html
