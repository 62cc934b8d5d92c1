"""`python -m suite export`: write a dataset's problems as files any planner can read."""

from __future__ import annotations

import argparse

from suite.cli.args import positive_float
from suite.problems import DEFAULT_TIER


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--dataset", default=DEFAULT_TIER, metavar="NAME[:TIER]",
                   help=f"the dataset (tier) to export (default {DEFAULT_TIER})")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="export directory: problems.jsonl, schema.json, robot/*.urdf, README.md")
    p.add_argument("--time-limit-s", type=positive_float, default=5.0,
                   help="planning budget per problem written into the problems, seconds (default 5)")


def run(args: argparse.Namespace) -> int:
    from suite.exchange.export import write_export

    manifest = write_export(args.dataset, args.out, time_limit_s=args.time_limit_s)
    ds = manifest["dataset"]
    print(f"exported {manifest['problems']} problems of {ds['name']}:{ds['tier']} (hash {ds['hash']}) to {args.out}")
    return 0
