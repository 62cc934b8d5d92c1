"""The pyroboplan adapter (adapters/pyroboplan/plan.py) reads only an export, plans with a library
nobody here wrote, and its results file imports as records judged like the suite's own.

It runs with any Python that has pyroboplan: this one (`pip install -e ".[pyroboplan]"`) or the
one named by $PYROBOPLAN_PYTHON (pyroboplan pins matplotlib and toppra, so it is best kept in an
environment of its own); without either the test is skipped."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ADAPTER = Path(__file__).resolve().parents[2] / "adapters" / "pyroboplan" / "plan.py"
DATASET = "recycle-v1:quick"


def pyroboplan_python() -> str | None:
    if importlib.util.find_spec("pyroboplan") is not None:
        return sys.executable
    return os.environ.get("PYROBOPLAN_PYTHON") or None


@pytest.mark.skipif(pyroboplan_python() is None,
                    reason="pyroboplan not installed: pip install -e '.[pyroboplan]', or set PYROBOPLAN_PYTHON "
                           "to a Python that has it")
def test_the_adapter_plans_from_the_export_alone_and_its_results_import(tmp_path):
    from suite.exchange.export import write_export
    from suite.exchange.results import import_results
    from suite.problems.dataset import load_dataset
    from suite.run.records import read_trials

    ds = load_dataset(DATASET)
    trivial = next(pid for pid in ds.ids if ds.meta[pid]["trivial"])
    hard = next(pid for pid in ds.ids if not ds.meta[pid]["trivial"] and ds.meta[pid]["kind"] == "approach")
    export = tmp_path / "export"
    write_export(DATASET, export, time_limit_s=5.0)
    results = tmp_path / "pyroboplan.jsonl"
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}  # nothing of the suite on its path
    subprocess.run([pyroboplan_python(), str(ADAPTER), str(export), "--out", str(results),
                    "--problems", f"{trivial},{hard}"], check=True, cwd=tmp_path, env=env, timeout=600,
                   capture_output=True)
    lines = [json.loads(line) for line in results.read_text().splitlines()]
    assert {ln["problem_id"] for ln in lines} == {trivial, hard}
    run, counts = import_results(dataset=DATASET, results=results, planner="pyroboplan", out=tmp_path / "run")
    by_id = {r.problem_id: r for r in read_trials(run)}
    assert by_id[trivial].status == "success" and by_id[trivial].external is True
    assert by_id[hard].status in ("success", "invalid_solution", "timeout")
    assert counts.statuses["no_result"] == len(ds.ids) - 2
