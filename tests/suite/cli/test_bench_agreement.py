"""bench agreement: the classification of a disagreement, the exact capsule reference, and a small
run that finds the two engines agreeing (skipped without roboplan)."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("roboplan")

from suite.bench.agreement import segment_distance  # noqa: E402
from suite.bench.agreement_pairs import PairMeasure, classify  # noqa: E402


def _pair(*, fcl_collide, coal_collide, swapped, epa, fcl_d, coal_d, a="held_can", b="can_2", shapes="cylinder-cylinder"):
    return PairMeasure(a, b, shapes, fcl_collide, coal_collide, swapped, epa, fcl_d, coal_d)


def test_a_deep_pair_coal_misses_in_roboplans_order_is_named():
    p = _pair(fcl_collide=True, coal_collide=False, swapped=True, epa=True, fcl_d=-0.022, coal_d=-0.022)
    kind = classify(fcl_free=False, roboplan_free=True, roboplan_debug_hit=False, pairs=[p])
    assert kind == ("coal collide misses cylinder-cylinder held_can-can_2 in roboplan's order; "
                    "found in the other order, and with EPA")


def test_shallow_contacts_and_broadphase_are_told_apart():
    touching = _pair(fcl_collide=True, coal_collide=False, swapped=False, epa=False, fcl_d=-4e-7, coal_d=2e-7)
    assert classify(fcl_free=False, roboplan_free=True, roboplan_debug_hit=False, pairs=[touching]) == "shallow contact"
    deep = _pair(fcl_collide=True, coal_collide=True, swapped=True, epa=True, fcl_d=-0.01, coal_d=-0.01)
    # the exhaustive check finds it, the broadphase query did not
    assert classify(fcl_free=False, roboplan_free=True, roboplan_debug_hit=True, pairs=[deep]) == "broadphase"
    phantom = _pair(fcl_collide=False, coal_collide=True, swapped=True, epa=True, fcl_d=-0.003, coal_d=-0.003)
    assert classify(fcl_free=True, roboplan_free=False, roboplan_debug_hit=True, pairs=[phantom]).startswith(
        "fcl collide misses cylinder-cylinder")


def test_segment_distance_matches_a_dense_search():
    rng = np.random.default_rng(4)
    for _ in range(50):
        p1, q1, p2, q2 = rng.normal(size=(4, 3))
        t = np.linspace(0, 1, 801)
        A = p1 + t[:, None] * (q1 - p1)
        B = p2 + t[:, None] * (q2 - p2)
        dense = np.min(np.linalg.norm(A[:, None] - B[None], axis=2))
        exact = segment_distance(p1, q1, p2, q2)
        assert exact <= dense + 1e-12 and dense - exact < 5e-3
    assert segment_distance(*np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)) == pytest.approx(1.0)


def test_a_small_run_agrees_and_reports_both_engines(tmp_path, capsys):
    from suite.cli import main

    out = tmp_path / "agreement.json"
    rc = main(["bench", "agreement", "--configs", "300", "--families", "wall", "--worlds", "2",
               "--distance-configs", "4", "--self-sweep", "50", "--json", str(out)])
    assert rc == 0
    (row,) = json.loads(out.read_text())["families"]
    assert row["configs"] == 300 and row["worlds"] == 2 and row["held_worlds"] == 1
    assert row["agree"] == 300 and row["disagreements"] == []
    assert 0 < row["fcl_free"] < 300
    assert row["pose_and_distance"]["pose_max_translation_m"] < 1e-12
    text = capsys.readouterr().out
    assert "roboplan checks/s" in text and "wall" in text
