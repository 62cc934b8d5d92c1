"""The report of `python -m suite paper gcs-arm`: its comparison runs' records per task and planner
beside the paper's numbers, and the paper's findings judged with each region set.

- `aggregate`: per task and planner over the runs, success, certified paths, and the median and
  quartiles of path length (rad), planning time and GCS's solver time (s).
- `findings`: the paper's four findings, each judged with our regions and with the paper's.
- `table_markdown` (table.md) and `plot_paths` (paths.png, the paper's Fig. 9 in two projections).

How the runs are made is `suite.paper.gcs_arm_protocol`.
"""

from __future__ import annotations

import json
import statistics
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from suite.run.records import TrialRecord

#: The planners of the protocol: the paper's two (GCS; PRM, plain and shortcut) and the suite's.
PLANNERS = ("gcs", "prm-roadmap", "prm-roadmap-shortcut", "rrt", "trajopt", "ik")
#: The region sets GCS can plan on: ours (grown at the paper's IRIS settings, `gcs_arm_protocol.PAPER_GCS`) and
#: the paper's stored ones.
REGION_SETS = ("ours", "paper")
#: The table's name of `gcs` planning on the paper's regions (the planner is `gcs` in its records).
GCS_PAPER = "gcs-paper-regions"
#: `gcs`'s name in the table for each region set.
GCS_NAMES = {"ours": "gcs", "paper": GCS_PAPER}
#: The paper's findings (arXiv v1 section 7.4 and Fig. 10, via docs/gcs-paper-sources.md
#: section 8; its per-task numbers are an unverified third-party transcription).
PAPER = {
    "lengths_rad": {"AS->TS": (3.3, 9.7, 5.6), "TS->CS": (2.1, 6.7, 5.2), "CS->LB": (2.6, 3.7, 2.7),
                    "LB->RB": (3.5, 6.1, 3.8), "RB->AS": (1.8, 4.2, 1.9)},  # GCS, PRM, shortcut PRM
    "times_s": {"AS->TS": (0.11, 0.26, 0.61), "TS->CS": (0.01, 0.21, 0.60), "CS->LB": (0.05, 0.20, 0.44),
                "LB->RB": (0.14, 0.21, 0.51), "RB->AS": (0.08, 0.21, 0.54)},
    "gap_mean": 0.041, "gap_max": 0.130, "regions_s": 53.0, "roadmap_s": 16 * 60.0,
    "generation": "arXiv v1 (2022): Fig. 10 and section 7.4, via an unverified transcription (gcs-paper-sources.md "
                  "section 8); GCS time = preprocessing + relaxation + every rounding (MOSEK); PRM time = a non-lazy "
                  "query (Python over common-robotics-utilities), the shortcut PRM's with TRI's shortcutting",
}


def _quartiles(values: list[float]) -> dict[str, float] | None:
    """The run summary's median and quartiles (`MetricStats`) as a dict; None for no values."""
    from suite.report.summary_stats import MetricStats

    if not values:
        return None
    s = MetricStats.of(np.asarray(values, float))
    return {"median": s.median, "q1": s.q1, "q3": s.q3}


def task_labels(dataset: str) -> dict[str, str]:
    """problem_id -> task label ("AS->TS", ...) of a gcs-arm dataset."""
    from suite.problems.dataset import PROBLEMS_FILE, dataset_dir

    out = {}
    for line in (dataset_dir(dataset) / PROBLEMS_FILE).read_text().splitlines():
        if line.strip():
            rec = json.loads(line)
            out[rec["problem_id"]] = rec.get("task", rec["problem_id"])
    return out


