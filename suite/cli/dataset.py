"""`python -m suite dataset build|verify|show|recertify|rereference|refine|rewitness`: frozen datasets of problems with reference solutions."""

from __future__ import annotations

import argparse
import json
import sys

from scenes.errors import SuiteError
from suite.cli.args import nonneg_int, positive_float, positive_int


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True, parser_class=type(p))
    b = sub.add_parser("build", help="draw scenes, build their problems and reference solutions, write the dataset")
    b.add_argument("--name", required=True, help="dataset name (directory under scenes/datasets/)")
    b.add_argument("--variants", default=None,
                   help="comma-separated families (default open,wall,station,shelf,window,clutter)")
    b.add_argument("--scenes", type=positive_int, default=12, help="scenes per family (default 12)")
    b.add_argument("--cans", type=positive_int, default=5, help="cans per scene; clutter draws its own (default 5)")
    b.add_argument("--seed", type=nonneg_int, default=0, help="first scene seed (default 0)")
    b.add_argument("--reference-time-s", type=positive_float, default=10.0,
                   help="AORRTC budget per non-trivial problem for its reference solution (default 10)")
    b.add_argument("--quick-problems", type=positive_int, default=120, help="size of the quick tier (default 120)")
    b.add_argument("--jobs", type=positive_int, default=2, help="worker processes (default 2)")
    b.add_argument("--no-progress", action="store_true", help="no progress output")
    v = sub.add_parser("verify", help="re-validate every reference and re-check every hash")
    v.add_argument("name", help="dataset name")
    r = sub.add_parser("recertify", help="write a revision of a dataset with every reference certified (same problems)")
    r.add_argument("--from", dest="source", required=True, help="the dataset to revise (left untouched)")
    r.add_argument("--name", required=True, help="the revision's name (directory under scenes/datasets/)")
    r.add_argument("--reference-time-s", type=positive_float, default=10.0,
                   help="AORRTC budget per reference planned again (default 10)")
    r.add_argument("--jobs", type=positive_int, default=2, help="worker processes (default 2)")
    r.add_argument("--no-progress", action="store_true", help="no progress output")
    o = sub.add_parser("rereference", help="write a revision of a dataset whose best known paths come from a long "
                                           "offline search and a local optimizer alone (same problems and ids)")
    o.add_argument("--from", dest="source", required=True, help="the dataset to revise (left untouched)")
    o.add_argument("--name", required=True, help="the revision's name (directory under scenes/datasets/)")
    o.add_argument("--search-s", type=positive_float, default=20.0,
                   help="AORRTC's budget per non-trivial problem, s (default 20)")
    o.add_argument("--starts", type=nonneg_int, default=3,
                   help="RRT-Connect runs whose paths the local optimizer also starts from (default 3)")
    o.add_argument("--polish-s", type=positive_float, default=5.0,
                   help="the certified descent's budget per start, s (default 5)")
    o.add_argument("--trajopt-s", type=positive_float, default=5.0,
                   help="each trajectory optimization started from a path, s (default 5)")
    o.add_argument("--jobs", type=positive_int, default=2, help="worker processes (default 2)")
    o.add_argument("--no-progress", action="store_true", help="no progress output")
    f = sub.add_parser("refine", help="run the local optimizers again from every offline-search best known path "
                                      "of a revision not yet shipped, in place; keep what is shorter and certified")
    f.add_argument("name", help="dataset name")
    f.add_argument("--polish-s", type=positive_float, default=2.0, help="the certified descent's budget, s (default 2)")
    f.add_argument("--trajopt-s", type=positive_float, default=5.0,
                   help="each seeded trajectory optimization's budget, s (default 5)")
    f.add_argument("--jobs", type=positive_int, default=2, help="worker processes (default 2)")
    f.add_argument("--no-progress", action="store_true", help="no progress output")
    w = sub.add_parser("rewitness", help="apply the witness rule (at least 0.1 mm of clearance) to a dataset "
                                         "built before it, in place (not for a shipped dataset)")
    w.add_argument("name", help="dataset name")
    s = sub.add_parser("show", help="print a dataset's composition")
    s.add_argument("name", help="dataset name, optionally NAME:TIER")
    s.add_argument("--json", action="store_true", help="print it as JSON")
    s.add_argument("--plot", metavar="PNG", help="also draw the composition and difficulty to PNG")


