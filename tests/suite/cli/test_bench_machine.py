"""`bench machine`: the pinned workload that scales the README's timings to a reader's machine.

These assert what it prints and writes, never how fast anything is."""

from __future__ import annotations

import dataclasses
import json

import pytest

from scenes.errors import SuiteError
from suite.bench.machine import (FIGURES, REFERENCE_FILE, WORKLOAD, World, _worlds, check_workload, factor,
                                 quickstart_check, read_reference)
from suite.cli import main

FIGS = dict.fromkeys(FIGURES, 10.0)


def test_the_factor_is_the_geometric_mean_of_the_ratios():
    ref = dict.fromkeys(FIGURES, 10.0)
    assert factor(dict.fromkeys(FIGURES, 20.0), ref) == pytest.approx(2.0)
    assert factor({"fcl_state_us": 40.0, "fcl_motion_us": 10.0, "kernel_motion_us": 10.0, "drake_state_us": 2.5},
                  ref) == pytest.approx(1.0)


def test_the_workload_is_pinned_and_its_digest_stable():
    # recycle-v3's first problem of each family in its quick tier, not the default dataset's
    assert WORKLOAD.dataset == "recycle-v3" and WORKLOAD.dataset_hash == "9434c72dfb14354ad61a"
    assert [w.family for w in WORKLOAD.worlds] == ["open", "wall", "station", "shelf", "window", "clutter"]
    assert WORKLOAD.segments == 204 and WORKLOAD.configs_per_world == 1000 and WORKLOAD.config_seed == 20261126
    assert WORKLOAD.motion_resolution_rad == 0.05
    # a change of any field is a new workload: the reference must be re-measured with it
    assert WORKLOAD.digest() == "5fba7233c8e564ba"
    assert dataclasses.replace(WORKLOAD, config_seed=1).digest() != WORKLOAD.digest()
    saved = json.loads(json.dumps(WORKLOAD.to_json()))
    assert saved["digest"] == WORKLOAD.digest() and saved["segments"] == 204


def test_the_pinned_worlds_are_those_the_dataset_ships():
    worlds = _worlds(WORKLOAD)
    assert [w.problem_id for w, _, _ in worlds] == [w.problem_id for w in WORKLOAD.worlds]
    assert sum(len(ref) - 1 for _, _, ref in worlds) == 204


@pytest.mark.parametrize("change, words", [
    (dict(dataset_hash="0" * 20), "has hash 9434c72dfb14354ad61a, the pinned workload's is 00000000000000000000"),
    (dict(worlds=(World("open", "0" * 20, 99, "0" * 16),)), "holds no problem 00000000000000000000"),
    (dict(worlds=(dataclasses.replace(WORKLOAD.worlds[0], reference_sha="0" * 16),)), "is not the pinned one"),
])
def test_a_dataset_that_is_not_the_pinned_one_is_refused(change, words):
    with pytest.raises(SuiteError, match=words):
        _worlds(dataclasses.replace(WORKLOAD, **change))


def test_a_reference_on_the_same_workload_is_accepted():
    ref = {"figures": FIGS, "workload": json.loads(json.dumps(WORKLOAD.to_json()))}
    check_workload(ref, WORKLOAD, path="ref.json")  # no error
    fewer = dataclasses.replace(WORKLOAD, configs_per_world=5)
    check_workload({"figures": FIGS, "workload": fewer.to_json()}, fewer, path="ref.json")


@pytest.mark.parametrize("workload, words", [
    # the file before workloads were pinned: recycle-v3's 204 segments, no digest
    ({"dataset": "recycle-v3", "families": ["open"], "configs_per_world": 1000, "rounds": 5, "segments": 204},
     "an unpinned workload (recycle-v3, 204 segments, 1000 configurations a world, no digest)"),
    (None, "an unpinned workload (none recorded)"),
    (dataclasses.replace(WORKLOAD, dataset="recycle-v3.1").to_json(), "another workload (recycle-v3.1 "),
    (dataclasses.replace(WORKLOAD, worlds=WORKLOAD.worlds[:5]).to_json(), "5 worlds, 202 segments"),
    (dataclasses.replace(WORKLOAD, configs_per_world=200).to_json(), "run with --configs 200, or re-measure"),
    ({**WORKLOAD.to_json(), "config_seed": 1}, "not its recorded digest '5fba7233c8e564ba' (edited?)"),
])
def test_a_reference_on_another_workload_is_refused_naming_both(workload, words):
    ref = {"figures": FIGS, **({} if workload is None else {"workload": workload})}
    with pytest.raises(SuiteError) as err:
        check_workload(ref, WORKLOAD, path="ref.json")
    msg = str(err.value)
    assert len(msg.splitlines()) == 1 and "'ref.json'" in msg and words in msg
    assert "--save ref.json" in msg  # how to re-measure
    if "edited" not in msg:
        assert f"digest {WORKLOAD.digest()}" in msg  # this run's workload, named beside the reference's