def aggregate(run_dirs: list[Path], labels: dict[str, str], *, rename: dict[str, str] | None = None
              ) -> dict[str, dict[str, Any]]:
    """Per task and planner over the runs' records: runs, successes, certified, and the
    quartiles of the successes' length (rad), of every run's planning time (s) and, for `gcs`, of
    its GCS solver time (s: `stats.gcs_solve_s`, every GCS solve of the query: Drake's
    preprocessing, the relaxation and the rounded solves, repairs' solves included; and
    `first_solve_s`, the first solve alone, before any repair). `rename` maps
    a record's planner to the table's name (`gcs` on the paper's regions)."""
    from suite.run.records import read_trials

    cells: dict[tuple[str, str], list[TrialRecord]] = {}
    for d in run_dirs:
        for r in read_trials(d):
            name = (rename or {}).get(r.planner, r.planner)
            cells.setdefault((labels.get(r.problem_id, r.problem_id), name), []).append(r)
    out: dict[str, dict[str, Any]] = {}
    for (task, planner), recs in sorted(cells.items()):
        ok = [r for r in recs if r.succeeded]
        solver = [float(r.stats["gcs_solve_s"]) for r in recs if (r.stats or {}).get("gcs_solve_s") is not None]
        first = [float(r.stats["first_solve_s"]) for r in recs if (r.stats or {}).get("first_solve_s") is not None]
        out.setdefault(task, {})[planner] = {
            "runs": len(recs), "successes": len(ok),
            "certified": sum((r.certification or {}).get("verdict") == "certified" for r in ok),
            "length_rad": _quartiles([float(r.metrics["path_length_rad"]) for r in ok]),
            "time_s": _quartiles([float(r.planning_time_s) for r in recs if r.planning_time_s is not None]),
            "solver_s": _quartiles(solver),
            "first_solve_s": _quartiles(first),
            "repairs": sum(int((r.stats or {}).get("repairs", 0)) for r in recs),
            "num_regions": sorted({r.stats["num_regions"] for r in recs if (r.stats or {}).get("num_regions")}),
            "offline_s": next((r.stats.get("offline_s") for r in recs if (r.stats or {}).get("offline_s")), None),
            "failures": sorted({str(r.reason_code) for r in recs if not r.succeeded}),
        }
    return out


def merge_tables(*tables: dict[str, dict[str, Any]]) -> dict[str, dict[str, Any]]:
    out: dict[str, dict[str, Any]] = {}
    for t in tables:
        for task, by in t.items():
            out.setdefault(task, {}).update(by)
    return out


def _med(cell: dict | None, what: str) -> float | None:
    if not cell or not cell.get(what):
        return None
    return cell[what]["median"]


def _pct(x: float) -> str:
    return f"{100 * x:.1f}%"


