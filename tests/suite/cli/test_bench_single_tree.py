"""`bench single-tree`: OMPL's plain RRT beside the tuned `rrtstar` on the same problems."""

import pytest

from planners.tuned import tuned_settings
from scenes.errors import SuiteError
from suite.bench import single_tree


def test_the_ablation_runs_both_planners_on_the_same_problems():
    out = single_tree.measure(single_tree.DEFAULT_DATASET, budget_s=0.3, ranges=[0.5, None], limit=2)
    assert out["problems"] == 2
    planners = [(r["planner"], r["range_rad"]) for r in out["rows"]]
    tuned = tuned_settings("rrtstar")  # the ablation runs rrtstar as tuned, and the plain tree with its goal bias
    assert planners == [("rrtstar (tuned)", tuned.get("range_rad")), ("plain RRT", 0.5), ("plain RRT", None)]
    assert all(0 <= r["solved"] <= 2 and r["goal_bias"] == tuned.get("goal_bias", 0.05) for r in out["rows"])


def test_the_plain_tree_is_ompl_rrt_not_rrtstar(wall_transit):
    from planners.ompl_rrt import RRTstarConfig

    result = single_tree._plain_rrt_class()(RRTstarConfig(range_rad=0.5)).plan(wall_transit.with_(time_limit_s=1.0))
    assert result.stats["solver"] == "RRT" and "best_cost" not in result.stats


def test_bad_ranges_are_refused():
    assert single_tree.parse_ranges("none, 0.5") == [None, 0.5]
    with pytest.raises(SuiteError, match="'x'"):
        single_tree.parse_ranges("0.5,x")
    with pytest.raises(SuiteError, match="'-1'"):
        single_tree.parse_ranges("-1")
