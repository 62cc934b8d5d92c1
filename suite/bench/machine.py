"""`python -m suite bench machine`: how fast this machine runs the suite's own checks, against the
machine the README's timings were measured on.

A planning time is a figure of the planner and of the machine. The README's timings carry the
machine they came from (`results/reference/machine.json`: its CPU, cores and this benchmark's
figures, measured on it beside the reference run). Run this on your machine: the ratio of your
figures to those says how much slower or faster the README's timings would be here.

The workload is fixed and short (a few seconds): the worlds of the first problem of each family in
the shipped dataset's quick tier (no IK: stored problems), the same seeded configurations and the
worlds' stored reference paths, on one thread:

- `fcl_state_us`: one python-fcl state check (`CollisionWorld.is_free`, what the OMPL planners'
  state checker runs), per configuration;
- `fcl_motion_us`: one motion check along a reference path segment at `rrt`'s resolution
  (`motion_samples_free`), per segment, on the numpy reference (the judge's path);
- `kernel_motion_us`: the same motion checks by the compiled kernels (the planners' path);
- `drake_state_us`: one Drake state check (`SceneGraphCollisionChecker.CheckConfigCollisionFree`,
  C++; Drake's queries are what `ik` and `trajopt` spend most of their time on).

Each item's time is its fastest of `--rounds` rounds (the least disturbed by other processes);
each figure is the median over items. The factor is the geometric mean of the ratios (yours / the
reference machine's): above 1, this machine is slower. `rrt`'s time follows the kernel and fcl
figures, `ik`'s and `trajopt`'s the Drake one, which is why each is shown.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from scenes.errors import SuiteError
from suite.cli.args import positive_float, positive_int
from suite.problems import DEFAULT_DATASET

#: Where the reference machine's figures are kept (measured beside the reference run).
REFERENCE_FILE = Path(__file__).resolve().parents[2] / "results" / "reference" / "machine.json"
FIGURES = ("fcl_state_us", "fcl_motion_us", "kernel_motion_us", "drake_state_us")
CONFIG_SEED = 20261126  # the configurations' generator seed (fixed: figures compare run to run)
#: `rrt`'s planning resolution (rad), at which the motion checks run
MOTION_RESOLUTION_RAD = 0.05


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--configs", type=positive_int, default=1000,
                   help="seeded configurations per world (default 1000)")
    p.add_argument("--rounds", type=positive_int, default=5,
                   help="timing rounds; an item's time is its fastest round (default 5)")
    p.add_argument("--against", default=str(REFERENCE_FILE),
                   help="the reference machine's figures (default: the README's, results/reference/machine.json)")
    p.add_argument("--save", metavar="JSON", default=None,
                   help="also write this machine's figures to JSON (how the reference file is made)")
    p.add_argument("--quickstart-wall-s", type=positive_float, default=None, metavar="S",
                   help="with --save: also record the Quickstart compare's wall time measured on this machine (s)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")


def _worlds(dataset: str) -> list:
    """The first problem of each family in the dataset's quick tier (stored order), with its reference."""
    from suite.problems.dataset import load_dataset

    ds = load_dataset(f"{dataset}:quick")
    out, seen = [], set()
    for pid, problem in zip(ds.ids, ds.problems):
        family = ds.meta[pid]["family"]
        if family not in seen:
            seen.add(family)
            out.append((family, problem, ds.references[pid]))
    return out


