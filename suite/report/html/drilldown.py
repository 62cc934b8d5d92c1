"""The problem table (one row per problem, one column per planner) and one drill-down per problem.

Rows and drill-downs are written as HTML here (so the page reads without JavaScript); the browser
only filters, sorts, opens a drill-down and draws its pictures from the inline drawing data
(`problems.drawing_json`).
"""

from __future__ import annotations

import json
import math
import shlex
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from suite.report.html.markup import esc
from suite.report.html.problems import Problem
from suite.report.summary_tables import failure_reason, format_number
from suite.run.records import (
    SUCCESS,
    TrialRecord,
    is_success,
    metric,
    problem_number,
    problem_subject,
)

#: Where `python -m suite replay` writes a problem's 3-D replay, inside the run directory.
REPLAYS_DIR = "replays"

#: The drill-down's per-trial columns: (label, how to get the value from a record).
TRIAL_COLUMNS: tuple[tuple[str, Any], ...] = (
    ("planning (s)", lambda r: format_number(metric(r, "planning_time_s"))),
    ("setup (s)", lambda r: format_number(float(r.setup_time_s))
     if isinstance(r.setup_time_s, (int, float)) else "n/a"),
    ("timing (s)", lambda r: format_number(metric(r, "timing_time_s"))),
    ("length (rad)", lambda r: format_number(metric(r, "path_length_rad"))),
    ("length / ref.", lambda r: format_number(metric(r, "length_ratio"))),
    ("clearance (mm)", lambda r: format_number(1000 * metric(r, "clearance_min_m"))),
    ("duration (s)", lambda r: format_number(metric(r, "duration_s"))),
    ("SPARC", lambda r: format_number(metric(r, "sparc"))),
    ("turning (rad)", lambda r: format_number(metric(r, "turning_angle_rad"))),
)


def replay_path(run_dir: Path, pid: str) -> Path:
    """The file `python -m suite replay RUN PID` writes."""
    return Path(run_dir) / REPLAYS_DIR / f"{pid}.html"


def _verdict(r: TrialRecord) -> str:
    if not is_success(r):
        return "-"
    cert = r.certification
    return str(cert.get("verdict")) if isinstance(cert, dict) and cert.get("verdict") else "not checked"


def _status_class(status: str) -> str:
    return "ok" if status == SUCCESS else ("slow" if status in ("timeout", "killed_timeout") else "fail")