def findings(table: dict[str, dict[str, Any]], optimality: dict[str, dict[str, dict]], offline: dict[str, Any]
             ) -> list[dict]:
    """The paper's four findings, each judged with each region set of `optimality` (`ours`,
    `paper`): per set what we measured and whether it held here (True, False; None: measured
    only, or not comparable)."""
    tasks = [t for t in PAPER["lengths_rad"] if t in table]
    sets = [k for k in REGION_SETS if k in optimality]
    f1, f2, f3 = [], [], []
    for rs in sets:
        gname = GCS_NAMES[rs]
        solved = [t for t in tasks if (table[t].get(gname) or {}).get("successes")]
        unsolved = f"; GCS solved {len(solved)} of {len(tasks)} tasks" if len(solved) < len(tasks) else ""
        shorter = []
        for t in solved:
            g, p, s = (_med(table[t].get(n), "length_rad") for n in (gname, "prm-roadmap", "prm-roadmap-shortcut"))
            shorter.append(all(x is None or g < x for x in (p, s)))
        f1.append({"regions": rs, "held": len(solved) == len(tasks) and all(shorter),
                   "here": f"shorter than both in {sum(shorter)} of the {len(solved)} tasks GCS solved (medians: "
                           + ", ".join(f"{_med(table[t].get(gname), 'length_rad'):.2f}" for t in solved)
                           + f" rad){unsolved}"})
        faster, slower, solver_s = [], [], []
        for t in tasks:
            g = _med(table[t].get(gname), "first_solve_s")  # one solve, as the paper's (no repairs there)
            p, s = (_med(table[t].get(n), "time_s") for n in ("prm-roadmap", "prm-roadmap-shortcut"))
            if t in solved and None not in (g, p):
                faster.append(g < p)
                solver_s.append(g)
            if None not in (p, s):
                slower.append(s > 1.5 * p)
        span = f" (GCS solver {min(solver_s):.3f}-{max(solver_s):.3f} s)" if solver_s else ""
        f2.append({"regions": rs, "held": len(faster) == len(tasks) and all(faster) and all(slower),
                   "here": f"GCS's solver time (its first solve: relaxation and every rounding) below the plain PRM's query time in {sum(faster)} of the {len(faster)} "
                           f"tasks it solved{span}; the shortcut PRM over 1.5x the plain PRM's time in {sum(slower)} "
                           f"of {len(slower)} tasks"})
        opt = optimality[rs]
        linked = [o for o in opt.values() if o.get("connected")]
        parts = []
        for key, label in (("linear", "the paper's formulation (LinearGCS, edge costs)"),
                           ("", "Drake's GcsTrajectoryOptimization (vertex costs)")):
            pre = f"{key}_" if key else ""
            gaps = [o[f"{pre}gap" if key else "relaxation_gap"] for o in linked
                    if o.get(f"{pre}gap" if key else "relaxation_gap") is not None]
            reached = sum(bool(o.get(f"{pre}rounding_optimal")) for o in linked)
            invalid = [t for t, o in opt.items() if o.get(f"{pre}path_valid" if key else "rounded_path_valid") is False]
            parts.append(f"{label}: rounding reached the enumerated optimum in {reached} of {len(linked)} tasks; gap "
                         + (f"mean {_pct(statistics.mean(gaps))}, max {_pct(max(gaps))}" if gaps else "-")
                         + (f"; its rounded (= optimum) path collides in our world in {', '.join(invalid)}" if invalid else ""))
        unl = f"; the regions link the ends of {len(linked)} of {len(opt)} tasks" if len(linked) < len(opt) else ""
        # Held: every task linked, rounding optimal in each, and no optimum colliding in our world
        # (a colliding "optimum" is not a path). The gap's size is reported, not judged: the
        # paper's 4.1% / 13.0% are arXiv v1's on regions it did not publish.
        collides = any(o.get("linear_path_valid") is False or o.get("rounded_path_valid") is False for o in linked)
        f3.append({"regions": rs, "here": "; ".join(parts) + unl,
                   "held": len(linked) == len(opt) and not collides
                   and all(bool(o.get("linear_rounding_optimal")) for o in linked)})
    out = [
        {"finding": "in all five tasks GCS's path is shorter than both PRMs'", "by_regions": f1},
        {"finding": "GCS's runtime is below the plain PRM's; the shortcut PRM's is significantly larger (arXiv v1: "
                    "GCS = MOSEK's preprocessing + relaxation + all roundings; PRM = a non-lazy query)", "by_regions": f2},
        {"finding": "the rounded GCS solution is the global optimum in every task; the relaxation gap averages 4.1%, "
                    "at most 13.0% (the paper's formulation, LinearGCS)", "by_regions": f3},
    ]
    ours_s = offline.get("regions_s")
    out.append({"finding": "offline: regions in 53 s (parallel), roadmap of 15,000 samples in 16 min", "by_regions": [
        {"regions": "ours", "held": None,
         "here": (f"our 8 regions {ours_s:.0f} s (one thread) at the paper's IRIS settings; " if ours_s else "")
                 + f"roadmap of {offline.get('roadmap_milestones', 0)} milestones {offline.get('roadmap_s', float('nan')):.0f} s"},
        {"regions": "paper", "held": None, "here": "the paper's regions are loaded (their build time is not published)"}]})
    return out


def _max_diff(opt: dict) -> float:
    """The largest difference between the two formulations' relaxed costs over the tasks (rad)."""
    d = [abs(o["relaxed_rad"] - o["linear_relaxed_rad"]) for o in opt.values()
         if o.get("relaxed_rad") is not None and o.get("linear_relaxed_rad") is not None]
    return max(d) if d else float("nan")


def _two(c: dict) -> str:
    """GCS's first solve / all solves (medians, s), or "-"."""
    if not c.get("first_solve_s"):
        return "-"
    return f"{c['first_solve_s']['median']:.3f} / {c['solver_s']['median']:.3f}"


