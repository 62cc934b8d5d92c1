"""`python -m suite paper gcs-arm`: the GCS paper's arm protocol on the suite's planners, and its
table beside the paper's findings (`suite.paper.gcs_arm_report`).

The protocol (`run_protocol`):
1. Offline, once, cached as data in the dataset's directory: `gcs`'s 8 regions from the scene's
   hand-placed seeds at the paper's IRIS settings (`PAPER_GCS`; `regions/`), and the PRM's roadmap
   (`roadmaps/`). Their build times are reported apart, never as planning time. The paper's own 9
   regions (final generation, converted once to plain arrays: `suite.paper.paper_regions`) are the
   second region set: written as a region set of this world into OUT/paper-regions/.
2. For each of the five tasks and each region set: the convex relaxation's cost, the rounded cost
   and the enumerated global optimum, in `gcs`'s formulation (Drake's GcsTrajectoryOptimization)
   and in the paper's (LinearGCS) (`suite.paper.gcs_arm.gcs_optimality`); each region set's
   regions sampled uniformly and judged by the python-fcl world.
3. `runs` comparison runs of the dataset's tasks (`comparison_run`: the runner's
   `suite.run.comparison.run_comparison`, as `compare --dataset gcs-arm:tasks` runs them; one
   worker, run seeds 0, 1, ...) of `gcs`, `prm-roadmap`, `prm-roadmap-shortcut`, `rrt`, `trajopt`
   and `ik` (run-K/), and of `gcs` on the paper's regions (run-K-paper/, named `gcs-paper-regions`
   in the table): every path judged by the suite's validator and certifier, every planner with the
   same online budget.
4. Per task and planner: success, path length (rad), planning time and GCS's solver time (s) as
   median and quartiles over the runs; the paper's findings, each judged with both region sets
   (`suite.paper.gcs_arm_report`).

Which generation each number is compared with: the paper's regions are the final (Science
Robotics) generation's (the arXiv v1 regions were never published); its per-task table (`PAPER`)
is arXiv v1's Fig. 10, whose PRM query is not lazy and whose GCS time counts preprocessing, the
relaxation and every rounding.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from scenes.errors import SuiteError
from suite.paper.gcs_arm_report import (
    GCS_PAPER,
    PAPER,
    PLANNERS,
    REGION_SETS,
    aggregate,
    findings,
    merge_tables,
    plot_paths,
    table_markdown,
    task_labels,
)

#: The paper's IRIS settings mapped onto `gcs`'s options, field by field: the final notebook's
#: `IrisOptions` (reproduction/prm_comparison/prm_comparison.ipynb at 3d781488; docs/gcs-paper-sources.md
#: section 7d) -> IrisNp2's field that stands for it:
#:   iteration_limit = 10                    -> max_iterations = 10
#:   termination_threshold = -1              -> termination_threshold = -1 (the absolute test off)
#:   relative_termination_threshold = 0.02   -> relative_termination_threshold = 0.02 (arXiv v1: 0.01)
#:   require_sample_point_is_contained = True -> require_sample_point_is_contained = True
#:   random_seed = SEED (0)                  -> random_seed = 0
#:   configuration_space_margin (unset: 1e-2) -> configuration_space_margin_rad = 0.01
#:   num_collision_infeasible_samples = 1    -> no counterpart: IrisNp's per-iteration nonlinear search
#:       for collisions from a few random starts is IrisNp2's sampled statistical test, here at Drake's
#:       own defaults (1,000 particles, epsilon 0.01, delta 0.05, 20 rounds of at most 10 planes).
#: No robot-environment padding (the notebook's plant has none); each seed's region grown on its own,
#: as there (no configuration obstacles). Chosen before any run on these tasks; everything else is
#: `gcs`'s tuned setting.
PAPER_IRIS = {"max_iterations": 10, "termination_threshold": -1.0, "relative_termination_threshold": 0.02,
              "require_sample_point_is_contained": True, "random_seed": 0, "configuration_space_margin_rad": 0.01}
PAPER_GCS = {**PAPER_IRIS, "padding_m": 0.0, "num_particles": 1000, "epsilon": 0.01, "delta": 0.05,
             "max_iterations_separating_planes": 20, "max_separating_planes_per_iteration": 10,
             "max_rounded_paths": 10}  # the paper's rounding: 10 paths (randomForwardPathSearch max_paths)


def offline_work(dataset: str, problem, *, rebuild: bool = False) -> tuple[dict[str, Any], Any]:
    """Build (or load) the regions and the roadmap of `problem`'s world into the dataset's
    directory. Returns their figures (seconds are the builds' own, stored with the data) and the
    region set."""
    from planners.gcs.planner import GcsPlanner
    from planners.gcs.regions import regions_for
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
            "regions_cache": info["cache"], "regions_file": Path(info["path"]).name, "region_build_s": rs.region_build_s,
            "roadmap_milestones": len(rm.milestones),
            "roadmap_edges": len(rm.edges), "roadmap_seeded": rm.seeded, "roadmap_s": rm.offline_s,
            "roadmap_cache": rm_cache}, rs


def our_region_rows(problem, rs) -> dict[str, dict]:
    """Per region of our set, named by its scene seed: faces, IRIS iterations and stop reason,
    inscribed radius, build time, and its collision fraction (`collision_fractions`)."""
    from planners.gcs.cover import scene_seeds
    from suite.paper.paper_regions import collision_fractions

    named, _ = scene_seeds(problem)
    names = []
    for q in rs.seeds:
        names.append(next((n for n, s in named if np.allclose(s, q, atol=1e-9)), f"r{len(names)}"))
    frac = collision_fractions(problem, names, list(rs.A), list(rs.b))
    out = {}
    for k, name in enumerate(names):
        iris = rs.region_iris[k] if k < len(rs.region_iris) else {}
        out[name] = {**frac[name], **{key: iris.get(key) for key in ("iterations", "stop", "volume", "radius_rad")},
                     "build_s": rs.region_build_s[k] if k < len(rs.region_build_s) else None}
    return out


def paper_region_rows(problem) -> dict[str, dict]:
    """Per paper region: faces, collision fraction, inscribed radius."""
    from planners.gcs.iris import inscribed_volume
    from suite.paper.paper_regions import collision_fractions, load_paper_regions

    names, A, b = load_paper_regions()
    frac = collision_fractions(problem, names, A, b)
    return {n: {**frac[n], **inscribed_volume(a, c)} for n, a, c in zip(names, A, b)}


def parse_region_sets(text: str) -> tuple[str, ...]:
    """"ours", "paper" or "both" -> the region sets GCS plans on."""
    if text == "both":
        return REGION_SETS
    if text not in REGION_SETS:
        raise SuiteError(f"--regions {text!r}; allowed: ours, paper, both")
    return (text,)


def comparison_run(run_dir: Path, *, settings: Path, planners: list[str], dataset: str, seed: int, jobs: int,
                   time_limit_s: float, progress: bool = True) -> None:
    """One comparison run of the protocol into `run_dir`, with the records, manifest and report that
    `compare` writes: `planners` on the problems of `dataset` (NAME:TIER) at run seed `seed`, the
    planners' settings from the YAML file `settings` (its `planner_configs`), `jobs` worker
    processes, `time_limit_s` of planning per problem. A run already in `run_dir` is resumed (its
    recorded trials are kept; its settings must be these)."""
    import sys

    import yaml

    from scenes.schema import load
    from suite.report.write import write_report
    from suite.run.comparison import run_comparison
    from suite.run.runner import TRIALS_FILE, CompareConfig

    values = {**(yaml.safe_load(settings.read_text()) or {}), "planners": tuple(planners), "dataset": dataset,
              "seed": seed, "jobs": jobs, "time_limit_s": float(time_limit_s)}
    config = load(CompareConfig, values, where=f"{settings}: ")
    run_comparison(config, out=run_dir, command=sys.argv[1:], resume=(run_dir / TRIALS_FILE).exists(),
                   progress_bar=progress, then=lambda done: write_report(done.out))


def run_protocol(out: Path, *, dataset: str = "gcs-arm", runs: int = 10, time_limit_s: float = 5.0,
                 jobs: int = 1, rebuild: bool = False, progress: bool = True,
                 regions: tuple[str, ...] = REGION_SETS) -> dict[str, Any]:
    """The whole protocol (module docstring) into directory `out`: run-K/ (and run-K-paper/) per
    comparison run, paper.json, table.md and paths.png, GCS planning on each region set of
    `regions` ("ours", "paper"). A run already complete in `out` is kept (resumed)."""
    import sys

    import yaml

    from planners.gcs.planner import GcsPlanner
    from suite.paper.gcs_arm import TASKS, gcs_optimality, task_label
    from suite.paper.paper_regions import paper_region_set
    from suite.problems.dataset import load_dataset
    from suite.run.trial import make_config

    for r in regions:
        if r not in REGION_SETS:
            raise SuiteError(f"region set {r!r}; allowed: {', '.join(REGION_SETS)}")
    out.mkdir(parents=True, exist_ok=True)
    labels = task_labels(dataset)
    ds = load_dataset(f"{dataset}:tasks")
    problem = ds.problems[0]
    off, ours = offline_work(dataset, problem, rebuild=rebuild)
    sets = {}
    if "ours" in regions:
        sets["ours"] = ours
    paper_dir = out / "paper-regions"
    if "paper" in regions:
        # the paper's regions as the region set of this world at `gcs`'s settings: `gcs` finds it in
        # `regions_dir` before our set of the same name in the dataset's regions/
        sets["paper"] = paper_region_set(problem, make_config(GcsPlanner, PAPER_GCS).region_options())
        for stale in paper_dir.glob("*.npz"):
            stale.unlink()
        sets["paper"].save(paper_dir / f"{sets['paper'].world_hash}.npz")
    optimality = {k: {labels[pid]: gcs_optimality(p, rs) for pid, p in zip(ds.ids, ds.problems)} for k, rs in sets.items()}
    region_rows = {}
    if "ours" in sets:
        region_rows["ours"] = our_region_rows(problem, ours)
    if "paper" in sets:
        region_rows["paper"] = paper_region_rows(problem)
    # gcs and the PRMs find the regions and the roadmap in the dataset's directory themselves (no
    # path in the settings: a trial's id must not depend on where the checkout lies); the paper's
    # regions are in OUT/paper-regions (its path, as given, is in those trials' settings)
    config = {"planner_configs": {"gcs": dict(PAPER_GCS)}}
    (out / "config.yaml").write_text(yaml.safe_dump(config))
    paper_config = {"planner_configs": {"gcs": {**PAPER_GCS, "regions_dir": str(paper_dir), "build_regions": False}}}
    (out / "config-paper-regions.yaml").write_text(yaml.safe_dump(paper_config))
    main_planners = [p for p in PLANNERS if p != "gcs" or "ours" in regions]
    run_dirs, paper_dirs = [], []
    for k in range(runs):
        for rd, planners, cfg in ((out / f"run-{k}", main_planners, out / "config.yaml"),
                                  (out / f"run-{k}-paper", ["gcs"] if "paper" in regions else [],
                                   out / "config-paper-regions.yaml")):
            if not planners:
                continue
            if progress:
                print(f"run {k + 1}/{runs}: {', '.join(planners)} on {dataset}:tasks, seed {k}, settings {cfg.name} "
                      f"-> {rd}", file=sys.stderr, flush=True)
            comparison_run(rd, settings=cfg, planners=planners, dataset=f"{dataset}:tasks", seed=k, jobs=jobs,
                           time_limit_s=time_limit_s, progress=progress)
            (paper_dirs if rd.name.endswith("-paper") else run_dirs).append(rd)
    table = merge_tables(aggregate(run_dirs, labels), aggregate(paper_dirs, labels, rename={"gcs": GCS_PAPER}))
    for task, by in table.items():  # gcs must have planned on the paper's 9 regions, not found ours
        if GCS_PAPER in by and by[GCS_PAPER]["num_regions"] not in ([], [len(sets["paper"])]):
            raise SuiteError(f"{task}: gcs on the paper's regions planned on {by[GCS_PAPER]['num_regions']} regions, "
                             f"not the paper's {len(sets['paper'])}")
    table = {task_label(a, b): table[task_label(a, b)] for a, b in TASKS if task_label(a, b) in table}
    facts = findings(table, optimality, off)
    runs_all = [(d, {}) for d in run_dirs] + [(d, {"gcs": GCS_PAPER}) for d in paper_dirs]
    ours_model = verdicts_with_our_robot(runs_all, labels, dataset=dataset)
    report = {"dataset": dataset, "runs": runs, "time_limit_s": time_limit_s, "region_sets": list(regions),
              "offline": off, "gcs_optimality": optimality, "regions": region_rows, "table": table,
              "findings": facts, "paper": PAPER, "gcs_settings": PAPER_GCS, "paper_iris": PAPER_IRIS,
              "verdicts_with_our_robot": ours_model}
    (out / "paper.json").write_text(json.dumps(report, indent=1, default=float) + "\n")
    text = table_markdown(table, optimality, facts, runs=runs, regions=region_rows)
    text += ("\nThe same successes judged with the project's own robot model (capsules, the WSG's fingers "
             "open) in the same scene:\n\n| planner | successes | valid with our model |\n|---|---|---|\n"
             + "".join(f"| {p} | {c['successes']} | {c['valid_with_ours']} |\n" for p, c in sorted(ours_model.items())))
    (out / "table.md").write_text(text)
    plot_paths(runs_all[:1] + [x for x in runs_all if x[0].name == "run-0-paper"], labels, out / "paths.png")
    return report


def verdicts_with_our_robot(runs: list[tuple[Path, dict[str, str]]], labels: dict[str, str], *,
                            dataset: str = "gcs-arm") -> dict[str, dict[str, int]]:
    """Every success of the runs ((run directory, planner renames) pairs) judged again with the
    project's own robot model (`iiwa14-wsg`: capsules, the WSG's fingers open) in the same scene:
    per planner, successes and how many of them that validator still passes. The paper's model is
    the scene's own; this says how much the verdicts depend on it. The problems are `dataset`'s."""
    import dataclasses

    from planners.worlds import collision_world
    from scenes.robot_model import DEFAULT_ROBOT
    from suite.problems.dataset import load_dataset
    from suite.run.records import read_trials
    from suite.scoring.validate import validate_path

    ds = load_dataset(f"{dataset}:tasks")
    problems = {pid: p.with_(scene=dataclasses.replace(p.scene, spec=dataclasses.replace(p.scene.spec, robot=DEFAULT_ROBOT)))
                for pid, p in zip(ds.ids, ds.problems)}
    out: dict[str, dict[str, int]] = {}
    for d, rename in runs:
        for r in read_trials(d):
            if not r.succeeded or not r.path or r.problem_id not in problems:
                continue
            p = problems[r.problem_id]
            cell = out.setdefault(rename.get(r.planner, r.planner), {"successes": 0, "valid_with_ours": 0})
            cell["successes"] += 1
            cell["valid_with_ours"] += validate_path(p, np.asarray(r.path, float), collision_world(p)) is None
    return out
