"""The perceived-world lines read typed execution records."""

from __future__ import annotations

from suite.execution.execution_records import ExecutionRecord
from suite.report.summary_perceived import paired_lines, perceived_world_lines


def _execution(planner: str, seed: int, in_bin: int, **extra) -> ExecutionRecord:
    return ExecutionRecord(planner=planner, scene_seed=seed, variant="open", cans_total=4, cans_in_bin=in_bin, **extra)


def test_paired_lines_count_cans_and_perception_induced_failures():
    base = [_execution("rrt", 0, 4), _execution("rrt", 1, 3)]
    other = [_execution("rrt", 0, 2, perception_induced=[{"cause": "missed"}]), _execution("rrt", 1, 3)]
    (line,) = paired_lines(base, other, planners=["rrt", "ik"])
    assert "2 scenes, cans in the bin 7/8 -> 5/8" in line and "perception-induced failures 1" in line
    assert "scenes worse 1, better 0" in line


def test_perceived_world_lines_name_the_worlds_and_causes():
    world = {"build_time_s": 0.5, "boxes": 10, "voxel_m": 0.01, "can_padding_m": 0.005}
    recs = [_execution("rrt", 0, 3, perceived_worlds=[world], planning_time_s=2.0,
                       perception_induced=[{"cause": "missed"}, {"cause": "missed"}])]
    lines = perceived_world_lines(recs, planners=["rrt"])
    assert lines[0].startswith("  perceived worlds: 1, voxel 10 mm")
    assert lines[1] == "  rrt: perception-induced failures missed 2"
