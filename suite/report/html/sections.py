"""The report's summary sections: provenance, the headline and per-family tables, failures, figures,
more statistics and execution in physics.

The tables are the summary's own (`summary_tables` row builders, `summary_execution`), rendered as
HTML; the figures are the PNGs `make_plots` drew into the run's plots/ directory, inlined as they are.
"""

from __future__ import annotations

import datetime as dt
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from suite.execution.execution_records import ExecutionRecord
from suite.execution.moving_bin_records import MovingBinRecord
from suite.report.html.markup import esc, inline_md, png_img, table
from suite.report.plots_common import PLOTS_DIR
from suite.report.summary_stats import (
    N_RESAMPLES,
    GroupSummary,
    PairedComparison,
    RunSummary,
)
from suite.report.summary_tables import (
    ATTRIBUTION_INTRO,
    CERTIFICATION_INTRO,
    COLD_INTRO,
    REASON_CODE_INTRO,
    attribution_rows,
    certification_rows,
    cold_rows,
    common_rows,
    composition,
    failure_reason_rows,
    failure_rows,
    group_rows,
    paired_rows,
    reason_code_rows,
)
from suite.run.records import TrialRecord, statuses_in

#: Where each standard figure goes, with its caption; PNGs not named here go under "Other figures".
FIGURES: dict[str, tuple[str, str]] = {
    "planning_time_cdf.png": ("overview", "Share of problems solved within a planning time (failures never arrive)."),
    "metrics_boxplots.png": ("overview", "Each metric over each planner's solved problems."),
    "success_by_family.png": ("families", "Success rate per scene family, with 95% Wilson intervals."),
    "length_ratio_by_family.png": ("families", "Path length over the reference path's, per family (solved problems)."),
    "outcomes.png": ("failures", "Every trial's status, per planner."),
    "natural_poses.png": ("figures", "Natural poses (the seed paper's question) over each planner's solved problems."),
    "time_attribution.png": ("figures", "Where planning time goes: the share spent in collision queries."),
    "budget_curves.png": ("figures", "Success and length against the planning budget."),
    "execution.png": ("execution", "Where the cans ended after execution in physics."),
    "moving_bin.png": ("moving_bin", "Cans in the bin against bin speed per planner (95% Wilson intervals), and why "
                                     "cans were lost: replan latency against the deadline, deadline misses and failed "
                                     "replans, cans lost, contacts with the bin or the person, and the paired difference between planners "
                                     "(mean over the episodes both ran, 95% scene-bootstrap interval)."),
}


def figures(run_dir: Path, where: str) -> str:
    """The run's figures that belong to section `where` (`FIGURES`; "figures" also takes the unlisted ones)."""
    plots = run_dir / PLOTS_DIR
    if not plots.is_dir():
        return ""
    out = []
    for path in sorted(plots.glob("*.png")):
        section, caption = FIGURES.get(path.name, ("figures", ""))
        if section != where:
            continue
        if path.name.startswith("gripper_paths_"):
            caption = "Every planner's gripper paths over one scene of the family (the drill-downs show each problem)."
        elif path.name.startswith("joint_profiles_"):
            caption = "Timed joint positions and velocities (TOPP-RA) of one motion."
        out.append(f'<figure>{png_img(path, alt=path.stem)}<figcaption><b>{esc(path.name)}</b>: '
                   f'{esc(caption)}</figcaption></figure>')
    return f'<div class="figures">{"".join(out)}</div>' if out else ""


def _duration_s(start: str | None, end: str | None) -> float | None:
    try:
        return (dt.datetime.fromisoformat(end) - dt.datetime.fromisoformat(start)).total_seconds()
    except (TypeError, ValueError):
        return None


def _budgets(records: Sequence[TrialRecord]) -> str:
    values = sorted({float(r.time_limit_s) for r in records if isinstance(r.time_limit_s, (int, float))})
    from suite.report.summary_contention import budget_clocks

    clocks = budget_clocks(records)
    of = " of CPU time" if clocks == ["cpu"] else (" (wall and CPU clocks)" if len(clocks) > 1 else "")
    return (", ".join(f"{v:g} s" for v in values) + of) if values else "not recorded"