def _cell(trials: Sequence[TrialRecord]) -> tuple[str, str, float, str]:
    """A planner's cell of the problem table: (text, css class, sort value, status tokens).

    Sort value: the planning time for a success; failures after every success, by their time."""
    if not trials:
        return "not run", "none", math.inf, "none"
    ok = [r for r in trials if is_success(r)]
    times = [metric(r, "planning_time_s") for r in (ok or trials)]
    t = sorted(times)[len(times) // 2]
    if len(trials) == 1:
        status = str(trials[0].status)
        text = f"{format_number(t)} s" if ok else f"{status.replace('_', ' ')} · {format_number(t)} s"
        if ok and _verdict(trials[0]) == "collision":
            text += " ⚠"
        return text, _status_class(status), (t if ok else 1e6 + t), status
    statuses = " ".join(sorted({str(r.status) for r in trials}))
    return (f"{len(ok)}/{len(trials)} solved · {format_number(t)} s", "ok" if len(ok) == len(trials) else "mixed",
            (t if ok else 1e6 + t), statuses)


def problem_table(problems: Sequence[Problem], planners: Sequence[str]) -> str:
    """The filterable, sortable table: one row per problem, each planner's status and planning time."""
    head = ["problem", "family", "kind", "scene", "can", "difficulty", "reference (rad)", "solved by"]
    ths = "".join(f'<th data-type="{"num" if h in ("scene", "can", "difficulty", "reference (rad)", "solved by") else "text"}">'
                  f'{esc(h)}</th>' for h in head)
    ths += "".join(f'<th data-type="num" class="planner" title="planning time; failures sort after successes">'
                   f'{esc(p)}</th>' for p in planners)
    rows = []
    for p in problems:
        f = p.first
        solved = sum(any(is_success(r) for r in p.trials.get(pl, ())) for pl in planners)
        diff = f.difficulty
        ref = f.reference_length_rad
        cells = [
            f'<td data-v="{esc(p.pid)}"><a href="#{esc(p.anchor)}" title="{esc(p.pid)}">{esc(p.pid[:10])}</a></td>',
            f"<td>{esc(p.family)}</td>", f"<td>{esc(p.kind)}</td>",
            f'<td class="num" data-v="{int(f.scene_seed)}" title="scene key {esc(str(f.scene_key))}">'
            f'{int(f.scene_seed)}</td>',
            f'<td class="num" title="{esc(problem_subject(f))}">{problem_number(f)}</td>',  # a free transit: its task
            f'<td class="num" data-v="{diff if isinstance(diff, (int, float)) else -1}">'
            f'{format_number(float(diff)) if isinstance(diff, (int, float)) else "-"}</td>',
            f'<td class="num" data-v="{ref if isinstance(ref, (int, float)) else -1}">'
            f'{format_number(float(ref)) if isinstance(ref, (int, float)) else "-"}</td>',
            f'<td class="num" data-v="{solved}">{solved}/{len(planners)}</td>',
        ]
        tokens = []
        for pl in planners:
            text, cls, v, status = _cell(p.trials.get(pl, ()))
            for s in status.split():
                tokens.append(f"{pl}:{s}")
            cells.append(f'<td class="st {cls}" data-v="{v:.6g}">{esc(text)}</td>')
        rows.append(f'<tr data-pid="{esc(p.pid)}" data-anchor="{esc(p.anchor)}" data-family="{esc(p.family)}" '
                    f'data-kind="{esc(p.kind)}" data-st="{esc(" ".join(dict.fromkeys(tokens)))}">{"".join(cells)}</tr>')
    return (f'<div class="tablewrap"><table id="problem-table" class="problems"><thead><tr>{ths}</tr></thead>'
            f'<tbody>{"".join(rows)}</tbody></table></div>')


def _facts(p: Problem) -> str:
    f = p.first
    held = f.held
    parts = [f"scene seed {f.scene_seed}" + (f" (key {f.scene_key})" if f.scene_key else ""),
             problem_subject(f), "holding the can" if held else ("empty gripper" if held is False else "")]
    if f.trivial is not None:
        parts.append("trivial (its straight segment is valid)" if f.trivial else "not trivial")
    if isinstance(f.difficulty, (int, float)):
        parts.append(f"difficulty {format_number(float(f.difficulty))}")
    if f.split:
        parts.append(f"{f.split} split")
    for value, label in ((f.straight_length_rad, "straight segment"), (f.reference_length_rad, "reference path")):
        if isinstance(value, (int, float)):
            parts.append(f"{label} {format_number(float(value))} rad")
    budget = f.time_limit_s
    if isinstance(budget, (int, float)):
        parts.append(f"budget {budget:g} s")
    return " &middot; ".join(esc(x) for x in parts if x)


def _trial_rows(p: Problem, planners: Sequence[str]) -> tuple[str, str]:
    """The drill-down's per-trial table and its solver statistics."""
    head = "".join(f"<th>{esc(h)}</th>" for h in ("planner", "status", "reason", "verdict",
                                                 *(c for c, _ in TRIAL_COLUMNS)))
    rows, stats = [], []
    for pl in planners:
        trials = p.trials.get(pl, ())
        if not trials:
            rows.append(f'<tr><th><span class="swatch" data-planner="{esc(pl)}"></span>{esc(pl)}</th>'
                        f'<td colspan="{3 + len(TRIAL_COLUMNS)}">not run on this problem</td></tr>')
            continue
        for k, r in enumerate(trials):
            name = pl + (f" (trial {k + 1})" if len(trials) > 1 else "")
            status = str(r.status)
            reason = failure_reason(r) or ("" if status == SUCCESS else "none recorded")
            cells = [f'<th><span class="swatch" data-planner="{esc(pl)}"></span>{esc(name)}</th>',
                     f'<td class="st {_status_class(status)}">{esc(status)}</td>',
                     f'<td class="reason">{esc(reason)}</td>', f"<td>{esc(_verdict(r))}</td>"]
            cells += [f'<td class="num">{esc(get(r))}</td>' for _, get in TRIAL_COLUMNS]
            rows.append(f"<tr>{''.join(cells)}</tr>")
            st = {k2: v for k2, v in (r.stats or {}).items() if k2 not in ("reason",)}
            if r.certification:
                st["certification"] = r.certification
            body = ", ".join(f"<code>{esc(str(k2))}</code>&nbsp;{esc(json.dumps(v) if not isinstance(v, str) else v)}"
                             for k2, v in st.items()) or "none recorded"
            stats.append(f"<li><b>{esc(name)}</b>: {body}</li>")
    table = (f'<div class="tablewrap"><table class="trials"><thead><tr>{head}</tr></thead>'
             f'<tbody>{"".join(rows)}</tbody></table></div>')
    return table, f'<details class="stats"><summary>Solver statistics</summary><ul>{"".join(stats)}</ul></details>'


def drilldown(p: Problem, *, planners: Sequence[str], run_dir: Path, command_dir: str) -> str:
    """One problem's drill-down section (hidden until opened)."""
    trials, stats = _trial_rows(p, planners)
    replay = replay_path(run_dir, p.pid)
    command = shlex.join(["python", "-m", "suite", "replay", command_dir, p.pid])
    link = (f' It has been written: <a href="{esc(REPLAYS_DIR)}/{esc(replay.name)}">open the 3-D replay</a>.'
            if replay.exists() else "")
    return (
        f'<section class="drill" id="{esc(p.anchor)}" data-pid="{esc(p.pid)}" hidden>'
        f'<div class="drillhead"><h3>{esc(p.family)} &middot; {esc(p.kind)} &middot; '
        f'<span class="pid">{esc(p.pid)}</span></h3>'
        '<span class="drillnav"><button type="button" data-nav="-1" title="previous shown problem (k)">&larr; previous</button>'
        '<button type="button" data-nav="1" title="next shown problem (j)">next &rarr;</button>'
        '<button type="button" data-nav="0" title="close (Esc)">close &times;</button></span></div>'
        f'<p class="facts">{_facts(p)}</p>'
        f'{trials}{stats}'
        '<div class="views"></div>'
        '<h4>Joint paths over path length</h4><div class="joints"></div>'
        '<h4>3-D replay</h4>'
        f'<p>A Meshcat replay of every planner\'s timed path (about 3 MB each: written on demand rather than '
        f'inlined for every problem): <code class="cmd">{esc(command)}</code>{link}</p>'
        '</section>'
    )