def test_an_old_reference_file_is_refused_before_any_work(tmp_path, capsys):
    old = json.loads(REFERENCE_FILE.read_text()) if "digest" not in REFERENCE_FILE.read_text() else {
        "machine": {"cpu": "AMD EPYC", "cores": 2}, "figures": FIGS,
        "workload": {"dataset": "recycle-v3", "segments": 204, "configs_per_world": 1000}}
    path = tmp_path / "old.json"
    path.write_text(json.dumps(old))
    assert main(["bench", "machine", "--against", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "unpinned workload (recycle-v3, 204 segments" in err
    assert WORKLOAD.digest() in err and f"--save {path}" in err


def test_the_readme_reference_is_shipped_and_complete():
    ref = read_reference(REFERENCE_FILE)
    assert ref["machine"]["cores"] >= 1 and ref["machine"]["cpu"]
    assert ref["quickstart_wall_s"] > 0  # the README's Quickstart figure, measured on the same machine


def test_the_readme_reference_was_measured_on_the_pinned_workload():
    check_workload(read_reference(REFERENCE_FILE), WORKLOAD, path=REFERENCE_FILE)


def test_the_quickstart_prediction_is_set_beside_a_measured_one():
    check = quickstart_check({"quickstart_wall_s": 63.5}, 2.0, 100.0)
    assert check == {"reference_s": 63.5, "predicted_s": 127.0, "measured_s": 100.0, "predicted_over_measured": 1.27}
    assert quickstart_check({"quickstart_wall_s": 63.5}, 2.0, None) is None
    assert quickstart_check({}, 2.0, 100.0) is None


def test_it_saves_its_figures_and_compares_them(tmp_path, capsys):
    saved = tmp_path / "here.json"
    assert main(["bench", "machine", "--configs", "5", "--rounds", "1", "--against", "", "--save", str(saved),
                 "--quickstart-wall-s", "60"]) == 0
    mine = json.loads(saved.read_text())
    assert set(mine["figures"]) == set(FIGURES) and all(v > 0 for v in mine["figures"].values())
    w = mine["workload"]
    assert w["configs_per_world"] == 5 and w["segments"] == 204 and len(w["worlds"]) == 6
    assert w["digest"] == dataclasses.replace(WORKLOAD, configs_per_world=5).digest()
    assert mine["quickstart_wall_s"] == 60 and mine["rounds"] == 1
    capsys.readouterr()
    assert main(["bench", "machine", "--configs", "5", "--rounds", "1", "--against", str(saved),
                 "--quickstart-wall-s", "30"]) == 0
    out = capsys.readouterr().out
    assert "reference:" in out and out.count(" ratio") == 1 and "factor " in out and w["digest"] in out
    assert "measured here (--quickstart-wall-s): 30.0 s" in out
    for k in FIGURES:
        assert k in out
    # the same file against the pinned workload's 1000 configurations: refused, one line, before any work
    assert main(["bench", "machine", "--against", str(saved)]) == 2
    assert "run with --configs 5" in capsys.readouterr().err


@pytest.mark.parametrize("content, words", [
    (None, "cannot read it"),
    ("not json", "is not JSON"),
    ('{"figures": {"fcl_state_us": 1.0, "fcl_motion_us": 0, "kernel_motion_us": 1.0, "drake_state_us": 1.0}}',
     "'fcl_motion_us' missing or not"),
])
def test_a_bad_reference_file_is_one_line_before_any_work(tmp_path, capsys, content, words):
    path = tmp_path / "ref.json"
    if content is not None:
        path.write_text(content)
    assert main(["bench", "machine", "--against", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and words in err and str(path) in err
