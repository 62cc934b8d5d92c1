"""`python -m suite regions build --dataset NAME[:TIER]`: build `gcs`'s convex regions ahead.

One job per distinct collision world of the dataset's problems, on the local process pool or a
Dask cluster (the suite's executors, with their hard limits and crash handling); each grows the
world's region set for all its problems and returns it, and this process stores it under the
world's hash, where every later `gcs` trial finds it (see `planners.gcs.regions`). Worlds already
built and verified are not rebuilt (a Dask worker on another machine sees the cache only through
a shared file system; otherwise it rebuilds).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

from scenes.errors import SuiteError
from suite.cli.args import positive_int

#: A world's build is killed after this long (the slowest measured: 171 s on 2 busy cores).
HARD_LIMIT_S = 1800.0


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True, parser_class=type(p))
    b = sub.add_parser("build", help="build (or complete) the gcs regions of every collision world of a dataset")
    b.add_argument("--dataset", required=True, help="NAME[:TIER] (e.g. recycle-v2:quick)")
    b.add_argument("--out", default=None,
                   help="region cache directory (default scenes/datasets/NAME/regions/, read by gcs)")
    b.add_argument("--iris", default=None, help="IRIS algorithm: np2 or zo (default: gcs's default)")
    b.add_argument("--seeding", default=None,
                   help="chain, cliques (from the world alone) or problem (at each problem's ends; default: gcs's default)")
    b.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", dest="region_set",
                   help="a region option of gcs (planners.gcs.sets.RegionOptions: e.g. max_iterations=10, "
                        "termination_threshold=-1); repeatable")
    b.add_argument("--jobs", type=positive_int, default=2, help="worker processes (default 2)")
    b.add_argument("--executor", choices=("local", "dask"), default="local", help="where jobs run (default local)")
    b.add_argument("--scheduler", default=None, help="Dask scheduler address tcp://HOST:PORT (with --executor dask)")
    b.add_argument("--limit", type=positive_int, default=None, help="build only the first K worlds")
    b.add_argument("--tune-sample", type=positive_int, default=None, metavar="PER_FAMILY",
                   help="only the worlds of `tune --per-family PER_FAMILY`'s sample (the non-trivial problems of "
                        "the dataset's tune split; --dataset names the dataset alone)")
    b.add_argument("--rebuild", action="store_true",
                   help="grow every world from nothing, ignoring cached regions (e.g. to re-measure the offline "
                        "cost on a quiet machine, or after changing how regions grow)")
    _add_report(sub)


def _add_report(sub) -> None:
    r = sub.add_parser("report", help="per family, what the cached regions of a setting are (nothing is grown)")
    r.add_argument("--dataset", required=True, help="NAME[:TIER], or NAME with --tune-sample")
    r.add_argument("--tune-sample", type=positive_int, default=None, metavar="PER_FAMILY",
                   help="the worlds of `tune --per-family PER_FAMILY`'s sample")
    r.add_argument("--seeding", default=None, help="chain or cliques (default: gcs's tuned setting)")
    r.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", dest="region_set",
                   help="a region option of gcs over its tuned settings (as for build); repeatable")
    r.add_argument("--json", default=None, metavar="FILE", help="also write the figures, per world too, as JSON")


def parse_region_settings(items: list[str]) -> dict:
    """`--set NAME=VALUE` items as {name: value} (values read as YAML scalars), each name a field of
    `RegionOptions`; anything else is one SuiteError line."""
    import dataclasses

    import yaml

    from planners.gcs.sets import RegionOptions

    names = sorted(f.name for f in dataclasses.fields(RegionOptions))
    out = {}
    for item in items:
        name, eq, value = item.partition("=")
        if not eq or name.strip() not in names:
            raise SuiteError(f"--set {item!r}: expected NAME=VALUE with NAME one of {', '.join(names)}")
        out[name.strip()] = yaml.safe_load(value)
    return out


def _connected(rs, problem) -> bool:
    """Whether gcs would find start and goal linked by the regions (after its online joins)."""
    from planners.gcs.solve import connect_ends
    from planners.worlds import collision_world

    return bool(connect_ends(rs.A, rs.b, rs.edges, problem.q_start, problem.q_goal,
                             world=collision_world(problem))["connected"])


def _build_world(payload: tuple) -> dict:
    """Worker: grow one world's regions for each of its problems (in this process)."""
    problems, options, out, rebuild = payload
    from planners.gcs.regions import regions_for
    from planners.gcs.sets import RegionSet

    t0 = time.perf_counter()
    infos = []
    rs: RegionSet | None = None
    for i, problem in enumerate(problems):
        rs, info = regions_for(problem, options, cache_dir=out, build=True, fresh=rebuild and i == 0)
        infos.append(info)
    connected = [_connected(rs, p) for p in problems] if rs is not None else []
    stored = None if rs is None else {
        "A": [a.tolist() for a in rs.A], "b": [x.tolist() for x in rs.b], "seeds": [q.tolist() for q in rs.seeds],
        "region_build_s": rs.region_build_s, "offline_s": rs.offline_s, "problems": rs.problems,
        "edges": [list(e) for e in rs.edges], "iris": rs.iris, "checked": rs.checked, "region_iris": rs.region_iris,
        "offline_cpu_s": rs.offline_cpu_s,
    }
    return {
        "set": stored,
        "world_hash": infos[0]["world_hash"],
        "problems": len(problems),
        "connected": sum(connected),
        "regions": 0 if rs is None else len(rs),
        "offline_s": 0.0 if rs is None else rs.offline_s,
        "offline_cpu_s": None if rs is None else rs.offline_cpu_s,
        "region_build_s": [] if rs is None else list(rs.region_build_s),
        "region_iris": [] if rs is None else list(rs.region_iris),
        "cache": [i["cache"] for i in infos],
        "wall_s": time.perf_counter() - t0,
    }


