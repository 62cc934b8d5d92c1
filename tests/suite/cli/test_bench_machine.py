"""`bench machine`: the fixed workload that scales the README's timings to a reader's machine.

These assert what it prints and writes, never how fast anything is."""

from __future__ import annotations

import json

import pytest

from suite.bench.machine import FIGURES, REFERENCE_FILE, factor, read_reference
from suite.cli import main


def test_the_factor_is_the_geometric_mean_of_the_ratios():
    ref = dict.fromkeys(FIGURES, 10.0)
    assert factor(dict.fromkeys(FIGURES, 20.0), ref) == pytest.approx(2.0)
    assert factor({"fcl_state_us": 40.0, "fcl_motion_us": 10.0, "kernel_motion_us": 10.0, "drake_state_us": 2.5},
                  ref) == pytest.approx(1.0)


def test_the_readme_reference_is_shipped_and_complete():
    ref = read_reference(REFERENCE_FILE)
    assert ref["machine"]["cores"] >= 1 and ref["machine"]["cpu"]
    assert ref["quickstart_wall_s"] > 0  # the README's Quickstart figure, measured on the same machine


def test_it_saves_its_figures_and_compares_them(tmp_path, capsys):
    saved = tmp_path / "here.json"
    assert main(["bench", "machine", "--configs", "5", "--rounds", "1", "--against", "", "--save", str(saved)]) == 0
    mine = json.loads(saved.read_text())
    assert set(mine["figures"]) == set(FIGURES) and all(v > 0 for v in mine["figures"].values())
    assert mine["workload"]["families"] and mine["workload"]["segments"] > 0
    capsys.readouterr()
    assert main(["bench", "machine", "--configs", "5", "--rounds", "1", "--against", str(saved)]) == 0
    out = capsys.readouterr().out
    assert "reference:" in out and out.count(" ratio") == 1 and "factor " in out
    for k in FIGURES:
        assert k in out


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