def _flt(o: dict, k: str, fmt: str = "{:.3f}") -> str:
    return fmt.format(o[k]) if o.get(k) is not None else "-"


def table_markdown(table: dict, optimality: dict[str, dict], facts: list[dict], *, runs: int,
                   regions: dict[str, Any] | None = None) -> str:
    """The per-task table (ours beside the paper's numbers), GCS on each region set, the regions
    and the findings."""
    def cell(c, what, fmt):
        if not c or not c.get(what):
            return "-"
        q = c[what]
        return f"{fmt.format(q['median'])} [{fmt.format(q['q1'])}, {fmt.format(q['q3'])}]"

    lines = [f"Median [quartiles] over {runs} runs per task; solved = paths the validator passes (and how many of "
             "them the exact check certifies, where fewer); length in rad (sum of joint-space steps) over the "
             "solved runs; time = the suite's planning time in s over all runs (offline work excluded); GCS solver "
             "= `gcs`'s GCS solves alone (s): the first solve (relaxation and every rounding), then all of them (with the "
             f"online repairs' re-solves). `{GCS_PAPER}` = `gcs` on the paper's own 9 regions (final generation). "
             "`paper` = arXiv v1's Fig. 10 (GCS / PRM / shortcut PRM; GCS time: MOSEK's preprocessing, relaxation "
             "and all roundings; PRM: a non-lazy query). The shortcut PRM here is OMPL's full PathSimplifier "
             "(shortcuts and B-spline smoothing), stronger than the paper's shortcutting.", ""]
    names = ("gcs", GCS_PAPER) + PLANNERS[1:]
    lines += ["| task | planner | solved | length (rad) | time (s) | GCS solver: first / all (s) |", "|---|---|---|---|---|---|"]
    for task, by in table.items():
        for planner in names:
            c = by.get(planner)
            if c is None:
                continue
            cert = "" if c["certified"] == c["successes"] else f" ({c['certified']} certified)"
            lines.append(f"| {task} | {planner} | {c['successes']}/{c['runs']}{cert} | {cell(c, 'length_rad', '{:.2f}')} | "
                         f"{cell(c, 'time_s', '{:.3f}')} | {_two(c)} |")
        if task in PAPER["lengths_rad"]:
            L, T = PAPER["lengths_rad"][task], PAPER["times_s"][task]
            lines.append(f"| {task} | paper | - | {L[0]} / {L[1]} / {L[2]} | {T[0]} / {T[1]} / {T[2]} | {T[0]} |")
    for rs, opt in optimality.items():
        lines += ["", f"GCS on {'our regions' if rs == 'ours' else 'the paper regions'} (no online repair), in Drake's "
                  "formulation (`gcs`: GcsTrajectoryOptimization, vertex costs) and in the paper's (LinearGCS, edge "
                  "costs); optimum = the enumerated global optimum of the same graph problem (both formulations share it); "
                  f"the two relaxations differ by at most {_max_diff(opt):.1e} rad here:", "",
                  "| task | ends joined | optimum (rad) | relaxed / rounded (rad), ours | gap | rounded = optimum | rounded path valid | "
                  "relaxed / rounded (rad), LinearGCS | gap | rounded = optimum | rounded path valid |",
                  "|---|---|---|---|---|---|---|---|---|---|---|"]
        for task, o in opt.items():
            gap = _pct(abs(o["relaxation_gap"])) if o.get("relaxation_gap") is not None else "-"
            lgap = _pct(abs(o["linear_gap"])) if o.get("linear_gap") is not None else "-"
            lines.append(f"| {task} | {o['start_join']} / {o['goal_join']} | {_flt(o, 'optimum_rad')} | "
                         f"{_flt(o, 'relaxed_rad')} / {_flt(o, 'rounded_rad')} | {gap} | {o.get('rounding_optimal', '-')} | "
                         f"{o.get('rounded_path_valid', '-')} | {_flt(o, 'linear_relaxed_rad')} / {_flt(o, 'linear_rounded_rad')} | "
                         f"{lgap} | {o.get('linear_rounding_optimal', '-')} | {o.get('linear_path_valid', '-')} |")
    if regions:
        lines += ["", "The regions: uniform samples of each (hit-and-run) judged by the python-fcl world; for ours, "
                  "what IRIS did (from Drake's log):", "",
                  "| set | region | faces | samples in collision | IRIS iterations | stopped by | inscribed radius (rad) | build (s) |",
                  "|---|---|---|---|---|---|---|---|"]
        for rs, rows in regions.items():
            for name, r in rows.items():
                lines.append(f"| {rs} | {name} | {r['faces']} | {r['collide']}/{r['samples']} ({_pct(r['fraction'])}) | "
                             f"{r.get('iterations', '-')} | {', '.join(r.get('stop', [])) or '-'} | "
                             f"{_flt(r, 'radius_rad', '{:.2f}')} | {_flt(r, 'build_s', '{:.1f}')} |")
    lines += ["", "| | regions | finding | held here |", "|---|---|---|---|"]
    for f in facts:
        lines.append(f"| paper | | {f['finding']} | |")
        for h in f["by_regions"]:
            mark = {True: "held", False: "not held", None: "(measured)"}[h["held"]]
            lines.append(f"| here | {h['regions']} | {h['here']} | {mark} |")
    return "\n".join(lines) + "\n"