def run(args: argparse.Namespace) -> int:
    if args.action == "report":
        return _report(args)
    return _build(args)


def _options(args):
    from planners.gcs.planner import GcsPlanner
    from suite.run.trial import make_config

    chosen = {k: v for k, v in (("iris", getattr(args, "iris", None)), ("seeding", args.seeding)) if v is not None}
    chosen.update(parse_region_settings(args.region_set))
    return make_config(GcsPlanner, chosen).region_options()  # gcs's tuned settings, overlaid


def _report(args: argparse.Namespace) -> int:
    from suite.report.regions_table import markdown, report

    rep = report(args.dataset, tune_sample=args.tune_sample, options=_options(args))
    print(markdown(rep))
    if args.json:
        Path(args.json).write_text(json.dumps(rep, indent=1, default=str))
    return 0 if rep["worlds"] else 1


def _build(args: argparse.Namespace) -> int:
    from planners.gcs.sets import world_hash
    from suite.problems.dataset import dataset_dir, load_dataset, parse_dataset_arg, tuning_problems

    if args.scheduler and args.executor != "dask":
        raise SuiteError("--scheduler needs --executor dask")
    if args.tune_sample is not None:
        ds, sample = tuning_problems(args.dataset, per_family=args.tune_sample, time_limit_s=5.0)
        problems = [p for p, _ in sample]
    else:
        ds = load_dataset(args.dataset)
        problems = ds.problems
    options = _options(args)
    out = Path(args.out) if args.out else dataset_dir(parse_dataset_arg(args.dataset)[0]) / "regions"
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SuiteError(f"--out {str(out)!r} is not writable: {exc.strerror}") from None
    worlds: dict[str, list] = {}
    for p in problems:
        if p.pre_status is None and p.q_goal is not None:
            worlds.setdefault(world_hash(p, options), []).append(p)
    items = list(worlds.values())[: args.limit]
    print(f"{len(problems)} problems in {len(worlds)} collision worlds; building {len(items)} "
          f"({options.iris}) into {out} ({args.executor}, {args.jobs} workers)", flush=True)
    from suite.run.executors import Job, LocalExecutor

    if args.executor == "dask":
        from suite.run.dask_executor import DaskExecutor

        executor = DaskExecutor(scheduler=args.scheduler, n_workers=args.jobs)
    else:
        executor = LocalExecutor(jobs=args.jobs)
    jobs = [Job(world_hash(ps[0], options), _build_world, (ps, options, str(out), args.rebuild), HARD_LIMIT_S) for ps in items]
    from suite.run.interrupt import Interrupted, SignalGuard
    from suite.run.lock import LOCK_FILE, RunLock

    rows: list[dict] = []
    with SignalGuard(), RunLock(out, what="regions build"):  # one build per regions directory
        try:
            code = _build_all(executor, jobs, items, out, rows, args, options)
        except Interrupted as exc:
            # Count the files, not the results received: a worker writes its world's file before
            # this process collects its result (and the workers are stopped by now).
            kept = sum((out / f"{job.key}.npz").is_file() for job in jobs)
            print(f"interrupted by {exc.name}: the {kept} world(s) finished are kept in {out}; run the same "
                  f"command again to build the rest", file=sys.stderr)
            return exc.exit_code
        finally:
            (out / LOCK_FILE).unlink(missing_ok=True)  # the directory is committed as data
    return code


def _build_all(executor, jobs, items, out: Path, rows: list[dict], args, options) -> int:
    """Run the world builds, saving each world's regions as it finishes; write the build's summary."""
    t0 = time.perf_counter()
    outcomes = executor.run(jobs)
    try:
        for k, outcome in enumerate(outcomes, 1):
            _record_world(k, outcome, items, out, rows)
    finally:
        outcomes.close()  # an error or a signal stops the workers at once
    return _write_summary(rows, out, args, options, wall=time.perf_counter() - t0, items=items)


