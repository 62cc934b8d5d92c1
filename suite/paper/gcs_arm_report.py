"""`python -m suite paper gcs-arm`: the GCS paper's arm protocol on the suite's planners, and its
table beside the paper's findings.

The protocol (`run_protocol`):
1. Offline, once, cached as data in the dataset's directory: `gcs`'s 8 regions from the scene's
   hand-placed seeds (`regions/`), and the PRM's roadmap (`roadmaps/`). Their build times are
   reported apart, never as planning time.
2. For each of the five tasks, on those regions: the convex relaxation's cost, the rounded cost
   and the enumerated global optimum (`suite.paper.gcs_arm.gcs_optimality`).
3. `runs` comparison runs (`compare --dataset gcs-arm:tasks`, one worker, run seeds 0, 1, ...) of
   `gcs`, `prm-roadmap`, `prm-roadmap-shortcut`, `rrt`, `trajopt` and `ik`: every path judged
   by the suite's validator and certifier, every planner with the same online budget.
4. Per task and planner: success, path length (rad) and planning time (s) as median and
   quartiles over the runs; the paper's findings, each held or not (`findings`).
"""

from __future__ import annotations

import json
import statistics
from pathlib import Path
from typing import Any

import numpy as np

from scenes.errors import SuiteError

#: The planners of the protocol: the paper's two (GCS; PRM, plain and shortcut) and the suite's.
PLANNERS = ("gcs", "prm-roadmap", "prm-roadmap-shortcut", "rrt", "trajopt", "ik")
#: The paper's IRIS settings mapped onto `gcs`'s options: 10 alternations (its iteration_limit),
#: no robot-environment padding, a 0.01 rad configuration-space margin; each seed's region grown
#: on its own, as there. The paper's IrisNp searched for collisions by nonlinear programming and
#: had no sampled test; IrisNp2's sampled test gets Drake's own defaults (1,000 particles,
#: epsilon 0.01, delta 0.05, 20 rounds of at most 10 planes), not `gcs`'s faster tuned ones
#: (200 particles, epsilon 0.05). Chosen before any run on these tasks; everything else is `gcs`'s
#: tuned setting.
PAPER_GCS = {"max_iterations": 10, "padding_m": 0.0, "configuration_space_margin_rad": 0.01,
             "num_particles": 1000, "epsilon": 0.01, "delta": 0.05, "max_iterations_separating_planes": 20,
             "max_separating_planes_per_iteration": 10}
