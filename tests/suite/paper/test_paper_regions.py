"""The GCS paper's own regions as data (no pickle at run time), the paper's IRIS settings mapped
field by field, and `gcs` planning on the paper's regions."""

from __future__ import annotations

import numpy as np
import pytest

from scenes.errors import SuiteError
from suite.paper.paper_regions import NAMES, PAPER_REGIONS_DIR, REGIONS_FILE, load_paper_regions

#: The final notebook's IrisOptions (prm_comparison.ipynb at 3d781488) -> (our field, value).
NOTEBOOK_IRIS = {
    "iteration_limit": ("max_iterations", 10),
    "termination_threshold": ("termination_threshold", -1.0),
    "relative_termination_threshold": ("relative_termination_threshold", 0.02),
    "require_sample_point_is_contained": ("require_sample_point_is_contained", True),
    "random_seed": ("random_seed", 0),
    "configuration_space_margin": ("configuration_space_margin_rad", 0.01),  # unset there: Drake's 1e-2
}


def _task(label: str):
    from suite.paper.gcs_arm_report import task_labels
    from suite.problems.dataset import load_dataset

    labels = task_labels("gcs-arm")
    ds = load_dataset("gcs-arm:tasks")
    return next(p for pid, p in zip(ds.ids, ds.problems) if labels[pid] == label)


def test_the_papers_regions_load_as_plain_arrays():
    names, A, b = load_paper_regions()
    assert tuple(names) == NAMES and len(names) == 9
    faces = {"TS": 92, "CS": 54, "BS": 54, "LB": 85, "RB": 103, "C": 53, "L": 42, "R": 91, "AS": 113}
    for n, a, c in zip(names, A, b):
        assert a.shape == (faces[n], 7) and c.shape == (faces[n],) and a.dtype == np.float64
    i, j = names.index("CS"), names.index("BS")  # BS is a copy of CS in the source file
    assert np.array_equal(A[i], A[j]) and np.array_equal(b[i], b[j])
    with np.load(PAPER_REGIONS_DIR / REGIONS_FILE, allow_pickle=False) as z:  # no object arrays: no pickle
        assert all(z[k].dtype != object for k in z.files)
    assert {p.name for p in PAPER_REGIONS_DIR.iterdir()} == {REGIONS_FILE, "source.json", "LICENSE.TXT"}
    assert "BSD 3-Clause" in (PAPER_REGIONS_DIR / "LICENSE.TXT").read_text()


def test_the_conversion_refuses_another_file_and_any_other_class():
    import pickle

    from suite.paper.paper_regions import _Unpickler, convert

    with pytest.raises(SuiteError, match="git blob id"):
        convert(b"not the paper's file")
    import io

    with pytest.raises(SuiteError, match="refusing to unpickle os.system"):
        _Unpickler(io.BytesIO(b"cos\nsystem\n(S'true'\ntR.")).load()
    assert pickle  # the restricted unpickler is pickle's own, with find_class limited


@pytest.mark.parametrize("notebook_name", sorted(NOTEBOOK_IRIS))
def test_paper_gcs_maps_each_notebook_iris_option(notebook_name):
    """Each IrisOptions field the notebook sets is named in PAPER_GCS (dropping one fails here, even
    where `gcs`'s tuned setting happens to agree) and reaches IrisNp2 with the notebook's value."""
    from planners.gcs.planner import GcsPlanner
    from planners.gcs.iris import iris_options
    from suite.paper.gcs_arm_protocol import PAPER_GCS
    from suite.run.trial import make_config

    field, value = NOTEBOOK_IRIS[notebook_name]
    assert PAPER_GCS[field] == value
    s = iris_options(make_config(GcsPlanner, PAPER_GCS).region_options()).sampled_iris_options
    drake_name = {"iteration_limit": "max_iterations"}.get(notebook_name, notebook_name)
    assert getattr(s, drake_name) == value


def test_the_unmapped_notebook_option_is_documented():
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[3] / "docs" / "gcs-paper-sources.md").read_text()
    assert "num_collision_infeasible_samples" in doc and "no counterpart" in doc


def test_gcs_plans_on_the_papers_regions(tmp_path):
    """The switch: a region set of the paper's regions in `regions_dir`, `build_regions` off, and
    `gcs` plans RB->AS on the paper's 9 regions; the path passes the validator, about the paper's 1.8 rad."""
    from planners.gcs.planner import GcsPlanner
    from planners.worlds import collision_world
    from suite.paper.gcs_arm_protocol import PAPER_GCS, parse_region_sets
    from suite.paper.paper_regions import write_paper_region_set
    from suite.run.trial import make_config
    from suite.scoring.polyline import path_length_rad
    from suite.scoring.validate import validate_path

    problem = _task("RB->AS")
    base = make_config(GcsPlanner, PAPER_GCS)
    write_paper_region_set(problem, base.region_options(), tmp_path)
    planner = GcsPlanner(make_config(GcsPlanner, {**PAPER_GCS, "regions_dir": str(tmp_path), "build_regions": False}))
    planner.prepare(problem)
    result = planner.plan(problem)
    assert result.stats["num_regions"] == 9 and result.stats["regions_cache"] == "hit"
    assert result.path is not None, result.stats.get("reason")
    assert validate_path(problem, np.asarray(result.path), collision_world(problem)) is None
    assert path_length_rad(result.path) == pytest.approx(1.80, abs=0.05)
    assert parse_region_sets("both") == ("ours", "paper") and parse_region_sets("paper") == ("paper",)
    with pytest.raises(SuiteError, match="allowed: ours, paper, both"):
        parse_region_sets("theirs")


def test_linear_gcs_on_the_papers_regions_reaches_the_papers_length():
    """The paper's formulation on its own regions: RB->AS relaxed and rounded at about 1.8 rad."""
    from planners.gcs.sets import RegionOptions
    from suite.paper.paper_regions import linear_gcs, paper_region_set

    problem = _task("RB->AS")
    names, A, b = load_paper_regions()
    out = linear_gcs(A, b, paper_region_set(problem, RegionOptions()).edges, problem.q_start, problem.q_goal)
    assert [names[i] for i in out["start_regions"]] == ["RB"] and [names[i] for i in out["goal_regions"]] == ["AS"]
    assert out["rounded_rad"] == pytest.approx(1.80, abs=0.01)
    assert out["relaxed_rad"] <= out["rounded_rad"] + 1e-6
    wp = np.asarray(out["waypoints"])
    np.testing.assert_allclose(wp[0], problem.q_start, atol=1e-6)
    np.testing.assert_allclose(wp[-1], problem.q_goal, atol=1e-6)
    assert np.sum(np.linalg.norm(np.diff(wp, axis=0), axis=1)) == pytest.approx(out["rounded_rad"], rel=1e-4)