def headline_facts(run_dir: Path, manifest: dict[str, Any], records: Sequence[TrialRecord],
                   planners: Sequence[str]) -> str:
    """The line under the title: trials, planners, problems, dataset and budget."""
    ds = manifest.get("dataset") or {}
    selection = (manifest.get("config") or {}).get("dataset")
    source = (f"dataset <b>{esc(str(selection or ds.get('name')))}</b>" if (selection or ds.get("name"))
              else "generated scenes")
    return (f'<p class="facts">{len(records)} trials &middot; {len(planners)} planners '
            f'({esc(", ".join(planners))}) &middot; {source} &middot; budget {esc(_budgets(records))} per problem'
            f'</p><p class="facts">{esc(composition(records))}</p>' + _provenance_line(manifest)
            + _contention_warning(records))


def _contention_warning(records: Sequence[TrialRecord]) -> str:
    """summary.md's warning when trials were contended (`suite.report.summary_contention`), or nothing."""
    from suite.report.summary_contention import contention_warning

    warning = contention_warning(records)
    return f'<div class="note contended" style="border-left:4px solid #c60;padding-left:8px">{inline_md(warning)}</div>' \
        if warning else ""


def _provenance_line(manifest: dict[str, Any]) -> str:
    """Hash, commit, machine, versions and date in one line (the full table is under Run settings)."""
    ds, machine, versions = manifest.get("dataset") or {}, manifest.get("machine") or {}, manifest.get("versions") or {}
    parts = [f"dataset hash {ds['hash']}" if ds.get("hash") else "",
             f"git {str(manifest['git_commit'])[:10]}" if manifest.get("git_commit") else "",
             f"{machine.get('cpu', '?')}, {machine.get('cores', '?')} cores" if machine else "",
             ", ".join(f"{k} {versions[k]}" for k in ("drake", "ompl", "python-fcl", "toppra") if k in versions),
             f"started {manifest['started_utc']}" if manifest.get("started_utc") else ""]
    shown = " &middot; ".join(esc(p) for p in parts if p)
    return f'<p class="facts">{shown} &middot; <a href="#settings">all settings</a></p>' if shown else ""


def settings_html(manifest: dict[str, Any], records: Sequence[TrialRecord], planners: Sequence[str]) -> str:
    """The run's settings and provenance: dataset, budget, planners and their configs, machine, versions."""
    if not manifest:
        rows = [["manifest", "none in the run directory: only what the trial records hold is shown"]]
    else:
        cfg = manifest.get("config") or {}
        ds = manifest.get("dataset") or {}
        wall = _duration_s(manifest.get("started_utc"), manifest.get("finished_utc"))
        rows = [
            ["command", manifest.get("command", "not recorded")],
            ["dataset", f"{ds.get('name')} tier {ds.get('tier')}, hash {ds.get('hash')} (selection {cfg.get('dataset')})"
             if ds else "generated scenes: variant {variant}, seed {seed}, {scenes} scenes, {cans} cans, {grasps} "
                        "grasps".format(**{k: cfg.get(k) for k in ("variant", "seed", "scenes", "cans", "grasps")})],
            ["budget per problem", _budgets(records)],
            ["status", f"{manifest.get('status', 'not recorded')}: {manifest.get('trials_recorded', '?')} of "
                       f"{manifest.get('trials_total', '?')} trials recorded"],
            ["started / finished (UTC)", f"{manifest.get('started_utc', '?')} / {manifest.get('finished_utc', '?')}"
             + (f" ({wall:.0f} s of trials)" if wall is not None else "")],
            ["workers", f"{cfg.get('jobs', '?')} ({cfg.get('executor', '?')} executor)"],
            ["machine", ", ".join(f"{k} {v}" for k, v in (manifest.get("machine") or {}).items()) or "not recorded"],
            ["versions", ", ".join(f"{k} {v}" for k, v in (manifest.get("versions") or {}).items()) or "not recorded"],
            ["git commit", manifest.get("git_commit", "not recorded")],
        ]
    out = [table(["setting", "value"], [[k, str(v)] for k, v in rows], cls="settings")]
    out.append("<h3>Planner settings (as recorded with their trials)</h3>")
    for p in planners:
        configs = {json.dumps(r.planner_config, sort_keys=True) for r in records if r.planner == p}
        cfg = json.loads(next(iter(configs))) if len(configs) == 1 else None
        if isinstance(cfg, dict):
            body = ", ".join(f"<code>{esc(str(k))}</code>&nbsp;{esc(json.dumps(v))}" for k, v in cfg.items())
        else:
            body = (f"{len(configs)} different settings across its trials (several budgets or configs)"
                    if len(configs) > 1 else "not recorded")
        out.append(f'<details class="config"><summary><b>{esc(p)}</b></summary><p>{body}</p></details>')
    return "".join(out)


