"""Runs at several budgets: no statistic mixes budgets; curves and the per-family table."""

from __future__ import annotations

import json

from suite.report.budgets import budget_table, budgets_in, by_budget_view
from suite.report.write import write_report
from tests.suite.report.test_summary import record


def _budget_run():
    recs = []
    for budget, solved in ((0.1, 2), (1.0, 4)):
        for i in range(4):
            r = record("rrtstar", seed=i, length_rad=1.0 + i / budget / 10,
                       status="success" if i < solved else "timeout", time_s=min(budget, 0.05))
            r.time_limit_s = budget
            r.trial_id += f"-{budget}"
            if r.status == "success":
                r.metrics["length_ratio"] = r.metrics["path_length_rad"]
            recs.append(r)
    return recs


def test_budgets_are_kept_apart():
    recs = _budget_run()
    assert budgets_in(recs) == [0.1, 1.0]
    assert {r.planner for r in by_budget_view(recs)} == {"rrtstar@0.1s", "rrtstar@1s"}
    assert by_budget_view(recs[:4]) == recs[:4]  # one budget: names unchanged
    table = budget_table(recs, planners=["rrtstar"])
    rows = [[c.strip() for c in line.split("|")[1:-1]] for line in table.splitlines()[2:]]
    assert rows == [["rrtstar", "0.1", "2/4 [15-85%], 1.5", "2/4 [15-85%], 1.5"],
                    ["rrtstar", "1", "4/4 [51-100%], 1.15", "4/4 [51-100%], 1.15"]]


def test_report_of_a_budget_run(tmp_path):
    (tmp_path / "trials.jsonl").write_text("".join(json.dumps(r.to_json()) + "\n" for r in _budget_run()))
    write_report(tmp_path)
    md = (tmp_path / "summary.md").read_text()
    assert "## By budget" in md and "rrtstar@0.1s" in md and "rrtstar@1s" in md
    data = json.loads((tmp_path / "summary.json").read_text())
    assert data["planners"]["rrtstar@0.1s"]["success"]["k"] == 2
    assert data["planners"]["rrtstar@1s"]["success"]["k"] == 4
    assert data["distinct_problems"] == 4  # the same four problems at both budgets
    assert (tmp_path / "plots" / "budget_curves.png").stat().st_size > 20_000
