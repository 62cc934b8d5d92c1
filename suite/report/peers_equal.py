"""Peers at equal check density: `rrt` against `roboplan-rrt` over seeds, with an uncertainty.

Reads the runs of each *setting* (a directory whose sub-directories are `compare` runs of the same
problems and planner settings, one per run seed: `results/peers-equal/step-0.01-range-1/seed-0`,
...) and gives, per setting:

- each planner's time to a validated path per problem: the median over seeds of `planning_time_s`
  for a success, a failure (any other status) counted at the trial's budget;
- the ratio of the two planners' times per problem, the median ratio over problems and its
  percentile-bootstrap 95% interval, resampling problems (seeded; also resampling scenes, whose
  transit and return share a world, in the JSON);
- each side's check setting as it ran (step, norm, re-check, post-processing), successes, certified
  share of the successes (the exact verdict, `certification`), median length ratio, samples checked
  per tree edge (`rrt` counts them; `roboplan-rrt`'s are computed from its edges' lengths) and its
  search and post-processing times.

`python -m suite.report.peers_equal SETTING_DIR... [--json FILE]` prints the markdown tables and
writes the JSON that docs/peers.md's generated block is rendered from (`docs_block`).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import statistics
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from scenes.errors import SuiteError
from suite.report.outcomes import cluster_bootstrap_median_ci
from suite.run.records import (
    TRIALS_FILE,
    TrialRecord,
    is_success,
    problem_key,
    read_manifest,
    read_trials,
)

#: `rrt` at most this times `roboplan-rrt`'s time (issue 50)
TARGET_RATIO = 0.8
RESAMPLES = 10_000
PLANNERS = ("rrt", "roboplan-rrt")
#: where `suite docs` reads the analysis that docs/peers.md's table is written from
ANALYSIS_JSON = Path("results") / "peers-equal" / "analysis.json"
COMMAND = "sh docs/peers-equal.sh"


@dataclasses.dataclass(frozen=True)
class RatioSummary:
    """The median over problems of per-problem ratios a / b, with percentile-bootstrap intervals.

    Attributes:
        median: the median ratio; problems: how many problems it is over.
        ci_low, ci_high: its 95% interval resampling problems.
        ci_scene_low, ci_scene_high: the same resampling scenes (clusters of problems).
    """

    median: float
    problems: int
    ci_low: float
    ci_high: float
    ci_scene_low: float
    ci_scene_high: float


@dataclasses.dataclass(frozen=True)
class Side:
    """One planner's figures at one setting (times in s; medians over what each names).

    Attributes:
        planner: its name; check: how it checks an edge ("0.01 rad, l2"); recheck: its re-check
            of the returned path ("none" or the re-check's step); post_processing: its shortening.
        trials, successes: trials run and those the suite's validator accepted.
        solved_every_seed: problems solved with every seed.
        certified: successes the exact verdict certifies.
        time_s: median over problems of the per-problem median over seeds of the time to a
            validated path (a failure at the budget).
        search_s, post_s: medians over successes of the search's and the post-processing's time.
        length_ratio: median over successes of the path length over the best known.
        samples_per_edge: median over trials of the samples checked per tree edge;
            samples_per_edge_from: "counted" (by the planner's motion validator) or "computed"
            (from the kept edges' lengths and the step).
        cold_trials: trials that were their worker's first of the planner.
    """

    planner: str
    check: str
    recheck: str
    post_processing: str
    trials: int
    successes: int
    solved_every_seed: int
    certified: int
    time_s: float
    search_s: float
    post_s: float
    length_ratio: float
    samples_per_edge: float
    samples_per_edge_from: str
    cold_trials: int


@dataclasses.dataclass(frozen=True)
class SettingResult:
    """One setting's figures: both sides and the ratio of their times (`a` over `b`).

    Attributes:
        name: the setting directory's name; runs: its run directories.
        dataset, time_limit_s, seeds, problems: what was run.
        commits: the runs' git commits (`+dirty` where a tree had uncommitted changes).
        a, b: the two sides; ratio: a's time over b's; verdict: against `TARGET_RATIO`.
    """

    name: str
    runs: tuple[str, ...]
    dataset: str
    time_limit_s: float
    seeds: tuple[int, ...]
    problems: int
    range_rad: float | None
    commits: tuple[str, ...]
    a: Side
    b: Side
    ratio: RatioSummary
    verdict: str


# --- statistics -------------------------------------------------------------------------------------


def time_to_valid_s(rec: TrialRecord) -> float:
    """A trial's time to a validated path (s): its planning time if the suite's validator
    accepted its path, else its budget (a failure counted at the budget)."""
    return float(rec.planning_time_s) if is_success(rec) else float(rec.time_limit_s)


def per_problem_medians(records: Sequence[TrialRecord]) -> dict[tuple, float]:
    """Per problem (`problem_key`): the median over its trials (seeds) of `time_to_valid_s`."""
    times: dict[tuple, list[float]] = {}
    for r in records:
        times.setdefault(problem_key(r), []).append(time_to_valid_s(r))
    return {k: float(statistics.median(v)) for k, v in times.items()}


def median_ratio(a: dict[tuple, float], b: dict[tuple, float], *, clusters: dict[tuple, Any] | None = None,
                 resamples: int = RESAMPLES, seed: int = 0, level: float = 0.95) -> RatioSummary:
    """The median over problems of a[p] / b[p] and its percentile-bootstrap intervals.

    Args:
        a, b: per-problem times (s) of the two planners, on the same problems.
        clusters: per problem, the cluster (scene) it belongs to, for the second interval; None:
            every problem its own cluster.
        resamples: bootstrap resamples; seed: the bootstrap's seed (the same numbers every time).
        level: the intervals' coverage.

    Raises:
        SuiteError: the two planners' problems differ, or there are none.
    """
    if set(a) != set(b):
        raise SuiteError(f"the two planners ran different problems ({len(set(a) ^ set(b))} in one only)")
    if not a:
        raise SuiteError("no problems to compare")
    keys = sorted(a)
    ratios = np.array([a[k] / b[k] for k in keys], float)
    lo, hi = cluster_bootstrap_median_ci(ratios, keys, rng=np.random.default_rng(seed), n_resamples=resamples,
                                         level=level)
    groups = [clusters[k] for k in keys] if clusters is not None else keys
    slo, shi = cluster_bootstrap_median_ci(ratios, groups, rng=np.random.default_rng(seed), n_resamples=resamples,
                                           level=level)
    return RatioSummary(median=float(np.median(ratios)), problems=len(keys), ci_low=lo, ci_high=hi,
                        ci_scene_low=slo, ci_scene_high=shi)


def verdict(ratio: RatioSummary, target: float = TARGET_RATIO) -> str:
    """Whether the median ratio is at most `target`, and whether its interval says so too."""
    if not (math.isfinite(ratio.ci_low) and math.isfinite(ratio.ci_high)):
        return f"median {'met' if ratio.median <= target else 'not met'} (no interval: one problem)"
    if ratio.ci_high <= target:
        return "met"
    if ratio.ci_low > target:
        return "not met"
    return f"median {'met' if ratio.median <= target else 'not met'}, interval crosses {target:g}"


# --- reading a setting --------------------------------------------------------------------------------


def setting_runs(setting: Path) -> list[Path]:
    """The run directories of a setting: the directory itself if it holds `trials.jsonl`, else its
    sub-directories that do (sorted).

    Raises:
        SuiteError: there is none.
    """
    if (setting / TRIALS_FILE).is_file():
        return [setting]
    runs = sorted(d for d in setting.iterdir() if (d / TRIALS_FILE).is_file()) if setting.is_dir() else []
    if not runs:
        raise SuiteError(f"{setting} holds no runs (no {TRIALS_FILE} in it or its sub-directories)")
    return runs


def _mode(values: Sequence[Any], default: Any) -> Any:
    values = [v for v in values if v is not None]
    return statistics.mode(values) if values else default


def _median(values: Sequence[float | None]) -> float:
    values = [float(v) for v in values if v is not None and math.isfinite(float(v))]
    return float(statistics.median(values)) if values else math.nan


def _side_settings(recs: Sequence[TrialRecord]) -> tuple[str, str, str]:
    """(check, re-check, post-processing) of a planner's records, as they ran."""
    stats = [r.stats or {} for r in recs]
    cfg = recs[0].planner_config or {}
    if "collision_check_step_rad" in cfg:  # roboplan-rrt: L2 steps, no re-check, its shortcutter
        step, norm = cfg["collision_check_step_rad"], "l2"
        post = f"PathShortcutter({cfg.get('shortcut_max_iters')})" if cfg.get("shortcut") else "none"
    else:  # rrt and the other OMPL planners
        step, norm = cfg.get("resolution_rad"), cfg.get("resolution_norm", "linf")
        post = cfg.get("simplifier") if cfg.get("simplify_time_s", 1) > 0 else "none"
    fine = cfg.get("validate_resolution_rad")
    recheck = (f"{fine:g} rad, largest joint (replans at it)" if fine is not None and step is not None
               and fine < step else "none")
    # what the trials say they ran, where they say it (the planner config where they do not)
    step = _mode([s.get("resolution_rad") for s in stats], step)
    norm = _mode([s.get("resolution_norm") for s in stats], norm)
    post = _mode([s.get("post_processing") for s in stats], post or "not recorded")
    return f"{step:g} rad, {norm}" if step is not None else "not recorded", recheck, post


def side_figures(planner: str, recs: Sequence[TrialRecord], *, seeds: int) -> Side:
    """One planner's figures over its records at one setting (`Side`)."""
    ok = [r for r in recs if is_success(r)]
    by_problem: dict[tuple, int] = {}
    for r in ok:
        by_problem[problem_key(r)] = by_problem.get(problem_key(r), 0) + 1
    times = per_problem_medians(recs)
    stats_ok = [r.stats or {} for r in ok]
    check, recheck, post = _side_settings(recs)
    return Side(
        planner=planner, check=check, recheck=recheck, post_processing=post, trials=len(recs),
        successes=len(ok), solved_every_seed=sum(1 for n in by_problem.values() if n >= seeds),
        certified=sum(1 for r in ok if (r.certification or {}).get("verdict") == "certified"),
        time_s=float(statistics.median(times.values())),
        search_s=_median([s.get("solve_time_s") for s in stats_ok]),
        post_s=_median([s.get("simplify_time_s") for s in stats_ok]),
        length_ratio=_median([(r.metrics or {}).get("length_ratio") for r in ok]),
        samples_per_edge=_median([(r.stats or {}).get("samples_per_edge") for r in recs]),
        samples_per_edge_from=_mode([(r.stats or {}).get("samples_per_edge_from") for r in recs], "not recorded"),
        cold_trials=sum(1 for r in recs if r.warm is False),
    )


def analyse_setting(setting: Path, *, planners: tuple[str, str] = PLANNERS, resamples: int = RESAMPLES,
                    seed: int = 0) -> SettingResult:
    """Read a setting's runs and work out its figures (`SettingResult`).

    Raises:
        SuiteError: runs of different datasets or budgets, a seed run twice, a run without one of
            the planners, or planners whose problems differ within a run.
    """
    runs = setting_runs(setting)
    records: dict[str, list[TrialRecord]] = {p: [] for p in planners}
    seeds, commits, datasets, budgets, ranges = [], [], set(), set(), set()
    for run in runs:
        manifest = read_manifest(run)
        config = manifest.get("config") or {}
        seeds.append(int(config.get("seed", 0)))
        commits.append(str(manifest.get("git_commit", "unknown")))
        datasets.add(str(config.get("dataset")))
        recs = read_trials(run)
        per_run = {p: [r for r in recs if r.planner == p] for p in planners}
        for p, rs in per_run.items():
            if not rs:
                raise SuiteError(f"{run} has no trials of {p}")
            budgets.update(float(r.time_limit_s) for r in rs)
            ranges.update((r.planner_config or {}).get("range_rad") for r in rs)
            records[p].extend(rs)
        a, b = ({problem_key(r) for r in per_run[p]} for p in planners)
        if a != b:
            raise SuiteError(f"{run}: {planners[0]} and {planners[1]} ran different problems "
                             f"({len(a ^ b)} in one only): an incomplete run? (compare --resume)")
    if len(set(seeds)) != len(seeds):
        raise SuiteError(f"{setting}: a run seed appears twice ({sorted(seeds)})")
    if len(datasets) > 1 or len(budgets) > 1:
        raise SuiteError(f"{setting}: runs of different datasets or budgets ({sorted(datasets)}, {sorted(budgets)})")
    scenes = {problem_key(r): r.scene_key for rs in records.values() for r in rs}
    ratio = median_ratio(per_problem_medians(records[planners[0]]), per_problem_medians(records[planners[1]]),
                         clusters=scenes, resamples=resamples, seed=seed)
    rng_values = [r for r in ranges if r is not None]
    return SettingResult(
        name=setting.name, runs=tuple(str(r) for r in runs), dataset=datasets.pop(), time_limit_s=budgets.pop(),
        seeds=tuple(sorted(seeds)), problems=ratio.problems,
        range_rad=float(rng_values[0]) if len(set(rng_values)) == 1 else None, commits=tuple(commits),
        a=side_figures(planners[0], records[planners[0]], seeds=len(runs)),
        b=side_figures(planners[1], records[planners[1]], seeds=len(runs)),
        ratio=ratio, verdict=verdict(ratio))


# --- output ---------------------------------------------------------------------------------------------


def _s(v: float | None, spec: str = ".3g") -> str:
    return "-" if v is None or not math.isfinite(v) else format(v, spec)


def markdown(results: Sequence[dict[str, Any]]) -> str:
    """The two tables (the ratios; each side) of settings as `json.loads` gives them back."""
    lines = [f"| setting | range (rad) | problems x seeds | `{PLANNERS[0]}` time (s) | `{PLANNERS[1]}` time (s) "
             f"| ratio, median [95% CI] | at most {TARGET_RATIO:g}x |", "|---|---|---|---|---|---|---|"]
    for r in results:
        q, a, b = r["ratio"], r["a"], r["b"]
        check = f"both {a['check']}" if a["check"] == b["check"] else f"{a['check']} / {b['check']}"
        lines.append(f"| {check} | {_s(r['range_rad'])} | {r['problems']} x {len(r['seeds'])} "
                     f"| {_s(a['time_s'])} | {_s(b['time_s'])} "
                     f"| {_s(q['median'], '.2f')} [{_s(q['ci_low'], '.2f')}, {_s(q['ci_high'], '.2f')}] | {r['verdict']} |")
    lines += ["", "| setting | planner | edge check | re-check | post-processing | solved (trials) | certified "
              "| length ratio | samples per edge | search / post-processing (s) |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        for s in (r["a"], r["b"]):
            lines.append(f"| {r['name']} | `{s['planner']}` | {s['check']} | {s['recheck']} | {s['post_processing']} "
                         f"| {s['successes']}/{s['trials']} | {s['certified']}/{s['successes']} "
                         f"| {_s(s['length_ratio'])} | {_s(s['samples_per_edge'])} ({s['samples_per_edge_from']}) "
                         f"| {_s(s['search_s'])} / {_s(s['post_s'])} |")
    return "\n".join(lines) + "\n"


def as_json(results: Sequence[SettingResult], *, resamples: int, seed: int) -> dict[str, Any]:
    """The analysis as plain JSON values (NaN as null)."""
    def clean(v):
        if isinstance(v, float) and not math.isfinite(v):
            return None
        if isinstance(v, dict):
            return {k: clean(x) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [clean(x) for x in v]
        return v

    return clean({"target_ratio": TARGET_RATIO, "bootstrap": {"resamples": resamples, "seed": seed, "level": 0.95},
                  "planners": list(PLANNERS), "settings": [dataclasses.asdict(r) for r in results]})


def docs_block(root: Path, *, check_runs: Callable[[list[Path]], Any] | None = None) -> str:
    """docs/peers.md's generated table: `markdown` of `ANALYSIS_JSON`, or a line saying how to
    make it when there is none.

    Args:
        root: the repository's root.
        check_runs: called with every run the analysis read (as it names them) before anything is
            written from it: `suite docs` passes its provenance check, which refuses a run whose
            manifest records a dirty tree or no commit. None: the commits the analysis recorded
            are checked instead.

    Raises:
        SuiteError: a run of the analysis is from a tree with uncommitted changes.
    """
    path = root / ANALYSIS_JSON
    if not path.is_file():
        return f"_Not measured yet: `{COMMAND}` runs the settings below and writes `{ANALYSIS_JSON}`._\n"
    data = json.loads(path.read_text(encoding="utf-8"))
    if check_runs is not None:
        check_runs([Path(run) for r in data["settings"] for run in r["runs"]])
    for r in data["settings"]:
        dirty = [run for run, c in zip(r["runs"], r["commits"]) if c.endswith("+dirty")]
        if dirty:
            raise SuiteError(f"{ANALYSIS_JSON}: run {dirty[0]} is from a tree with uncommitted changes")
    return markdown(data["settings"])


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m suite.report.peers_equal", description=__doc__.split("\n\n")[0])
    p.add_argument("settings", nargs="+", metavar="SETTING_DIR",
                   help="a setting's directory: its sub-directories are compare runs, one per run seed")
    p.add_argument("--json", default=None, metavar="FILE", help="also write the analysis as JSON here")
    p.add_argument("--resamples", type=int, default=RESAMPLES, help=f"bootstrap resamples (default {RESAMPLES})")
    p.add_argument("--seed", type=int, default=0, help="the bootstrap's seed (default 0)")
    args = p.parse_args(argv)
    try:
        results = [analyse_setting(Path(s), resamples=args.resamples, seed=args.seed) for s in args.settings]
    except SuiteError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    data = as_json(results, resamples=args.resamples, seed=args.seed)
    sys.stdout.write(markdown(data["settings"]))
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