def _record_world(k: int, outcome, items, out: Path, rows: list[dict]) -> None:
    import numpy as np

    from planners.gcs.sets import RegionSet

    if outcome.result is None:
        print(f"[{k}/{len(items)}] {outcome.job.key}: {outcome.failure} ({outcome.message})", flush=True)
        return
    row = dict(outcome.result)
    stored = row.pop("set")
    if stored is not None and any(c != "hit" for c in row["cache"]):
        RegionSet(row["world_hash"], [np.asarray(x, float) for x in stored["A"]],
                  [np.asarray(x, float) for x in stored["b"]], [np.asarray(x, float) for x in stored["seeds"]],
                  stored["region_build_s"], stored["offline_s"], stored["problems"],
                  [tuple(e) for e in stored["edges"]], stored["iris"], stored["checked"], stored["region_iris"],
                  stored["offline_cpu_s"]).save(out / f"{row['world_hash']}.npz")
    rows.append(row)
    its = [r["iterations"] for r in row.get("region_iris") or []]
    print(f"[{k}/{len(items)}] {row['world_hash']}: {row['regions']} regions (IRIS iterations {its}), "
          f"{row['connected']}/{row['problems']} connected, offline {row['offline_s']:.1f} s "
          f"(CPU {row['offline_cpu_s'] or float('nan'):.1f} s; {'/'.join(row['cache'])})", flush=True)


def summary_name(selection: str, seeding: str = "chain", options=None) -> str:
    """The summary file of a build of `selection` (NAME[:TIER[:FILTERS]]) with `seeding`: one per
    tier, filters and seeding other than the chain, so that building regions for another tier of a
    dataset, or with another seeding, keeps the earlier build's figures; region `options` whose key
    differs from the class defaults' (other than the algorithm and the seeding, which have flags of
    their own) add a digest of that key."""
    import hashlib
    import re

    from planners.gcs.sets import RegionOptions

    rest = selection.partition(":")[2] or "all"
    tail = "" if seeding == "chain" else f"-{seeding}"
    if options is not None:
        mine = {k: v for k, v in options.key_fields().items() if k not in ("seeding", "iris")}
        base = RegionOptions(seeding=options.seeding, iris=options.iris).key_fields()
        base = {k: v for k, v in base.items() if k not in ("seeding", "iris")}
        if mine != base:
            tail += "-" + hashlib.sha1(json.dumps(mine, sort_keys=True).encode()).hexdigest()[:8]
    return "build-" + re.sub(r"[^A-Za-z0-9._=+-]+", "_", rest) + tail + ".json"


def _write_summary(rows: list[dict], out: Path, args, options, *, wall: float, items: list) -> int:
    from suite.report.regions_table import iris_summary
    from suite.report.tuning import p90

    built = [r for r in rows if any(c != "hit" for c in r["cache"])]
    per_region = [s for r in rows for s in r["region_build_s"]]
    cpu = [r["offline_cpu_s"] for r in rows if r.get("offline_cpu_s") is not None]
    summary = {
        "dataset": args.dataset, "iris": options.iris, "seeding": options.seeding, "options": options.key_fields(), "worlds": len(rows),
        "worlds_built_now": len(built), "wall_s": wall,
        "problems": sum(r["problems"] for r in rows), "connected": sum(r["connected"] for r in rows),
        "offline_s_median": statistics.median(r["offline_s"] for r in rows) if rows else None,
        "offline_s_max": max(r["offline_s"] for r in rows) if rows else None,
        "regions_median": statistics.median(r["regions"] for r in rows) if rows else None,
        "region_iris_s_median": statistics.median(per_region) if per_region else None,
        "offline_s_p90": p90([r["offline_s"] for r in rows]) if rows else None,
        "offline_cpu_s_median": statistics.median(cpu) if cpu else None,
        "offline_cpu_s_p90": p90(cpu) if cpu else None,
        "iris_runs": iris_summary([x for r in rows for x in r.get("region_iris") or []]),
        "size_bytes": sum(f.stat().st_size for f in out.glob("*.npz")),
        "worlds_detail": rows,
    }
    selection = args.dataset if args.tune_sample is None else f"{args.dataset}:tune-sample{args.tune_sample}"
    (out / summary_name(selection, options.seeding, options)).write_text(json.dumps(summary, indent=1))
    if not rows:
        print(f"no world was built: each of the {len(items)} failed (see above)", file=sys.stderr)
        return 1
    print(f"{summary['worlds']} worlds ({len(built)} built now) in {wall:.0f} s wall; median per world: "
          f"{summary['offline_s_median']:.1f} s offline (max {summary['offline_s_max']:.1f} s), "
          f"{summary['regions_median']} regions; median IRIS "
          f"call {summary['region_iris_s_median'] or 0:.2f} s; start and goal connected for "
          f"{summary['connected']}/{summary['problems']} problems; IRIS iterations per region: median "
          f"{summary['iris_runs'].get('iterations_median')}, stops {summary['iris_runs'].get('stop')}; "
          f"cache {summary['size_bytes'] / 1e6:.2f} MB",
          file=sys.stdout)
    return 0