def plot_paths(runs: list[tuple[Path, dict[str, str]]], labels: dict[str, str], out: Path, *,
               planners=("gcs", GCS_PAPER, "prm-roadmap")) -> Path:
    """The gripper's paths of each task (first run) for `planners` over the scene, top and side
    views, one colour per task (solid `gcs` on our regions, dotted on the paper's, dashed PRM): the
    paper's Fig. 9 in two projections. `runs`: (run directory, planner renames) pairs."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from scenes.robot_model import load_robot
    from suite.paper.gcs_arm import TASKS, paper_scene, task_label
    from matplotlib.patches import Polygon

    from suite.report.plots_paths import OUTLINE_STYLES, densify_joint_path
    from suite.report.scene_outlines import scene_outlines
    from suite.run.records import read_trials

    scene = paper_scene()
    robot = load_robot(scene.spec.robot)
    recs = [r.with_(planner=rename.get(r.planner, r.planner)) for d, rename in runs for r in read_trials(d)]
    fig, axes = plt.subplots(1, 2, figsize=(13, 6.6))
    for ax, dims in zip(axes, ((0, 1), (1, 2))):
        for o in scene_outlines(scene.spec, (), dims=dims):  # the world has no plate (no can station)
            ax.add_patch(Polygon(o.xy_m, closed=True, **OUTLINE_STYLES[o.kind]))
    colors = plt.get_cmap("tab10")
    styles = dict(zip(planners, ("-", ":", "--")))
    for k, (a, b) in enumerate(TASKS):
        label = task_label(a, b)
        for planner in planners:
            r = next((r for r in recs if labels.get(r.problem_id) == label and r.planner == planner
                      and r.succeeded and r.path), None)
            if r is None:
                continue
            p = robot.gripper_pose(densify_joint_path(np.asarray(r.path, float)))[:, :3, 3]
            for ax, (i, j) in zip(axes, ((0, 1), (1, 2))):
                ax.plot(p[:, i], p[:, j], styles[planner], color=colors(k), linewidth=1.8 if styles[planner] == ":" else 1.4,
                        label=f"{label} {planner}" if ax is axes[0] else None)
    axes[0].set(xlabel="x (m)", ylabel="y (m)", title="Top view")
    axes[1].set(xlabel="y (m)", ylabel="z (m)", title="Side view (from +x)")
    for ax in axes:
        ax.set_aspect("equal")
        ax.autoscale_view()
    fig.legend(loc="lower center", ncol=5, fontsize=8, frameon=False)
    fig.suptitle("Gripper paths on the GCS paper's five tasks (first run): GCS on our regions (solid), on the paper's "
                 "regions (dotted),\nthe fixed-roadmap PRM (dashed); shelves and bins hatched/green")
    fig.subplots_adjust(bottom=0.2)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out
