"""`python -m suite replay RUN PROBLEM`: a 3-D replay (Meshcat static HTML) of one problem's paths.

Written on demand rather than inlined in report.html: each replay carries Meshcat's viewer (about
3.5 MB). By default it goes to RUN/replays/PROBLEM.html, where the report's drill-down links it.
"""

from __future__ import annotations

import argparse


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", metavar="RUN", help="a run directory holding trials.jsonl")
    p.add_argument("problem", metavar="PROBLEM", help="the problem's id (as in report.html; a unique prefix of 6+ "
                                                      "characters will do)")
    p.add_argument("--out", default=None, metavar="FILE", help="the HTML file to write (default RUN/replays/ID.html)")


def run(args: argparse.Namespace) -> int:
    from suite.report.replay import write_replay

    replay = write_replay(args.run, args.problem, out=args.out)
    for planner, when in replay.schedule.items():
        print(f"  {planner}: " + (f"plays from {when[0]:.2f} s to {when[1]:.2f} s" if isinstance(when, tuple)
                                  else when))
    print(f"{replay.path} ({replay.path.stat().st_size / 1e6:.1f} MB); {replay.note}")
    return 0
