"""`python -m suite bench TARGET`: print speed figures (benchmarks report numbers; tests don't)."""

from __future__ import annotations

import argparse
import importlib

#: target -> module with add_arguments(parser) and run(args)
TARGETS = {
    "collision": "suite.bench.collision",
    "perception": "suite.bench.perception",
    "lookalike": "suite.bench.lookalike",
    "noise-estimate": "suite.bench.noise_estimate",
    "planners": "suite.bench.planners",
    "compare": "suite.bench.compare",
    "execution": "suite.bench.execution",
    "dataset": "suite.bench.dataset",
    "regions": "suite.bench.regions",
    "gcs-regions": "suite.bench.gcs_regions",
    "single-tree": "suite.bench.single_tree",
    "certify": "suite.bench.certify",
    "attribution": "suite.bench.attribution",
    "agreement": "suite.bench.agreement",
    "budget-flip": "suite.bench.budget_flip",
    "machine": "suite.bench.machine",
    "kernel": "suite.bench.kernel",
    "load": "suite.bench.load",
}


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="target", metavar="TARGET", required=True, parser_class=type(p))
    for name, module in TARGETS.items():
        sp = sub.add_parser(name, help=f"{name} benchmark")
        sp.set_defaults(_bench_module=module)
        try:
            importlib.import_module(module).add_arguments(sp)
        except ModuleNotFoundError:
            pass  # reported when run


def run(args: argparse.Namespace) -> int:
    return int(importlib.import_module(args._bench_module).run(args) or 0)
