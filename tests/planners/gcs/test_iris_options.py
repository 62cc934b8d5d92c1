"""`gcs`'s IRIS options: every option Drake's IRIS reads is set from `RegionOptions` (none left to a
default a reader cannot see), the options named late keep the shipped region sets' names while they
hold the values those sets were built with, and each region records what its IRIS call did."""

import dataclasses

import numpy as np
import pytest

from planners.gcs.iris import _IrisLog, iris_options
from planners.gcs.regions import regions_for
from planners.gcs.sets import UNKEYED_DEFAULTS, RegionOptions, RegionSet, world_hash
from scenes.errors import SuiteError

#: What Drake's IRIS options hold that `RegionOptions` deliberately does not name (see its
#: docstring): set by the suite itself, or never changed from the identity / none.
NOT_OPTIONS = {"parameterization", "solver_options", "prog_with_additional_constraints", "meshcat", "verbose",
               "containment_points", "parallelism", "solver"}
#: Drake's name -> ours, where they differ.
RENAMED = {"configuration_space_margin": "configuration_space_margin_rad", "sampling_strategy": "sampling_strategy",
           "num_threads": "threads"}


def _public(obj) -> set[str]:
    return {a for a in dir(obj) if not a.startswith("_") and not callable(getattr(obj, a))}


@pytest.mark.parametrize("iris", ["np2", "zo"])
def test_every_option_drake_reads_is_a_region_option_and_is_set(iris):
    from pydrake.planning import IrisNp2Options, IrisZoOptions

    fields = {f.name for f in dataclasses.fields(RegionOptions)}
    drake = IrisNp2Options() if iris == "np2" else IrisZoOptions()
    names = (_public(drake) | _public(drake.sampled_iris_options)) - {"sampled_iris_options", "ray_sampler_options"}
    if iris == "np2":
        names |= _public(drake.ray_sampler_options)
    unmapped = {n for n in names - NOT_OPTIONS if RENAMED.get(n, n) not in fields}
    assert not unmapped, f"Drake's IRIS reads options gcs does not name: {sorted(unmapped)}"
    # Every one is set from the options: change each from Drake's default and read it back.
    changed = RegionOptions(iris=iris, termination_threshold=-1.0, relative_termination_threshold=0.02, tau=0.4,
                            mixing_steps=7, require_sample_point_is_contained=False,
                            remove_all_collisions_possible=False, relax_margin=False, sample_particles_in_parallel=True,
                            sampling_strategy="ray", ray_search_num_steps=3, num_particles_to_walk_towards=9,
                            only_walk_toward_collisions=True, add_hyperplane_if_solve_fails=True, np2_solver="ipopt",
                            bisection_steps=4, max_iterations=7, random_seed=5, num_particles=77)
    opts = iris_options(changed)
    s = opts.sampled_iris_options
    assert (s.termination_threshold, s.relative_termination_threshold, s.tau, s.mixing_steps) == (-1.0, 0.02, 0.4, 7)
    assert not s.require_sample_point_is_contained and not s.remove_all_collisions_possible and not s.relax_margin
    assert s.sample_particles_in_parallel and s.max_iterations == 7 and s.random_seed == 5 and s.num_particles == 77
    if iris == "np2":
        r = opts.ray_sampler_options
        assert opts.sampling_strategy == "ray" and opts.add_hyperplane_if_solve_fails
        assert (r.ray_search_num_steps, r.num_particles_to_walk_towards, r.only_walk_toward_collisions) == (3, 9, True)
        assert type(opts.solver).__name__ == "IpoptSolver"
    else:
        assert opts.bisection_steps == 4


def test_the_late_options_default_to_drakes_and_stay_out_of_the_key_until_changed():
    from pydrake.planning import IrisNp2Options

    drake = IrisNp2Options()
    s = drake.sampled_iris_options
    defaults = RegionOptions()
    for name in ("tau", "mixing_steps", "require_sample_point_is_contained", "remove_all_collisions_possible",
                 "sample_particles_in_parallel"):
        assert getattr(defaults, name) == getattr(s, name) == UNKEYED_DEFAULTS[name], name
    for name in ("termination_threshold", "relative_termination_threshold"):  # the sets before were Drake's
        assert getattr(s, name) == UNKEYED_DEFAULTS[name], name
    assert (defaults.termination_threshold, defaults.relative_termination_threshold) == (-1.0, 0.02)  # the paper's
    assert defaults.relax_margin is True  # always on here, before it was named
    assert defaults.max_iterations == 1 and not set(UNKEYED_DEFAULTS) & set(defaults.key_fields())
    # With one iteration the thresholds cannot change a region, so they stay out of the key; with
    # more they enter it, unless they hold the values the earlier sets were built with.
    three = RegionOptions(max_iterations=3).key_fields()
    assert (three["termination_threshold"], three["relative_termination_threshold"]) == (-1.0, 0.02)
    drakes = RegionOptions(max_iterations=3, termination_threshold=0.02, relative_termination_threshold=0.001)
    assert "termination_threshold" not in drakes.key_fields()
    assert RegionOptions(tau=0.4).key_fields()["tau"] == 0.4
    with pytest.raises(SuiteError, match="sampling_strategy='spiral'; allowed: greedy, ray"):
        RegionOptions(sampling_strategy="spiral")
    with pytest.raises(SuiteError, match="np2_solver='nlopt'"):
        RegionOptions(np2_solver="nlopt")