def run(args: argparse.Namespace) -> int:
    return {"build": _build, "verify": _verify, "show": _show, "recertify": _recertify,
            "rereference": _rereference, "refine": _refine, "rewitness": _rewitness}[args.action](args)


def _refine(args: argparse.Namespace) -> int:
    from suite.problems.dataset import dataset_dir, read_manifest
    from suite.run.best_known import REFINE_JOURNAL_FILE, refine_dataset
    from suite.run.interrupt import Interrupted, SignalGuard

    out = dataset_dir(args.name)
    read_manifest(out)  # an unknown dataset fails before any work
    with SignalGuard():
        try:
            m = refine_dataset(args.name, polish_s=args.polish_s, trajopt_s=args.trajopt_s, jobs=args.jobs,
                               argv=sys.argv[1:], progress_bar=not args.no_progress)
        except Interrupted as exc:
            print(f"interrupted by {exc.name}: the problems refined so far are kept in {out / REFINE_JOURNAL_FILE}; "
                  f"run the same command again to go on", file=sys.stderr)
            return exc.exit_code
    r = m["refined"]
    print(f"dataset {m['name']} ({m['hash']}): {r['shortened']} of {r['tried']} best known paths shortened; "
          f"new / old {r['new_over_old_length_quantiles']}")
    return 0


def _rereference(args: argparse.Namespace) -> int:
    from suite.problems.dataset import dataset_dir, read_manifest
    from suite.run.best_known import JOURNAL_FILE, rereference_dataset
    from suite.run.interrupt import Interrupted, SignalGuard

    read_manifest(dataset_dir(args.source))  # an unknown source fails before any work
    out = dataset_dir(args.name)
    with SignalGuard():
        try:
            m = rereference_dataset(args.source, args.name, search_s=args.search_s, rrt_starts=args.starts,
                                    polish_s=args.polish_s, trajopt_s=args.trajopt_s, jobs=args.jobs,
                                    argv=sys.argv[1:],
                                    progress_bar=not args.no_progress)
        except Interrupted as exc:
            print(f"interrupted by {exc.name}: the problems searched so far are kept in {out / JOURNAL_FILE}; "
                  f"run the same command again to go on", file=sys.stderr)
            return exc.exit_code
    r = m["rereferenced"]
    print(f"dataset {m['name']} ({m['hash']}), a revision of {m['revision_of']['name']}: {r['searched']} best known "
          f"paths searched again, {len(r['kept_from_source'])} kept (not solved by the search); new / old length "
          f"{r['new_over_old_length_quantiles']}; shorter {r['shorter_than_source']}, equal {r['equal_to_source']}, "
          f"longer {r['longer_than_source']}")
    return 0


def _rewitness(args: argparse.Namespace) -> int:
    from suite.problems.dataset import dataset_dir, read_manifest
    from suite.run.rewitness_dataset import rewitness_dataset

    read_manifest(dataset_dir(args.name))  # an unknown dataset fails before any work
    m = rewitness_dataset(args.name, argv=sys.argv[1:])
    r = m["rewitnessed"]
    print(f"dataset {m['name']} ({m['hash']}, was {r['hash_before']}): {len(r['replaced'])} witnesses replaced by "
          f"ones with at least {r['min_clearance_m']} m of clearance, {len(r['dropped'])} problems left the benchmark "
          f"(no witness found with it); witness clearance now {m['witness_clearance_m']}")
    return 0


def _recertify(args: argparse.Namespace) -> int:
    from suite.problems.dataset import dataset_dir, read_manifest
    from suite.run.recertify_dataset import recertify_dataset

    read_manifest(dataset_dir(args.source))  # an unknown source fails before any work
    dataset_dir(args.name)
    m = recertify_dataset(args.source, args.name, reference_time_s=args.reference_time_s, jobs=args.jobs,
                          argv=sys.argv[1:], progress_bar=not args.no_progress)
    r = m["recertified"]
    v = r["source_verdicts"]
    print(f"dataset {m['name']} ({m['hash']}), a revision of {m['revision_of']['name']}: references were "
          f"{v['certified']} certified, {v['unproved']} unproved, {v['collision']} in collision; {r['replaced']} "
          f"replaced by certified paths, {len(r['dropped'])} problems dropped (no certified path found)")
    return 0


