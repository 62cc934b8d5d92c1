"""`bench lookalike`: the refusal curve is counted from the scene records as documented."""

from __future__ import annotations

import pytest

from scenes.errors import SuiteError
from suite.bench.lookalike import curve, file_name, parse_sensors, parse_waists, sensor_model, table_lines


def _rec(*, paper, robust, top, hourglasses=2):
    """A scene of 3 cans (ids 0-2) and a dented can (id 3); per pipeline (hourglasses grasped, ids found)."""
    row = {name: {"hourglasses": hourglasses, "hourglasses_grasped": g, "found": list(found), "detections": len(found) + g,
                  "distractor_grasps": 0} for name, (g, found) in (("paper", paper), ("robust", robust), ("robust-top", top))}
    return {"seed": 1, "key": "k", "cans": 3, "dented": 1, "dented_ids": [3], "by_waist": {"0.8": row}}


def test_the_curve_counts_refusals_recall_and_what_the_side_check_refused():
    records = [_rec(paper=(2, (0, 1, 2, 3)), robust=(0, (0, 2)), top=(2, (0, 1, 2, 3))),
               _rec(paper=(2, (0, 1, 2)), robust=(1, (0, 1, 2)), top=(2, (0, 1, 2)))]
    rows = {r["pipeline"]: r for r in curve(records, (0.8,))}
    paper, robust = rows["paper"], rows["robust"]
    assert (paper["hourglasses"], paper["hourglasses_refused"], paper["refused"]) == (4, 0, 0.0)
    assert (robust["hourglasses_refused"], robust["refused"]) == (3, 0.75)
    lo, hi = robust["refused_ci95"]
    assert lo < 0.75 < hi
    assert (robust["cans"], robust["cans_found"], robust["dented"], robust["dented_found"]) == (6, 5, 2, 0)
    # found by robust-top, not by robust: can 1 and the dented can 3 of the first scene
    assert (robust["cans_refused_by_side_check"], robust["dented_refused_by_side_check"]) == (1, 1)
    assert "cans_refused_by_side_check" not in paper
    doc = {"seeds": [1, 2], "scenes": 2, "sensor": "none", "segmentation": "geometric",
           "pipelines": {"paper": {"cameras": ["top"]}}, "curve": list(rows.values())}
    assert any("3/4 75%" in line for line in table_lines(doc))


def test_bad_waists_and_sensors_are_refused_naming_the_value():
    assert parse_waists("0.55,0.8,1") == (0.55, 0.8, 1.0)
    with pytest.raises(SuiteError, match=r"1\.2 is outside \(0, 1\]"):
        parse_waists("0.8,1.2")
    with pytest.raises(SuiteError, match="'wide' is not a number"):
        parse_waists("wide")
    assert parse_sensors("none,kinect-v1,kinect-v1@8") == ("none", "kinect-v1", "kinect-v1@8")
    assert sensor_model("none") is None and sensor_model("kinect-v1@8").correlation_px == 8.0
    assert file_name("kinect-v1@8") == "kinect-v1-corr8px.json" and file_name("none") == "none.json"
    with pytest.raises(SuiteError, match="unknown sensor 'kinect-v9'; allowed: none, "):
        parse_sensors("kinect-v9")
    with pytest.raises(SuiteError, match="'kinect-v1@wide': the correlation length"):
        parse_sensors("kinect-v1@wide")
