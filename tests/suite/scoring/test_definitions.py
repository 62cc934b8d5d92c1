"""The metric registry: unique names carrying their units, a direction and a definition each."""

from __future__ import annotations

import pytest

from scenes.errors import SuiteError
from suite.scoring.definitions import (
    METRICS,
    headline_metrics,
    markdown_table,
    metric_def,
)


def test_the_registry_names_units_and_directions():
    names = [m.name for m in METRICS]
    assert len(names) == len(set(names))
    assert all(m.direction in ("lower", "higher", "none") and m.definition and m.unit for m in METRICS)
    # A name ends with its unit where it has one.
    suffix = {"s": "_s", "rad": "_rad", "m": "_m", "deg": "_deg", "m^3": "_m3"}
    assert all(m.name.endswith(suffix[m.unit]) for m in METRICS if m.unit in suffix)
    assert metric_def("turning_angle_rad").direction == "lower" and metric_def("sparc").direction == "higher"
    assert markdown_table().count("\n") == len(METRICS) + 1


def test_an_unknown_metric_is_an_error_naming_the_known_ones():
    with pytest.raises(SuiteError, match="unknown metric 'smoothnes'.*turning_angle_rad"):
        metric_def("smoothnes")
    assert "smoothness" not in {m.name for m in headline_metrics()}
