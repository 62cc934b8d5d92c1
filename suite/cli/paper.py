"""`python -m suite paper gcs-arm [run|dataset]`: a published experiment reproduced.

`gcs-arm` is the arm experiment of the GCS paper (Marcucci et al., Science Robotics 2023): its
shelves-and-bins scene and robot model, its five tasks, GCS against a PRM with a fixed roadmap
(plain and shortcut), beside the suite's `rrt`, `trajopt` and `ik` (suite/paper/gcs_arm*.py,
docs/gcs-paper.md).

- `run` (the default): the offline work (regions, roadmap; built once into the dataset's
  directory, then loaded), the GCS relaxation and optimum per task, `--runs` comparison runs, and
  the table beside the paper's findings (OUT/table.md, OUT/paper.json, OUT/paths.png).
- `dataset`: build scenes/datasets/gcs-arm-v2 (the ten problems: the five tasks and their
  reverses as free transits, with certified best known paths; `gcs-arm`, the first revision,
  stays as it was built).
- `convert-regions`: convert the paper's own regions (its repository's
  data/prm_comparison/IRIS.reg, a pickle, and its LICENSE.TXT) once into plain arrays in
  scenes/datasets/gcs-arm/paper-regions/ (`suite.paper.paper_regions`).

`--regions ours|paper|both` (default both): the region sets `gcs` plans on in `run`: ours (grown
at the paper's IRIS settings) and the paper's stored ones, side by side in the table.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from suite.cli.args import positive_float, positive_int

EXPERIMENTS = ("gcs-arm",)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("experiment", choices=EXPERIMENTS, help="the experiment: gcs-arm (the GCS paper's arm comparison)")
    p.add_argument("action", nargs="?", choices=("run", "dataset", "convert-regions"), default="run",
                   help="run the protocol (default), rebuild its dataset, or convert the paper's regions")
    p.add_argument("--runs", type=positive_int, default=10,
                   help="comparison runs (run seeds 0, 1, ...) per task and planner (default 10)")
    p.add_argument("--time-limit-s", type=positive_float, default=5.0,
                   help="online budget per query, the same for every planner (default 5)")
    p.add_argument("--jobs", type=positive_int, default=1,
                   help="worker processes of each run (default 1: timings on one core, as the paper's)")
    p.add_argument("--out", default="results/paper-gcs-arm", help="output directory (default results/paper-gcs-arm)")
    p.add_argument("--rebuild-offline", action="store_true",
                   help="grow the regions and the roadmap again (to re-measure their cost) instead of loading them")
    p.add_argument("--regions", default="both", choices=("ours", "paper", "both"),
                   help="run: the region sets gcs plans on: ours (grown at the paper's IRIS settings), the paper's "
                        "own (final generation), or both (default)")
    p.add_argument("--reg-file", default=None,
                   help="convert-regions: the paper repository's data/prm_comparison/IRIS.reg (at 3d781488)")
    p.add_argument("--license-file", default=None,
                   help="convert-regions: the paper repository's LICENSE.TXT (default: beside --reg-file's repository "
                        "root, i.e. ../../LICENSE.TXT)")
    p.add_argument("--search-s", type=positive_float, default=20.0,
                   help="dataset: AORRTC's budget of the offline search per problem (default 20)")
    p.add_argument("--no-progress", action="store_true", help="no progress lines")


def run(args: argparse.Namespace) -> int:
    if args.action == "dataset":
        from suite.paper.gcs_arm import build_dataset

        m = build_dataset(search_s=args.search_s, jobs=args.jobs, progress_bar=not args.no_progress,
                          argv=sys.argv[1:])
        print(f"dataset {m['name']}: {m['counts']['problems']} problems, hash {m['hash']}")
        return 0
    if args.action == "convert-regions":
        from scenes.errors import SuiteError
        from suite.paper.paper_regions import write_paper_regions

        if not args.reg_file:
            raise SuiteError("convert-regions needs --reg-file (the paper repository's data/prm_comparison/IRIS.reg)")
        reg = Path(args.reg_file)
        lic = Path(args.license_file) if args.license_file else reg.resolve().parents[2] / "LICENSE.TXT"
        for f in (reg, lic):
            if not f.is_file():
                raise SuiteError(f"{f} is not a file")
        path = write_paper_regions(reg.read_bytes(), lic.read_text())
        print(f"wrote {path} (and source.json, LICENSE.TXT beside it)")
        return 0
    from suite.paper.gcs_arm_protocol import parse_region_sets, run_protocol

    out = Path(args.out)
    report = run_protocol(out, runs=args.runs, time_limit_s=args.time_limit_s, jobs=args.jobs,
                          rebuild=args.rebuild_offline, progress=not args.no_progress,
                          regions=parse_region_sets(args.regions))
    print((out / "table.md").read_text())
    off = report["offline"]
    print(f"offline: {off['regions']} regions ({off['regions_cache']}, built in {off['regions_s']:.1f} s), roadmap of "
          f"{off['roadmap_milestones']} milestones ({off['roadmap_cache']}, built in {off['roadmap_s']:.1f} s)")
    print(f"wrote {out / 'table.md'}, {out / 'paper.json'} and {out / 'paths.png'}")
    return 0
