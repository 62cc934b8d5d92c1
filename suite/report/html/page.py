"""Assembling report.html: the sections, the problem table, the drill-downs, inline CSS, JS and data."""

from __future__ import annotations

import datetime as dt
import json
import logging
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from suite.execution.execution_records import ExecutionRecord
from suite.report.html import drilldown, sections
from suite.report.html.markup import esc, inline_md
from suite.report.html.problems import drawing_json, group_problems, load_world
from suite.report.plots_common import planner_colors
from suite.report.summary_stats import PairedComparison, RunSummary
from suite.run.records import TrialRecord, statuses_in

log = logging.getLogger(__name__)

REPORT_FILE = "report.html"
ASSETS = Path(__file__).with_name("assets")


def _section(anchor: str, title: str, body: str) -> str:
    return f'<section class="block" id="{anchor}"><h2>{esc(title)}</h2>{body}</section>' if body else ""


def _filters(problems, planners: Sequence[str], statuses: Sequence[str]) -> str:
    def select(name: str, label: str, options: Sequence[tuple[str, str]]) -> str:
        opts = "".join(f'<option value="{esc(v)}">{esc(t)}</option>' for v, t in options)
        return f'<label>{esc(label)} <select id="f-{name}">{opts}</select></label>'

    families = sorted({p.family for p in problems})
    kinds = list(dict.fromkeys(p.kind for p in problems))
    return ('<div class="filters">'
            + select("family", "family", [("", "all")] + [(f, f) for f in families])
            + select("kind", "kind", [("", "all")] + [(k, k) for k in kinds])
            + select("planner", "planner", [("*any", "any planner"), ("*every", "every planner")]
                     + [(p, p) for p in planners])
            + select("status", "status", [("", "any"), ("*failed", "failed (not success)")]
                     + [(s, s) for s in statuses])
            + '<label>problem id <input id="f-text" type="search" placeholder="prefix" size="12"></label>'
            + '<button type="button" id="f-reset">reset</button>'
            + '<span id="f-count" class="count"></span></div>')


def render(
    run_dir: Path,
    *,
    records: Sequence[TrialRecord],
    manifest: dict[str, Any],
    planners: Sequence[str],
    summary: RunSummary,
    pairs: Sequence[PairedComparison],
    executions: Sequence[ExecutionRecord],
    command_dir: str,
) -> str:
    """The whole page as one string."""
    t0 = time.perf_counter()
    problems = group_problems(records)
    world = load_world(problems, manifest)
    data = drawing_json(problems, planners=planners, world=world)
    data.update(planners=list(planners), colors=planner_colors(planners))
    log.debug("report data: %d problems in %.2f s", len(problems), time.perf_counter() - t0)
    plots_note = "" if (run_dir / "plots").is_dir() else inline_md(
        "This run has no plots/ (it ran with `--no-plots`): `python -m suite plot RUN` draws them, then "
        "`python -m suite report RUN` puts them here.")
    drills = "".join(drilldown.drilldown(p, planners=planners, run_dir=run_dir, command_dir=command_dir)
                     for p in problems)
    problems_body = (
        inline_md("One row per distinct problem, one column per planner: its planning time, or its status and time "
                  "when it failed (⚠: a success whose exact verdict found a collision between the validator's "
                  "samples). Filter, click a column to sort, click a row to open its drill-down: the scene from "
                  "above and from the side with every planner's gripper path, each planner's status, reason, "
                  "timings and metrics, and the joint paths. "
                  "Keys: j / k next / previous shown problem, Esc closes.")
        + f'<p class="note">{esc(world.note)}</p>'
        + _filters(problems, planners, statuses_in(records))
        + drilldown.problem_table(problems, planners)
        + f'<div id="drills">{drills}</div>')
    nav = [("overview", "Overview"), ("families", "Families & kinds"), ("failures", "Failures"),
           ("problems", f"Problems ({len(problems)})")]
    body = [
        _section("overview", "Overview", sections.overview_html(run_dir, records, summary, planners) + plots_note),
        _section("families", "Per scene family", sections.families_html(run_dir, records, summary, planners)),
        _section("failures", "Failures", sections.failures_html(run_dir, records, summary, planners)),
        _section("problems", "Problems", problems_body),
    ]
    if executions:
        nav.append(("execution", "Execution"))
        body.append(_section("execution", "Execution in physics",
                             sections.execution_html(run_dir, executions, planners)))
    from suite.execution.execution_records import read_moving_bin

    moving = read_moving_bin(run_dir)
    if moving:
        nav.append(("moving_bin", "Moving bin"))
        body.append(_section("moving_bin", "Moving bin", sections.moving_bin_html(run_dir, moving, planners)))
    figures = sections.figures(run_dir, "figures")
    if figures:
        nav.append(("figures", "More figures"))
        body.append(_section("figures", "More figures", figures))
    more = sections.more_stats_html(records, pairs, planners)
    if more:
        nav.append(("more", "More statistics"))
        body.append(_section("more", "More statistics", more))
    nav.append(("settings", "Run settings"))
    body.append(_section("settings", "Run settings and provenance", sections.settings_html(manifest, records, planners)))
    css = (ASSETS / "report.css").read_text(encoding="utf-8")
    js = (ASSETS / "report.js").read_text(encoding="utf-8")
    # "</" inside inline JSON would end the script element early
    payload = json.dumps(data, separators=(",", ":")).replace("</", "<\\/")
    stamp = dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    links = "".join(f'<a href="#{a}">{esc(t)}</a>' for a, t in nav)
    return (
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
        "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
        f"<title>Run report: {esc(run_dir.name)}</title><style>{css}</style></head><body>"
        f'<header class="top"><h1>Run report: {esc(run_dir.resolve().name)}</h1>'
        f"{sections.headline_facts(run_dir, manifest, records, planners)}</header>"
        f'<nav>{links}</nav><main>{"".join(body)}</main>'
        f'<footer>Written {stamp} by <code>python -m suite report</code> from the run directory\'s files alone '
        "(trials.jsonl, manifest.json, plots/, execution.json, moving_bin.json); self-contained: no network, no server.</footer>"
        f'<script type="application/json" id="report-data">{payload}</script>'
        f"<script>{js}</script></body></html>\n"
    )