INTRO = (
    "The unit is the distinct problem: a problem tried several times counts once. Success: solved / distinct "
    "problems, rate and its 95% Wilson interval. Time to solve: median [quartiles] over every problem, a failure "
    "counted at its time budget. Other metrics: median [first quartile, third quartile] over each planner's own "
    "solved problems; the common-subset table measures all planners on the same problems.")


def overview_html(run_dir: Path, records: Sequence[TrialRecord], summary: RunSummary,
                  planners: Sequence[str]) -> str:
    """The headline: the per-planner table with intervals, the common subset, certification, two figures."""
    out = [inline_md(INTRO), table(*group_rows(summary.overall, key=None), cls="headline", stacked=True)]
    if len(planners) > 1:
        out += ["<h3>On the problems every planner solved</h3>",
                table(*common_rows(summary.common, planners))]
    out += ["<h3>Certified paths (successful trials)</h3>", inline_md(CERTIFICATION_INTRO),
            table(*certification_rows(records, planners)), figures(run_dir, "overview")]
    return "".join(out)


def success_matrix(groups: Sequence[GroupSummary], overall: Sequence[GroupSummary], *, key: str,
                   planners: Sequence[str], title: str) -> str:
    """Success per group (rows) and planner (columns): solved/n, rate and Wilson interval, shaded by rate."""
    cells = {(getattr(g, key), g.planner): g for g in groups}
    names = list(dict.fromkeys(getattr(g, key) for g in groups))
    head = "".join(f"<th class=num>{esc(p)}</th>" for p in planners)
    rows = []
    for name, source in [(n, cells) for n in names] + [("all", {("all", g.planner): g for g in overall})]:
        tds = []
        for p in planners:
            g = source.get((name, p))
            if g is None or not g.n:
                tds.append("<td class=num>-</td>")
                continue
            lo, hi = g.success_ci95
            shade = f"hsl({round(120 * g.success_rate)}, 55%, {round(93 - 6 * g.success_rate)}%)"
            k = f"{g.successes:g}" if float(g.successes).is_integer() else f"{g.successes:.1f}"
            tds.append(f'<td class="num rate" style="background:{shade}">{k}/{g.n} ({100 * g.success_rate:.0f}%)'
                       f'<span class="cell-q">[{100 * lo:.0f}, {100 * hi:.0f}]</span></td>')
        rows.append(f'<tr{" class=total" if name == "all" else ""}><th>{esc(str(name))}</th>{"".join(tds)}</tr>')
    return (f'<div class="tablewrap"><table class="matrix"><thead><tr><th>{esc(title)}</th>{head}</tr></thead>'
            f'<tbody>{"".join(rows)}</tbody></table></div>')


def families_html(run_dir: Path, records: Sequence[TrialRecord], summary: RunSummary,
                  planners: Sequence[str]) -> str:
    """Per scene family and per problem kind: success at a glance, every metric one click away."""
    out = [inline_md("Problems solved / distinct problems (rate), 95% Wilson interval below.")]
    if len({r.variant for r in records}) > 1:
        out += [success_matrix(summary.by_family, summary.overall, key="variant", planners=planners, title="family"),
                '<details><summary>Every metric per planner and family</summary>',
                table(*group_rows(summary.by_family, key="variant"), cls="grouped", stacked=True), "</details>"]
    out += [figures(run_dir, "families"), "<h3>Per problem kind</h3>",
            success_matrix(summary.by_kind, summary.overall, key="problem", planners=planners, title="kind"),
            '<details><summary>Every metric per planner and kind</summary>',
            table(*group_rows(summary.by_kind, key="problem"), cls="grouped", stacked=True), "</details>"]
    return "".join(out)


