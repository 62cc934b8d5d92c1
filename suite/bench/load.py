"""`python -m suite bench load`: does the answer move with the machine's load?

For each budget clock asked (`--budget-clock wall,cpu`), it runs the same `compare` twice, each in a
process of its own: quiet, then beside `--burners` CPU-bound processes (default 2: on a 2-core
machine, as many as the run's workers). It prints each planner's success count in both runs, their
difference, and how many trials each run's records call contended (`suite.run.contention`); the
figures go to OUT/load.json. With a CPU budget the target is a difference of at most 1 per
planner (issue 50); a planner that keeps the wall clock (docs/timing.md) may miss it.

The runs are kept as ordinary run directories (OUT/CLOCK-quiet, OUT/CLOCK-loaded): a complete one
is reused when the command is run again, so an interrupted measurement continues where it stopped.
The quiet run is only as quiet as the machine: its own contention count says whether it was.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

from suite.cli.args import positive_int

#: A burner: one CPU-bound process, nothing else (no imports, no memory).
BURNER = "while True: pass"
#: The largest change of a planner's success count, loaded against quiet, that meets the target.
TARGET_DIFF = 1


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--budget-clock", default="wall,cpu", metavar="wall,cpu",
                   help="the budget clock(s) to measure, comma-separated (default wall,cpu)")
    p.add_argument("--burners", type=positive_int, default=2,
                   help="CPU-bound processes running beside the loaded run (default 2)")
    p.add_argument("--out", default="results/load", help="directory of the runs and load.json (default results/load)")
    p.add_argument("--planners", default=None, help="as compare's (default: compare's)")
    p.add_argument("--dataset", default=None, metavar="NAME[:TIER[:FILTERS]]",
                   help="as compare's (default: compare's, the quick tier), e.g. a few problems for a trial run: "
                        "recycle-v3.1:quick:family=window,kind=transit")
    p.add_argument("--jobs", type=positive_int, default=None, help="as compare's (default: compare's, 2)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")


def clocks(text: str) -> list[str]:
    """"wall,cpu" -> ["wall", "cpu"]: each a budget clock, none twice; one SuiteError line otherwise."""
    from planners.base import BUDGET_CLOCKS
    from scenes.errors import SuiteError

    out = [c.strip() for c in text.split(",") if c.strip()]
    bad = [c for c in out if c not in BUDGET_CLOCKS]
    if bad or not out or len(set(out)) != len(out):
        raise SuiteError(f"--budget-clock {text!r}: allowed: {', '.join(BUDGET_CLOCKS)}, or both separated by a "
                         "comma, each once")
    return out


def compare_command(out: Path, *, clock: str, args: argparse.Namespace) -> list[str]:
    """The `compare` of one run: the flags given here, quiet on the terminal, no plots or report."""
    cmd = [sys.executable, "-m", "suite", "compare", "--budget-clock", clock, "--out", str(out),
           "--no-plots", "--no-html", "--no-progress"]
    for flag, value in (("--planners", args.planners), ("--dataset", args.dataset), ("--jobs", args.jobs)):
        if value is not None:
            cmd += [flag, str(value)]
    return cmd


def _complete(out: Path) -> bool:
    from suite.run.records import read_manifest

    return (out / "trials.jsonl").is_file() and read_manifest(out).get("status") == "complete"


def run_compare(out: Path, *, clock: str, burners: int, args: argparse.Namespace) -> None:
    """One compare into `out` (reused if already complete), beside `burners` CPU-bound processes
    started before it and killed after it."""
    from scenes.errors import SuiteError

    if _complete(out):
        print(f"{out}: complete, reused", file=sys.stderr)
        return
    if out.exists() and (out / "trials.jsonl").exists():
        raise SuiteError(f"{out} holds an unfinished run: resume it (python -m suite compare --resume --out {out}) "
                         "or remove it, then run this again")
    started = [subprocess.Popen([sys.executable, "-c", BURNER]) for _ in range(burners)]
    try:
        print(f"{out}: compare, budget clock {clock}, beside {burners} CPU-bound process(es)", file=sys.stderr)
        done = subprocess.run(compare_command(out, clock=clock, args=args), stdout=subprocess.DEVNULL)
    finally:
        for proc in started:  # only the processes started here, by their handles
            proc.kill()
            proc.wait()
    if done.returncode != 0:
        raise SuiteError(f"compare into {out} failed (exit code {done.returncode}); its error is printed above")


def run_figures(out: Path) -> dict[str, Any]:
    """A finished run's figures: per planner its trials and successes, and the run's contention."""
    from suite.run.contention import run_contention
    from suite.run.records import planners_in, read_trials

    records = read_trials(out)
    planners = planners_in(records)
    contention = run_contention(records)
    return {"run": str(out), "trials": len(records),
            "solved": {p: sum(r.succeeded for r in records if r.planner == p) for p in planners},
            "problems": {p: sum(r.planner == p for r in records) for p in planners},
            "contended": contention["contended"], "measured": contention["measured"],
            "run_contended": contention["run_contended"],
            "cpu_wait_share": contention["cpu_wait_share"], "load1": contention["load1"]}


def compare_runs(quiet: dict[str, Any], loaded: dict[str, Any]) -> list[dict[str, Any]]:
    """Per planner: solved quiet and loaded, their difference, and whether it is within the target."""
    rows = []
    for p in quiet["solved"]:
        q, l_ = quiet["solved"][p], loaded["solved"].get(p)
        diff = None if l_ is None else l_ - q
        rows.append({"planner": p, "problems": quiet["problems"][p], "quiet": q, "loaded": l_, "diff": diff,
                     "within_target": diff is not None and abs(diff) <= TARGET_DIFF})
    return rows


def run(args: argparse.Namespace) -> int:
    wanted = clocks(args.budget_clock)
    base = Path(args.out)
    base.mkdir(parents=True, exist_ok=True)
    result: dict[str, Any] = {"burners": args.burners, "target_diff": TARGET_DIFF, "clocks": {}}
    for clock in wanted:
        runs = {}
        for label, burners in (("quiet", 0), ("loaded", args.burners)):
            out = base / f"{clock}-{label}"
            run_compare(out, clock=clock, burners=burners, args=args)
            runs[label] = run_figures(out)
        result["clocks"][clock] = {**runs, "planners": compare_runs(runs["quiet"], runs["loaded"])}
    (base / "load.json").write_text(json.dumps(result, indent=1) + "\n", encoding="utf-8")
    if args.json:
        print(json.dumps(result, indent=1))
        return 0
    print(f"success counts, quiet and beside {args.burners} CPU-bound process(es) (target: within {TARGET_DIFF} "
          f"with a CPU budget); figures in {base / 'load.json'}")
    for clock, figures in result["clocks"].items():
        q, ld = figures["quiet"], figures["loaded"]
        print(f"\nbudget clock {clock}: contended trials {q['contended']}/{q['measured']} quiet, "
              f"{ld['contended']}/{ld['measured']} loaded (CPU wait {_share(q['cpu_wait_share'])} and "
              f"{_share(ld['cpu_wait_share'])} of planning wall time)")
        if q["run_contended"]:
            print("  the quiet run was contended too: the machine was not quiet (see its summary.md)")
        print(f"  {'planner':16s} {'quiet':>8s} {'loaded':>8s} {'diff':>6s}")
        for row in figures["planners"]:
            mark = "" if row["within_target"] or clock == "wall" else "   <- beyond the target"
            loaded = "-" if row["loaded"] is None else f"{row['loaded']}/{row['problems']}"
            diff = "-" if row["diff"] is None else f"{row['diff']:+d}"
            print(f"  {row['planner']:16s} {row['quiet']:>4d}/{row['problems']:<3d} {loaded:>8s} {diff:>6s}{mark}")
    return 0


def _share(v: float | None) -> str:
    return "n/a" if v is None else f"{100 * v:.1f}%"
