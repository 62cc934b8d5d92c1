"""`python -m suite bench machine`: how fast this machine runs the suite's own checks, against the
machine the README's timings were measured on.

A planning time is a figure of the planner and of the machine. The README's timings carry the
machine they came from (`results/reference/machine.json`: its CPU, cores and this benchmark's
figures, measured on it beside the reference run). Run this on your machine: the ratio of your
figures to those says how much slower or faster the README's timings would be here.

The workload is pinned in code (`WORKLOAD`, independent of the default dataset, so that a new
dataset cannot change what is timed): six worlds of `recycle-v3` (the first problem of each family
in its quick tier, by problem_id, the dataset by its hash), their stored reference paths (204
segments, each path pinned by a hash), 1000 seeded configurations per world and `rrt`'s motion
resolution. Its digest is saved with the figures, and a reference measured on another workload is
refused: ratios of two workloads are no factor (recycle-v3.1's 17 long segments against
recycle-v3's 204 short ones once printed 2.97 where the Quickstart took 1.33x). On one thread:

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
import dataclasses
import hashlib
import json
import logging
import math
import os
import time
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import Field

from scenes.errors import SuiteError
from scenes.schema import load
from suite.cli.args import positive_float, positive_int

#: Where the reference machine's figures are kept (measured beside the reference run).
REFERENCE_FILE = Path(__file__).resolve().parents[2] / "results" / "reference" / "machine.json"
FIGURES = ("fcl_state_us", "fcl_motion_us", "kernel_motion_us", "drake_state_us")


@dataclasses.dataclass(frozen=True)
class World:
    """One world of the workload: a stored problem, timed on its reference path.

    Attributes:
        family: the problem's family.
        problem_id: the stored problem (its world, held can and configurations, by content).
        segments: the reference path's segments (its points less one): the motion checks.
        reference_sha: the first 16 hex digits of the sha256 of the reference path, as
            little-endian float64 (N, 7): the segments themselves.
    """

    family: str
    problem_id: Annotated[str, Field(pattern=r"^[0-9a-f]{20}$")]
    segments: Annotated[int, Field(ge=1)]
    reference_sha: Annotated[str, Field(pattern=r"^[0-9a-f]{16}$")]


@dataclasses.dataclass(frozen=True)
class Workload:
    """What `bench machine` times: two sets of figures compare only on the same workload (same digest).

    Attributes:
        dataset: the shipped dataset the worlds come from (by name) ...
        dataset_hash: ... and its hash (its manifest's), so an edited dataset is refused.
        worlds: the worlds, in timing order.
        configs_per_world: seeded configurations per world, for the state checks.
        config_seed: the configurations' generator seed.
        motion_resolution_rad: the motion checks' resolution (rad, per joint): `rrt`'s.
    """

    dataset: str
    dataset_hash: Annotated[str, Field(pattern=r"^[0-9a-f]{20}$")]
    worlds: tuple[World, ...]
    configs_per_world: Annotated[int, Field(ge=1)]
    config_seed: int
    motion_resolution_rad: Annotated[float, Field(gt=0)]

    @property
    def segments(self) -> int:
        return sum(w.segments for w in self.worlds)

    def digest(self) -> str:
        """16 hex digits of the sha256 of the fields as canonical JSON: equal digests, same workload."""
        text = json.dumps(dataclasses.asdict(self), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def to_json(self) -> dict[str, Any]:
        """The fields, the segment count and the digest (what a figures file records)."""
        return {**dataclasses.asdict(self), "segments": self.segments, "digest": self.digest()}

    def label(self) -> str:
        """One line: dataset, counts and digest."""
        return (f"{self.dataset} ({self.dataset_hash}), {len(self.worlds)} worlds, {self.segments} segments, "
                f"{self.configs_per_world} configurations a world (seed {self.config_seed}), "
                f"{self.motion_resolution_rad:g} rad, digest {self.digest()}")


#: The pinned workload: the first problem of each family in recycle-v3's quick tier (the worlds
#: the reference was first measured on). recycle-v3's references are dense (two of 100 points), so
#: the motion figures are medians over 204 segments of every length; recycle-v3.1's shortened
#: references would give 17. Changing anything here changes the digest: re-measure the reference.
WORKLOAD = Workload(
    dataset="recycle-v3",
    dataset_hash="9434c72dfb14354ad61a",
    worlds=(
        World("open", "87f256ba576a502f6031", 99, "fd594270580b39aa"),
        World("wall", "92eb7f826b6b3127935e", 99, "5604a3c7415e0207"),
        World("station", "024cead6df5413e6dee4", 1, "799d9806cf33e43b"),
        World("shelf", "a9b8cab7e925c1921693", 2, "2c6f8cf657adbe7a"),
        World("window", "41205e71251b9a8267b3", 1, "bcfb65fc17e65717"),
        World("clutter", "3b3abc3798aa45a66ea9", 2, "914a285863cd41cc"),
    ),
    configs_per_world=1000,
    config_seed=20261126,
    motion_resolution_rad=0.05,  # rrt's planning resolution
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--configs", type=positive_int, default=WORKLOAD.configs_per_world,
                   help=f"seeded configurations per world (default {WORKLOAD.configs_per_world}; another count is "
                        "another workload, which the reference file's figures do not compare with)")
    p.add_argument("--rounds", type=positive_int, default=5,
                   help="timing rounds; an item's time is its fastest round (default 5)")
    p.add_argument("--against", default=str(REFERENCE_FILE),
                   help="the reference machine's figures (default: the README's, results/reference/machine.json; "
                        "'' for none)")
    p.add_argument("--save", metavar="JSON", default=None,
                   help="also write this machine's figures and their workload to JSON (how the reference file is made)")
    p.add_argument("--quickstart-wall-s", type=positive_float, default=None, metavar="S",
                   help="the Quickstart compare's wall time measured on this machine (s): recorded with --save, "
                        "and set beside the reference's prediction for this machine")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")


def reference_sha(path: np.ndarray) -> str:
    """The `World.reference_sha` of a reference path."""
    return hashlib.sha256(np.ascontiguousarray(path, dtype="<f8").tobytes()).hexdigest()[:16]


def _worlds(workload: Workload) -> list:
    """The workload's (world, problem, reference path), each checked against its pin.

    Raises:
        SuiteError: the dataset's hash, a problem or a reference path is not the pinned one.
    """
    from suite.problems.dataset import load_dataset

    ds = load_dataset(workload.dataset)
    if ds.hash != workload.dataset_hash:
        raise SuiteError(f"dataset {workload.dataset!r} has hash {ds.hash}, the pinned workload's is "
                         f"{workload.dataset_hash}: the dataset changed under bench machine; restore it or re-pin "
                         "WORKLOAD (suite/bench/machine.py) and re-measure the reference")
    index = {pid: problem for pid, problem in zip(ds.ids, ds.problems)}
    out = []
    for w in workload.worlds:
        if w.problem_id not in index:
            raise SuiteError(f"dataset {workload.dataset!r} holds no problem {w.problem_id} (bench machine's "
                             f"{w.family} world)")
        ref = ds.references[w.problem_id]
        if len(ref) - 1 != w.segments or reference_sha(ref) != w.reference_sha:
            raise SuiteError(f"dataset {workload.dataset!r}: problem {w.problem_id}'s reference path is not the "
                             f"pinned one ({len(ref) - 1} segments, sha {reference_sha(ref)}; pinned {w.segments}, "
                             f"{w.reference_sha})")
        out.append((w, index[w.problem_id], ref))
    return out


def measure(*, rounds: int, workload: Workload = WORKLOAD) -> dict[str, Any]:
    """This machine's figures on `workload` (see the module docstring), with the workload and its digest."""
    worlds = _worlds(workload)  # the pins are checked before any timing
    import pydrake.common  # noqa: F401  (it sets the "drake" logger's level on import: quiet it after)

    from planners.worlds import collision_world
    from scenes.collision.compiled import CompiledWorld
    from suite.bench.collision import drake_checker

    logging.getLogger("drake").setLevel(logging.WARNING)  # not Drake's line per checker about its contexts
    perf = time.perf_counter
    res = workload.motion_resolution_rad
    state_fcl, state_drake, motion, kernel = [], [], [], []
    for _, problem, reference in worlds:
        world = collision_world(problem)
        compiled = CompiledWorld(problem.scene, gripper_opening_m=problem.gripper_opening_m, held=problem.held,
                                 removed_can_ids=problem.removed_can_ids)
        checker = drake_checker(problem.scene, held=problem.held, gripper_opening_m=problem.gripper_opening_m)
        Q = world.robot.random_configurations(np.random.default_rng(workload.config_seed), workload.configs_per_world)
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
                world.motion_samples_free(a, b, resolution_rad=res)
                t1 = perf()
                compiled.motion_samples_free(a, b, resolution_rad=res)
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
        "workload": workload.to_json(),
        "rounds": rounds,
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


def _shown(path: str | Path) -> str:
    """`path` relative to the current directory when it is under it (the default reference file)."""
    try:
        return str(Path(path).resolve().relative_to(Path.cwd().resolve()))
    except (ValueError, OSError):
        return str(path)


def remeasure_command(path: str | Path) -> str:
    """The command that re-measures a reference file on the pinned workload (quiet machine)."""
    return (f"python -m suite bench machine --against '' --save {_shown(path)} --quickstart-wall-s S "
            "(S: the Quickstart compare's wall time, measured just before on the same machine)")


def check_workload(ref: dict[str, Any], workload: Workload, *, path: str | Path) -> None:
    """Refuse (one SuiteError line naming both workloads) a reference measured on another workload.

    Raises:
        SuiteError: the reference records no workload digest (a file written before workloads were
            pinned), one its fields do not hash to, or another workload than `workload`.
    """
    where = f"--against {_shown(path)!r}"
    mine = workload.label()
    data = ref.get("workload")
    if not isinstance(data, dict) or "digest" not in data:
        old = data if isinstance(data, dict) else {}
        theirs = (f"{old.get('dataset', '?')}, {old.get('segments', '?')} segments, "
                  f"{old.get('configs_per_world', '?')} configurations a world, no digest" if old else "none recorded")
        raise SuiteError(f"{where} was measured on an unpinned workload ({theirs}), not this one ({mine}): its "
                         f"ratios would be no factor; re-measure it on a quiet machine: {remeasure_command(path)}")
    theirs_w = load(Workload, data, where=f"{where}: workload ", ignore_unknown=True)
    if theirs_w.digest() != data["digest"]:
        raise SuiteError(f"{where}: its workload's fields hash to {theirs_w.digest()}, not its recorded digest "
                         f"{data['digest']!r} (edited?); re-measure it: {remeasure_command(path)}")
    if theirs_w != workload:
        hint = (f"run with --configs {theirs_w.configs_per_world}, or "
                if dataclasses.replace(workload, configs_per_world=theirs_w.configs_per_world) == theirs_w else "")
        raise SuiteError(f"{where} was measured on another workload ({theirs_w.label()}), not this one ({mine}): "
                         f"its ratios would be no factor; {hint}re-measure it on a quiet machine: "
                         f"{remeasure_command(path)}")


def factor(mine: dict[str, float], reference: dict[str, float]) -> float:
    """The geometric mean of mine / reference over FIGURES (above 1: this machine is slower)."""
    return math.exp(sum(math.log(mine[k] / reference[k]) for k in FIGURES) / len(FIGURES))


def quickstart_check(ref: dict[str, Any], f: float, wall_s: float | None) -> dict[str, float] | None:
    """The factor's prediction of the Quickstart's wall time here against one measured here, or None
    without both: {"reference_s", "predicted_s", "measured_s", "predicted_over_measured"}."""
    there = ref.get("quickstart_wall_s")
    if wall_s is None or not isinstance(there, (int, float)) or not there > 0:
        return None
    predicted = there * f
    return {"reference_s": there, "predicted_s": round(predicted, 1), "measured_s": wall_s,
            "predicted_over_measured": round(predicted / wall_s, 3)}


def run(args: argparse.Namespace) -> int:
    workload = dataclasses.replace(WORKLOAD, configs_per_world=args.configs)
    ref = read_reference(args.against) if args.against else None  # a bad file fails before any work
    if ref is not None:
        check_workload(ref, workload, path=args.against)
    mine = measure(rounds=args.rounds, workload=workload)
    if args.quickstart_wall_s is not None:
        mine["quickstart_wall_s"] = args.quickstart_wall_s
    if args.save:
        Path(args.save).write_text(json.dumps(mine, indent=1) + "\n")
    f = factor(mine["figures"], ref["figures"]) if ref else None
    check = quickstart_check(ref, f, args.quickstart_wall_s) if ref else None
    if args.json:
        print(json.dumps({**mine, "reference": ref, "factor": f, "quickstart_check": check}))
        return 0
    w = mine["workload"]
    print(f"machine benchmark: {w['configs_per_world']} configurations and {w['segments']} reference-path segments "
          f"in {len(w['worlds'])} worlds of {w['dataset']} ({', '.join(x['family'] for x in w['worlds'])}), "
          f"workload {w['digest']}; each item's fastest of {mine['rounds']} round(s), medians; one thread")
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
        if check:
            print(f"  measured here (--quickstart-wall-s): {check['measured_s']} s; the prediction is "
                  f"{check['predicted_over_measured']:.2f}x the measured time")
    cores = os.cpu_count() or 1
    if mine["load_average_1min"] > max(1.5, cores - 0.5):  # this benchmark itself counts for about 1
        print(f"note: the machine is busy (load average {mine['load_average_1min']} on {cores} cores, this "
              "benchmark included); the fastest-round rule absorbs some of it, a quiet machine gives steadier figures")
    return 0