def _build(args: argparse.Namespace) -> int:
    from scenes.spec import available_variants
    from suite.run.build_dataset import BuildSettings, build_dataset

    from suite.problems.dataset import dataset_dir

    families = BuildSettings(name=args.name).families
    if args.variants is not None:
        families = tuple(v.strip() for v in args.variants.split(",") if v.strip())
        known = available_variants()
        bad = [f for f in families if f not in known]
        if bad or not families:
            raise SuiteError(f"unknown variant {bad[0] if bad else args.variants!r}; allowed: {known}")
    dataset_dir(args.name)  # a bad name fails before any work
    settings = BuildSettings(name=args.name, families=families, scenes=args.scenes, cans=args.cans, seed=args.seed,
                             reference_time_s=args.reference_time_s, quick_problems=args.quick_problems,
                             jobs=args.jobs)
    from suite.run.interrupt import Interrupted, SignalGuard

    with SignalGuard():
        try:
            manifest = build_dataset(settings, argv=sys.argv[1:], progress_bar=not args.no_progress)
        except Interrupted as exc:
            print(f"interrupted by {exc.name}: nothing written (a dataset is written only when complete); "
                  f"run the same command again to build it", file=sys.stderr)
            return exc.exit_code
    c = manifest["counts"]
    print(f"dataset {manifest['name']} ({manifest['hash']}): {c['problems']} problems in {c['scenes']} scenes, "
          f"{c['trivial']} trivial; quick tier {len(manifest['tiers']['quick'])}; dropped {c['unsolved_dropped']} "
          f"unsolved and {c['trivial_dropped']} trivial")
    return 0


def _verify(args: argparse.Namespace) -> int:
    from suite.problems.dataset import verify_dataset

    def progress(i, n):
        if sys.stderr.isatty() and (i % 50 == 0 or i == n):
            print(f"\rverified {i}/{n}", end="", file=sys.stderr, flush=True)

    counts = verify_dataset(args.name, progress=progress)
    print(file=sys.stderr)
    v = counts["references"]
    print(f"dataset {args.name}: {counts['problems']} problems and {counts['cycle_steps']} stored cycle steps in "
          f"{counts['scenes']} scenes verified (hashes, problem_ids under identity rule {counts['identity_rule']}, "
          f"references valid at the validator's resolution); exact "
          f"verdict of the references: {v['certified']} certified, {v['unproved']} unproved, {v['collision']} in "
          f"collision" + ("" if counts["references_must_be_certified"] else
                          " (a dataset built before certification: counted, not required)"))
    return 0


def _show(args: argparse.Namespace) -> int:
    from suite.problems.dataset import load_dataset, summary

    if args.plot and not args.plot.lower().endswith(".png"):
        raise SuiteError(f"--plot must name a .png file, got {args.plot!r}")
    ds = load_dataset(args.name)
    info = summary(ds)
    if args.plot:
        from pathlib import Path

        from suite.report.plots_dataset import plot_dataset

        Path(args.plot).parent.mkdir(parents=True, exist_ok=True)
        plot_dataset(ds, Path(args.plot))
    if args.json:
        print(json.dumps(info))
        return 0
    print(f"dataset {info['name']} (tier {info['tier']}, hash {info['hash']}, identity rule {info['identity_rule']}): "
          f"{info['problems']} problems, "
          f"{info['distinct']} distinct, {info['trivial']} trivial ({info['trivial'] / max(info['problems'], 1):.0%})")
    print(f"{'family':10s} {'scenes':>6s} {'problems':>8s} {'trivial':>7s}  kinds")
    for fam, f in info["families"].items():
        kinds = ", ".join(f"{k} {n}" for k, n in f["kinds"].items())
        print(f"{fam:10s} {f['scenes']:6d} {f['problems']:8d} {f['trivial']:7d}  {kinds}")
    q = info["difficulty_quantiles"]
    print("difficulty (fraction of the straight segment in collision): "
          + ", ".join(f"{k} {v:.3f}" for k, v in q.items()))
    r = info["reference_over_straight_quantiles"]
    print("reference length / straight distance: " + ", ".join(f"{k} {v:.3f}" for k, v in r.items()))
    print("splits: " + ", ".join(f"{k} {v}" for k, v in info["splits"].items())
          + "; tiers: " + ", ".join(f"{k} {v}" for k, v in info["tiers"].items()))
    return 0
