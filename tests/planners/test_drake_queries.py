"""Counting Drake's distance queries inside SNOPT: the callback sees every evaluation, its sample is
uniform and deterministic, and a replay times the constraint at the sampled iterates."""

import numpy as np
import pytest

import planners.drake_queries as dq


def test_the_callback_counts_every_evaluation_of_a_snopt_program():
    from pydrake.solvers import MathematicalProgram, SnoptSolver

    prog = MathematicalProgram()
    x = prog.NewContinuousVariables(2)
    seen = {"constraint": 0}

    def ring(v):
        seen["constraint"] += 1
        return np.array([v[0] ** 2 + v[1] ** 2])

    prog.AddCost((x[0] - 1) ** 2 + (x[1] - 2) ** 2)
    prog.AddConstraint(ring, [0.0], [1.0], vars=x)
    counter = dq.EvaluationCounter()
    prog.AddVisualizationCallback(counter, x)
    assert SnoptSolver().Solve(prog, np.zeros(2)).is_success()
    assert counter.calls == seen["constraint"] > 1
    assert 0 < len(counter.sample) <= dq.REPLAY_QUERIES


def test_the_sample_is_bounded_uniform_and_deterministic():
    def fill(n):
        c = dq.EvaluationCounter()
        for k in range(n):
            c(np.array([float(k)]))
        return c

    a, b = fill(5000), fill(5000)
    assert a.calls == 5000 and len(a.sample) == dq.REPLAY_QUERIES
    assert [s[0] for s in a.sample] == [s[0] for s in b.sample]  # seeded
    assert np.mean([s[0] for s in a.sample]) > 1000  # not just the first evaluations
    a.restart()
    assert a.sample == [] and a.calls == 5000
    assert len(fill(3).sample) == 3


def test_query_stats_count_exactly_and_replay_finite_configurations(open_transit):
    from planners.worlds import drake_plan_scene
    from pydrake.multibody.inverse_kinematics import MinimumDistanceLowerBoundConstraint

    ds = drake_plan_scene(open_transit)
    ctx = ds.plant.GetMyMutableContextFromRoot(ds.diagram.CreateDefaultContext())
    c = MinimumDistanceLowerBoundConstraint(ds.plant, 0.001, ctx, None, 0.05)
    qs = np.linspace(open_transit.q_start, open_transit.q_goal, 4)
    out = dq.query_stats(1000, c, np.vstack([qs, np.full(7, np.nan)]))
    assert out["drake_distance_queries"] == 1000
    # timed, and scaled to the 1000 queries (over 0.1 us a query; how fast is the machine's business)
    assert 1000 * 1e-7 < out["drake_distance_query_s"] < float("inf")
    assert dq.query_stats(0, c, qs) == {"drake_distance_queries": 0, "drake_distance_query_s": 0.0}
    assert dq.replay_seconds(c, np.full((2, 7), np.nan)) is None


def test_attribution_adds_the_engines_it_was_given():
    from suite.run.trial import attribute

    stats = {"drake_distance_queries": 300, "drake_distance_query_s": 0.03}
    a = attribute(stats, 0.2, fcl=(100, 0.01))
    assert a["engine"] == "python-fcl+drake" and a["queries"] == 400
    assert a["query_s"] == pytest.approx(0.04) and a["other_s"] == pytest.approx(0.16)
    assert a["parts"]["drake"]["timing"] == "replayed" and a["parts"]["python-fcl"]["timing"] == "clocked"
    assert attribute({}, 0.2, fcl=(0, 0.0))["query_share"] == 0.0  # asked nothing: all time elsewhere
    assert attribute({}, 0.2) is None  # nothing counted