#: The paper's findings (arXiv v1 section 7.4 and Fig. 10, via docs/gcs-paper-sources.md
#: section 8; its per-task numbers are an unverified third-party transcription).
PAPER = {
    "lengths_rad": {"AS->TS": (3.3, 9.7, 5.6), "TS->CS": (2.1, 6.7, 5.2), "CS->LB": (2.6, 3.7, 2.7),
                    "LB->RB": (3.5, 6.1, 3.8), "RB->AS": (1.8, 4.2, 1.9)},  # GCS, PRM, shortcut PRM
    "times_s": {"AS->TS": (0.11, 0.26, 0.61), "TS->CS": (0.01, 0.21, 0.60), "CS->LB": (0.05, 0.20, 0.44),
                "LB->RB": (0.14, 0.21, 0.51), "RB->AS": (0.08, 0.21, 0.54)},
    "gap_mean": 0.041, "gap_max": 0.130, "regions_s": 53.0, "roadmap_s": 16 * 60.0,
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


def aggregate(run_dirs: list[Path], labels: dict[str, str]) -> dict[str, dict[str, Any]]:
    """Per task and planner over the runs' records: runs, successes, certified, and the
    quartiles of the successes' length (rad) and of every run's planning time (s)."""
    from suite.run.records import read_trials

    cells: dict[tuple[str, str], list[dict]] = {}
    for d in run_dirs:
        for r in read_trials(d):
            cells.setdefault((labels.get(r["problem_id"], r["problem_id"]), r["planner"]), []).append(r)
    out: dict[str, dict[str, Any]] = {}
    for (task, planner), recs in sorted(cells.items()):
        ok = [r for r in recs if r["status"] == "success"]
        out.setdefault(task, {})[planner] = {
            "runs": len(recs), "successes": len(ok),
            "certified": sum((r.get("certification") or {}).get("verdict") == "certified" for r in ok),
            "length_rad": _quartiles([float(r["metrics"]["path_length_rad"]) for r in ok]),
            "time_s": _quartiles([float(r["planning_time_s"]) for r in recs if r.get("planning_time_s") is not None]),
            "offline_s": next((r["stats"].get("offline_s") for r in recs if (r.get("stats") or {}).get("offline_s")), None),
            "failures": sorted({str(r.get("reason_code")) for r in recs if r["status"] != "success"}),
        }
    return out


def _med(cell: dict | None, what: str) -> float | None:
    if not cell or not cell.get(what):
        return None
    return cell[what]["median"]


def findings(table: dict[str, dict[str, Any]], optimality: dict[str, dict], offline: dict[str, float]) -> list[dict]:
    """The paper's four findings, each with what we measured and whether it held here."""
    tasks = [t for t in PAPER["lengths_rad"] if t in table]
    solved = [t for t in tasks if (table[t].get("gcs") or {}).get("successes")]
    unsolved = f"; GCS solved {len(solved)} of {len(tasks)} tasks" if len(solved) < len(tasks) else ""
    out = []
    shorter = []
    for t in solved:
        g, p, s = (_med(table[t].get(n), "length_rad") for n in ("gcs", "prm-roadmap", "prm-roadmap-shortcut"))
        shorter.append(all(x is None or g < x for x in (p, s)))
    out.append({"finding": "in all five tasks GCS's path is shorter than both PRMs'",
                "here": f"shorter than both in {sum(shorter)} of the {len(solved)} tasks GCS solved (medians){unsolved}",
                "held": len(solved) == len(tasks) and all(shorter)})
    faster, slower = [], []
    for t in tasks:
        g, p, s = (_med(table[t].get(n), "time_s") for n in ("gcs", "prm-roadmap", "prm-roadmap-shortcut"))
        if t in solved and None not in (g, p):
            faster.append(g < p)
        if None not in (p, s):
            slower.append(s > 1.5 * p)
    out.append({"finding": "GCS's runtime is below the plain PRM's; the shortcut PRM's is significantly larger",
                "here": f"GCS faster than the plain PRM in {sum(faster)} of the {len(faster)} tasks it solved; the shortcut "
                        f"PRM over 1.5x the plain PRM's time in {sum(slower)} of {len(slower)} tasks",
                "held": len(faster) == len(tasks) and all(faster) and all(slower)})
    gaps = [o["relaxation_gap"] for o in optimality.values() if o.get("relaxation_gap") is not None]
    opt = [o.get("rounding_optimal") for o in optimality.values() if o.get("connected")]
    here = (f"rounding reached the enumerated optimum in {sum(bool(x) for x in opt)} of the {len(opt)} tasks whose ends "
            f"the regions link ({len(optimality)} tasks); gap mean {100 * statistics.mean(gaps):.1f}%, max "
            f"{100 * max(gaps):.1f}%" if gaps else "no task's ends are linked by the regions")
    out.append({"finding": "the rounded GCS solution is the global optimum in every task; the relaxation gap averages "
                           "4.1%, at most 13.0%",
                "here": here, "held": len(opt) == len(optimality) and all(bool(x) for x in opt)})
    out.append({"finding": "offline: regions in 53 s (parallel), roadmap of 15,000 samples in 16 min",
                "here": f"regions {offline.get('regions_s', float('nan')):.0f} s (one thread), roadmap of "
                        f"{offline.get('roadmap_milestones', 0)} milestones {offline.get('roadmap_s', float('nan')):.0f} s",
                "held": None})
    return out


def table_markdown(table: dict, optimality: dict, facts: list[dict], *, runs: int) -> str:
    """The per-task table (ours beside the paper's numbers) and the findings."""
    def cell(c, what, fmt):
        if not c or not c.get(what):
            return "-"
        q = c[what]
        return f"{fmt.format(q['median'])} [{fmt.format(q['q1'])}, {fmt.format(q['q3'])}]"

    lines = [f"Median [quartiles] over {runs} runs per task; solved = paths the validator passes (and how many of "
             "them the exact check certifies, where fewer); length in rad (sum of joint-space steps) over the "
             "solved runs; time = the suite's planning time in s over all runs (offline work excluded). `paper` = "
             "the paper's Fig. 10 bars (GCS / PRM / shortcut PRM).", ""]
    head = "| task | planner | solved | length (rad) | time (s) |"
    lines += [head, "|---|---|---|---|---|"]
    for task, by in table.items():
        for planner in PLANNERS:
            c = by.get(planner)
            if c is None:
                continue
            cert = "" if c["certified"] == c["successes"] else f" ({c['certified']} certified)"
            lines.append(f"| {task} | {planner} | {c['successes']}/{c['runs']}{cert} | {cell(c, 'length_rad', '{:.2f}')} | "
                         f"{cell(c, 'time_s', '{:.3f}')} |")
        if task in PAPER["lengths_rad"]:
            L, T = PAPER["lengths_rad"][task], PAPER["times_s"][task]
            lines.append(f"| {task} | paper | - | {L[0]} / {L[1]} / {L[2]} | {T[0]} / {T[1]} / {T[2]} |")
    lines += ["", "GCS on the cached regions (no online repair):", "",
              "| task | ends joined | relaxed (rad) | rounded (rad) | optimum (rad) | gap | rounding optimal | rounded path valid |",
              "|---|---|---|---|---|---|---|---|"]
    for task, o in optimality.items():
        f = (lambda k: f"{o[k]:.3f}" if o.get(k) is not None else "-")
        gap = f"{abs(100 * o['relaxation_gap']):.1f}%" if o.get("relaxation_gap") is not None else "-"
        lines.append(f"| {task} | {o['start_join']} / {o['goal_join']} | {f('relaxed_rad')} | {f('rounded_rad')} | "
                     f"{f('optimum_rad')} | {gap} | {o.get('rounding_optimal', '-')} | {o.get('rounded_path_valid', '-')} |")
    lines += ["", "| | finding | held here |", "|---|---|---|"]
    for f in facts:
        mark = {True: "held", False: "not held", None: "(measured)"}[f["held"]]
        lines.append(f"| paper | {f['finding']} | |")
        lines.append(f"| here | {f['here']} | {mark} |")
    return "\n".join(lines) + "\n"


def plot_paths(run_dir: Path, labels: dict[str, str], out: Path, *, planners=("gcs", "prm-roadmap")) -> Path:
    """The gripper's paths of each task (first run) for `planners` over the scene, top and side
    views, one colour per task (solid GCS, dashed PRM): the paper's Fig. 9 in two projections."""
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
    recs = read_trials(run_dir)
    fig, axes = plt.subplots(1, 2, figsize=(13, 6.2))
    for ax, dims in zip(axes, ((0, 1), (1, 2))):
        for o in scene_outlines(scene.spec, (), dims=dims):
            if o.kind != "plate":  # the spec's plate is buried in the table: no geometry of its own
                ax.add_patch(Polygon(o.xy_m, closed=True, **OUTLINE_STYLES[o.kind]))
    colors = plt.get_cmap("tab10")
    styles = {planners[0]: "-", planners[1]: "--"}
    for k, (a, b) in enumerate(TASKS):
        label = task_label(a, b)
        for planner in planners:
            r = next((r for r in recs if labels.get(r["problem_id"]) == label and r["planner"] == planner
                      and r["status"] == "success" and r.get("path")), None)
            if r is None:
                continue
            p = robot.gripper_pose(densify_joint_path(np.asarray(r["path"], float)))[:, :3, 3]
            for ax, (i, j) in zip(axes, ((0, 1), (1, 2))):
                ax.plot(p[:, i], p[:, j], styles[planner], color=colors(k), linewidth=1.6,
                        label=f"{label} {planner}" if ax is axes[0] else None)
    axes[0].set(xlabel="x (m)", ylabel="y (m)", title="Top view")
    axes[1].set(xlabel="y (m)", ylabel="z (m)", title="Side view (from +x)")
    for ax in axes:
        ax.set_aspect("equal")
        ax.autoscale_view()
    fig.legend(loc="lower center", ncol=5, fontsize=8, frameon=False)
    fig.suptitle("Gripper paths of GCS (solid) and the fixed-roadmap PRM (dashed) on the GCS paper's five tasks "
                 "(first run; shelves and bins hatched/green)")
    fig.subplots_adjust(bottom=0.16)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


def offline_work(dataset: str, problem, *, rebuild: bool = False) -> tuple[dict[str, Any], Any]:
    """Build (or load) the regions and the roadmap of `problem`'s world into the dataset's
    directory. Returns their figures (seconds are the builds' own, stored with the data) and the
    region set."""
    from planners.gcs import GcsPlanner
    from planners.gcs_regions import regions_for
    from planners.ompl_roadmap import PRMRoadmapConfig, roadmap_for
    from suite.problems.dataset import dataset_dir
    from suite.run.trial import make_config

    d = dataset_dir(dataset)
    gcs_cfg = make_config(GcsPlanner, PAPER_GCS)
    rs, info = regions_for(problem, gcs_cfg.region_options(), cache_dir=d / "regions", fresh=rebuild)
    rm_cfg = PRMRoadmapConfig(roadmap_dir=str(d / "roadmaps"))
    if rebuild:
        from planners.ompl_roadmap import roadmap_key

        (d / "roadmaps" / f"{roadmap_key(problem, rm_cfg)}.npz").unlink(missing_ok=True)
    rm, rm_cache = roadmap_for(problem, rm_cfg)
    return {"regions": len(rs), "region_edges": len(rs.edges) // 2, "regions_s": rs.offline_s,
            "regions_cache": info["cache"], "roadmap_milestones": len(rm.milestones),
            "roadmap_edges": len(rm.edges), "roadmap_seeded": rm.seeded, "roadmap_s": rm.offline_s,
            "roadmap_cache": rm_cache}, rs


def run_protocol(out: Path, *, dataset: str = "gcs-arm", runs: int = 10, time_limit_s: float = 5.0,
                 jobs: int = 1, rebuild: bool = False, progress: bool = True) -> dict[str, Any]:
    """The whole protocol (module docstring) into directory `out`: run-K/ per comparison run,
    paper.json, table.md and paths.png. A run already complete in `out` is kept (resumed)."""
    import sys

    import yaml

    from suite.cli import main as suite_main
    from suite.paper.gcs_arm import TASKS, gcs_optimality, task_label
    from suite.problems.dataset import load_dataset

    out.mkdir(parents=True, exist_ok=True)
    labels = task_labels(dataset)
    ds = load_dataset(f"{dataset}:tasks")
    off, rs = offline_work(dataset, ds.problems[0], rebuild=rebuild)
    optimality = {labels[pid]: gcs_optimality(p, rs) for pid, p in zip(ds.ids, ds.problems)}
    # gcs and the PRMs find the regions and the roadmap in the dataset's directory themselves (no
    # path in the settings: a trial's id must not depend on where the checkout lies)
    config = {"planner_configs": {"gcs": dict(PAPER_GCS)}}
    (out / "config.yaml").write_text(yaml.safe_dump(config))
    run_dirs = []
    for k in range(runs):
        rd = out / f"run-{k}"
        argv = ["compare", "--dataset", f"{dataset}:tasks", "--planners", ",".join(PLANNERS), "--seed", str(k),
                "--jobs", str(jobs), "--time-limit-s", str(time_limit_s), "--config", str(out / "config.yaml"),
                "--out", str(rd)]
        if (rd / "trials.jsonl").exists():
            argv.append("--resume")
        if progress:
            print(f"run {k + 1}/{runs}: python -m suite {' '.join(argv)}", file=sys.stderr, flush=True)
        code = suite_main(argv + ([] if progress else ["--no-progress"]))
        if code not in (0, None):
            raise SuiteError(f"comparison run {k} failed (exit code {code}); its directory: {rd}")
        run_dirs.append(rd)
    table = aggregate(run_dirs, labels)
    table = {task_label(a, b): table[task_label(a, b)] for a, b in TASKS if task_label(a, b) in table}
    facts = findings(table, optimality, off)
    ours = verdicts_with_our_robot(run_dirs, labels)
    report = {"dataset": dataset, "runs": runs, "time_limit_s": time_limit_s, "offline": off,
              "gcs_optimality": optimality, "table": table, "findings": facts, "paper": PAPER,
              "gcs_settings": PAPER_GCS, "verdicts_with_our_robot": ours}
    (out / "paper.json").write_text(json.dumps(report, indent=1, default=float) + "\n")
    text = table_markdown(table, optimality, facts, runs=runs)
    text += ("\nThe same successes judged with the project's own robot model (capsules, the WSG's fingers "
             "open) in the same scene:\n\n| planner | successes | valid with our model |\n|---|---|---|\n"
             + "".join(f"| {p} | {c['successes']} | {c['valid_with_ours']} |\n" for p, c in sorted(ours.items())))
    (out / "table.md").write_text(text)
    plot_paths(run_dirs[0], labels, out / "paths.png")
    return report


def verdicts_with_our_robot(run_dirs: list[Path], labels: dict[str, str]) -> dict[str, dict[str, int]]:
    """Every success of the runs judged again with the project's own robot model (`iiwa14-wsg`:
    capsules, the WSG's fingers open) in the same scene: per planner, successes and how many of
    them that validator still passes. The paper's model is the scene's own; this says how much
    the verdicts depend on it."""
    import dataclasses

    from planners.worlds import collision_world
    from scenes.robot_model import DEFAULT_ROBOT
    from suite.paper.gcs_arm import paper_scene
    from suite.problems.dataset import load_dataset
    from suite.run.records import read_trials
    from suite.scoring.validate import validate_path

    scene = paper_scene()
    ours = dataclasses.replace(scene, spec=dataclasses.replace(scene.spec, robot=DEFAULT_ROBOT))
    ds = load_dataset("gcs-arm:tasks")
    problems = {pid: p.with_(scene=ours) for pid, p in zip(ds.ids, ds.problems)}
    out: dict[str, dict[str, int]] = {}
    for d in run_dirs:
        for r in read_trials(d):
            if r["status"] != "success" or not r.get("path") or r["problem_id"] not in problems:
                continue
            p = problems[r["problem_id"]]
            cell = out.setdefault(r["planner"], {"successes": 0, "valid_with_ours": 0})
            cell["successes"] += 1
            cell["valid_with_ours"] += validate_path(p, np.asarray(r["path"], float), collision_world(p)) is None
    return out