def test_a_shipped_region_set_still_loads_under_its_name():
    """The shipped sets were built before the late options were named: gcs's settings still find them."""
    from planners.gcs.planner import GcsPlanner
    from suite.problems.dataset import load_dataset
    from suite.run.trial import make_config

    problem = next(p for p in load_dataset("recycle-v3.1:quick").problems if p.pre_status is None and p.q_goal is not None)
    options = make_config(GcsPlanner, {}).region_options()
    rs, info = regions_for(problem, options, build=False)
    assert info["cache"] == "hit", (world_hash(problem, options), info)
    assert "/scenes/datasets/" in info["path"] and len(rs) >= 1


def test_the_iris_log_says_how_many_iterations_ran_and_why_they_stopped():
    lines = _IrisLog()
    for message in ("IrisNp2 iteration 0", "IrisNp2 probabilistic test passed!", "IrisNp2 iteration 1",
                    "IrisNp2: Terminating because the hyperellipsoid volume change 0.001 is below the threshold 0.02."):
        lines.emit(_record(message))
    assert lines.summary() == {"iterations": 2, "stop": ["absolute_threshold"]}
    zo = _IrisLog()
    for message in ("IrisZo outer iteration 0", "IrisZo reldelta vol 0.001, threshold 0.02"):
        zo.emit(_record(message))
    assert zo.summary() == {"iterations": 1, "stop": ["relative_threshold"]}
    assert _IrisLog().summary() == {"iterations": 0, "stop": ["unknown"]}


def _record(message: str):
    import logging

    return logging.LogRecord("drake", logging.INFO, __file__, 0, message, None, None)


def test_a_grown_region_records_its_iterations_stop_and_inscribed_volume(open_transit):
    """A real IrisZo region with the absolute threshold off runs to its iteration limit (or stops for a
    reason it names), and the region records it with the inscribed ellipsoid's volume."""
    from planners.gcs.iris import RegionBuilder
    from planners.gcs.regions import _add_region
    from planners.worlds import planning_world

    options = RegionOptions(iris="zo", num_particles=100, max_iterations=2, termination_threshold=-1.0,
                            relative_termination_threshold=-1.0, check_rounds=1, check_samples=50, padding_m=0.0)
    rs = RegionSet("test")
    q = np.asarray(open_transit.q_start, float)
    assert _add_region(rs, RegionBuilder(open_transit, options), planning_world(open_transit), q)
    (record,) = rs.region_iris
    assert 1 <= record["iterations"] <= 2 and record["stop"] and "absolute_threshold" not in record["stop"]
    if record["iterations"] == 2:
        assert record["stop"] == ["iteration_limit"]
    assert record["volume"] > 0 and 0 < record["radius_rad"] < 10


def test_regions_report_reads_the_cached_sets_per_family(tmp_path, capsys):
    """`regions report` grows nothing: it reads the shipped gcs-arm set at gcs's settings, counts one
    iteration per region for a set built before iterations were recorded at a limit of 1, and says
    which worlds of another setting are not built."""
    import json as _json

    from planners.gcs import iris
    from suite.cli import main

    before = iris.GROWN_IN_PROCESS
    out = tmp_path / "report.json"
    assert main(["regions", "report", "--dataset", "gcs-arm:tasks", "--json", str(out)]) == 0
    rep = _json.loads(out.read_text())
    (fam, every) = rep["families"]
    assert fam["family"] == "gcs-arm" and every["family"] == "all" and fam["worlds"] == 1
    assert fam["iterations_max"] == 1 and fam["stops"] == {"iteration_limit": fam["regions_per_world"]}
    assert 0 <= fam["linked"] <= fam["problems"] == 5 and fam["radius_rad_median"] > 0
    assert iris.GROWN_IN_PROCESS == before
    capsys.readouterr()
    assert main(["regions", "report", "--dataset", "gcs-arm:tasks", "--set", "max_iterations=7"]) == 1
    assert "1 world(s) have no cached set at these options" in capsys.readouterr().out
    assert main(["regions", "report", "--dataset", "gcs-arm:tasks", "--set", "iterations=7"]) == 2
    assert "expected NAME=VALUE with NAME one of" in capsys.readouterr().err


@pytest.mark.parametrize("tier", ["recycle-v3.1:quick", "recycle-v3:quick"])
def test_every_world_of_a_shipped_tier_still_finds_its_set(tier):
    """Every collision world of the shipped quick tiers finds its region set under gcs's settings
    (the late options and the thresholds kept out of the key)."""
    from planners.gcs.planner import GcsPlanner
    from planners.gcs.sets import find_cached
    from suite.problems.dataset import load_dataset
    from suite.run.trial import make_config

    options = make_config(GcsPlanner, {}).region_options()
    worlds = {world_hash(p, options) for p in load_dataset(tier).problems if p.pre_status is None and p.q_goal is not None}
    missing = [w for w in worlds if find_cached(w, None) is None]
    assert len(worlds) > 50 and not missing, missing