def measure(*, configs: int, rounds: int, dataset: str = DEFAULT_DATASET) -> dict[str, Any]:
    """This machine's figures on the fixed workload (see the module docstring)."""
    import pydrake.common  # noqa: F401  (it sets the "drake" logger's level on import: quiet it after)

    from planners.worlds import collision_world
    from scenes.fcl_compiled import CompiledWorld
    from suite.bench.collision import drake_checker

    logging.getLogger("drake").setLevel(logging.WARNING)  # not Drake's line per checker about its contexts
    perf = time.perf_counter
    state_fcl, state_drake, motion, kernel = [], [], [], []
    families = []
    for family, problem, reference in _worlds(dataset):
        families.append(family)
        world = collision_world(problem)
        compiled = CompiledWorld(problem.scene, gripper_opening_m=problem.gripper_opening_m, held=problem.held,
                                 removed_can_ids=problem.removed_can_ids)
        checker = drake_checker(problem.scene, held=problem.held, gripper_opening_m=problem.gripper_opening_m)
        Q = world.robot.random_configurations(np.random.default_rng(CONFIG_SEED), configs)
        segments = list(zip(reference[:-1], reference[1:]))
        for q in Q[:20]:  # warm up (first-call costs, caches)
            world.is_free(q)
            compiled.is_free(q)
            checker.CheckConfigCollisionFree(q)
        t_fcl = np.full(len(Q), np.inf)
        t_drake = np.full(len(Q), np.inf)
        t_motion = np.full(len(segments), np.inf)
        t_kernel = np.full(len(segments), np.inf)
        for _ in range(rounds):
            for m, q in enumerate(Q):  # interleaved: both engines see the same machine load
                t0 = perf()
                world.is_free(q)
                t1 = perf()
                checker.CheckConfigCollisionFree(q)
                t2 = perf()
                t_fcl[m] = min(t_fcl[m], t1 - t0)
                t_drake[m] = min(t_drake[m], t2 - t1)
            for m, (a, b) in enumerate(segments):
                t0 = perf()
                world.motion_samples_free(a, b, resolution_rad=MOTION_RESOLUTION_RAD)
                t1 = perf()
                compiled.motion_samples_free(a, b, resolution_rad=MOTION_RESOLUTION_RAD)
                t2 = perf()
                t_motion[m] = min(t_motion[m], t1 - t0)
                t_kernel[m] = min(t_kernel[m], t2 - t1)
        state_fcl.extend(t_fcl)
        state_drake.extend(t_drake)
        motion.extend(t_motion)
        kernel.extend(t_kernel)
    from suite.run.executors import cpu_description

    return {
        "machine": cpu_description(),
        "load_average_1min": round(os.getloadavg()[0], 2),
        "workload": {"dataset": dataset, "families": families, "configs_per_world": configs, "rounds": rounds,
                     "segments": len(motion), "config_seed": CONFIG_SEED,
                     "motion_resolution_rad": MOTION_RESOLUTION_RAD},
        "figures": {
            "fcl_state_us": round(float(np.median(state_fcl)) * 1e6, 2),
            "fcl_motion_us": round(float(np.median(motion)) * 1e6, 2),
            "kernel_motion_us": round(float(np.median(kernel)) * 1e6, 2),
            "drake_state_us": round(float(np.median(state_drake)) * 1e6, 2),
        },
        "measured_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }


def read_reference(path: str | Path) -> dict[str, Any]:
    """A saved figures file (`--save`), checked: every figure a positive number."""
    path = Path(path)
    try:
        ref = json.loads(path.read_text())
    except OSError as exc:
        raise SuiteError(f"--against {str(path)!r}: cannot read it ({exc.strerror})") from None
    except ValueError:
        raise SuiteError(f"--against {str(path)!r} is not JSON (a file written by bench machine --save)") from None
    figures = ref.get("figures") if isinstance(ref, dict) else None
    bad = [k for k in FIGURES if not isinstance((figures or {}).get(k), (int, float)) or not figures[k] > 0]
    if bad:
        raise SuiteError(f"--against {str(path)!r}: figure {bad[0]!r} missing or not a positive number; "
                         f"a figures file holds {', '.join(FIGURES)} (bench machine --save)")
    return ref


def factor(mine: dict[str, float], reference: dict[str, float]) -> float:
    """The geometric mean of mine / reference over FIGURES (above 1: this machine is slower)."""
    return math.exp(sum(math.log(mine[k] / reference[k]) for k in FIGURES) / len(FIGURES))


def run(args: argparse.Namespace) -> int:
    ref = read_reference(args.against) if args.against else None  # a bad file fails before any work
    mine = measure(configs=args.configs, rounds=args.rounds)
    if args.quickstart_wall_s is not None:
        mine["quickstart_wall_s"] = args.quickstart_wall_s
    if args.save:
        Path(args.save).write_text(json.dumps(mine, indent=1) + "\n")
    f = factor(mine["figures"], ref["figures"]) if ref else None
    if args.json:
        print(json.dumps({**mine, "reference": ref, "factor": f}))
        return 0
    w = mine["workload"]
    print(f"machine benchmark: {w['configs_per_world']} configurations and {w['segments']} reference-path segments "
          f"in {len(w['families'])} worlds of {w['dataset']}:quick ({', '.join(w['families'])}); each item's "
          f"fastest of {w['rounds']} round(s), medians; one thread")
    m = mine["machine"]
    print(f"  this machine: {m['cpu']}, {m['cores']} cores, load average {mine['load_average_1min']} (1 min)")
    if ref:
        r = ref["machine"]
        print(f"  reference:    {r['cpu']}, {r['cores']} cores, measured {ref.get('measured_utc', '?')} "
              f"({args.against})")
    print(f"  {'figure':16s} {'here':>9s}" + (f" {'reference':>10s} {'ratio':>6s}" if ref else ""))
    for k in FIGURES:
        line = f"  {k:16s} {mine['figures'][k]:9.2f}"
        if ref:
            line += f" {ref['figures'][k]:10.2f} {mine['figures'][k] / ref['figures'][k]:6.2f}"
        print(line)
    if ref:
        slow = "slower" if f > 1 else "faster"
        print(f"factor {f:.2f}: the README's timings, measured on the reference machine, would take about "
              f"{f:.2f}x as long here (this machine is {max(f, 1 / f):.2f}x {slow} on the suite's checks)")
        if ref.get("quickstart_wall_s"):
            print(f"  e.g. the Quickstart's compare: {ref['quickstart_wall_s']} s there, about "
                  f"{ref['quickstart_wall_s'] * f:.0f} s here")
    cores = os.cpu_count() or 1
    if mine["load_average_1min"] > max(1.5, cores - 0.5):  # this benchmark itself counts for about 1
        print(f"note: the machine is busy (load average {mine['load_average_1min']} on {cores} cores, this "
              "benchmark included); the fastest-round rule absorbs some of it, a quiet machine gives steadier figures")
    return 0