def failures_html(run_dir: Path, records: Sequence[TrialRecord], summary: RunSummary,
                  planners: Sequence[str]) -> str:
    """Failed trials by status, and by the reason the planner gave."""
    headers, rows = failure_reason_rows(records, planners)
    c_headers, c_rows = reason_code_rows(records, planners)
    return "".join([
        "<h3>By status (trials)</h3>", table(*failure_rows(summary.overall, statuses_in(records))),
        "<h3>By cause, per planner and family (trials)</h3>", inline_md(REASON_CODE_INTRO),
        table(c_headers, [[*r[:3], *(c or "" for c in r[3:])] for r in c_rows]) if c_rows else "<p>No trial failed.</p>",
        "<h3>By stated reason (trials)</h3>",
        inline_md("What each failed trial's planner said (numbers in the text shown as #, so one cause is one "
                  "row). Filter the problem table below by planner and status to see the problems."),
        table(headers, [[*r[:2], *(c or "" for c in r[2:])] for r in rows]) if rows else "<p>No trial failed.</p>",
        figures(run_dir, "failures"),
    ])


def more_stats_html(records: Sequence[TrialRecord], pairs: Sequence[PairedComparison],
                    planners: Sequence[str]) -> str:
    """Paired comparisons, where planning time goes, the OMPL planners' search and simplification apart and
    cold starts, when the records hold them."""
    out = []
    if pairs:
        out += ["<h3>Paired comparisons</h3>", inline_md(
            "Differences A - B on the distinct problems both planners solved: median, percentile-bootstrap 95% CI "
            f"resampling whole scenes ({N_RESAMPLES} resamples), two-sided Wilcoxon signed-rank p-value. Negative "
            "means A is lower."), table(*paired_rows(pairs))]
    if any(r.attribution for r in records):
        out += ["<h3>Where planning time goes</h3>", inline_md(ATTRIBUTION_INTRO),
                table(*attribution_rows(records, planners))]
    from suite.report.summary_search import SEARCH_INTRO, search_rows

    search = search_rows(records, planners)
    if search[1]:
        out += ["<h3>Search and simplification (OMPL planners)</h3>", inline_md(SEARCH_INTRO), table(*search)]
    if any(r.warm is not None for r in records):
        out += ["<h3>Cold starts</h3>", inline_md(COLD_INTRO), table(*cold_rows(records, planners))]
    return "".join(out)


def execution_html(run_dir: Path, executions: Sequence[ExecutionRecord], planners: Sequence[str]) -> str:
    """execution.json's table, figure and the Meshcat replays compare wrote beside it."""
    from suite.report.summary_execution import EXECUTION_INTRO, execution_rows

    text = EXECUTION_INTRO.split("\n", 2)[2]  # without its markdown heading
    replays = sorted(run_dir.glob("replay_*.html"))
    links = "".join(f'<li><a href="{esc(p.name)}">{esc(p.name)}</a> ({p.stat().st_size / 1e6:.1f} MB)</li>'
                    for p in replays if not p.stem.startswith("replay_p-"))
    return "".join([
        inline_md(" ".join(text.split("\n"))),
        table(*execution_rows(executions, planners=planners)),
        figures(run_dir, "execution"),
        f"<p>Physics replays written by the run (Meshcat, open beside this file):</p><ul>{links}</ul>" if links else "",
    ])


def moving_bin_html(run_dir: Path, records: Sequence[MovingBinRecord], planners: Sequence[str]) -> str:
    """moving_bin.json's tables (per planner and speed; planners paired over shared episodes; latency
    per step), its figure and the episodes' Meshcat replays."""
    from suite.report.summary_moving_bin import MOVING_BIN_INTRO, moving_bin_tables

    text = MOVING_BIN_INTRO.split("\n", 2)[2]  # without its markdown heading
    replays = sorted(run_dir.glob("replay_moving_bin_*.html"))
    links = "".join(f'<li><a href="{esc(p.name)}">{esc(p.name)}</a> ({p.stat().st_size / 1e6:.1f} MB)</li>'
                    for p in replays)
    tables = "".join((inline_md(caption) if caption else "") + table(headers, rows)
                     for caption, headers, rows in moving_bin_tables(records, planners=planners))
    return "".join([
        inline_md(text),
        tables,
        figures(run_dir, "moving_bin"),
        f"<p>One episode per planner (Meshcat, open beside this file; the bin and the person move):</p><ul>{links}</ul>"
        if links else "",
    ])
