"""Search and simplification apart, as OMPL's Benchmark reports them.

OMPL's Benchmark records a planner's solve time and its simplification time and the path's length
before and after simplification as separate figures; MoveIt simplifies every solution by default.
The suite's OMPL planners record the same four figures in their trial stats (`solve_time_s`,
`simplify_time_s`, `length_before_rad`, `length_after_rad`); this module reports their medians per
planner, over warm successful trials, and names each planner's post-processing from its config.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from suite.run.records import TrialRecord

#: The stats an OMPL trial carries, in the order the table shows them.
SEARCH_FIELDS = ("solve_time_s", "simplify_time_s", "length_before_rad", "length_after_rad")


def post_processing(config: dict[str, Any] | None) -> str:
    """What a planner does to its first solution, read from its config (as recorded in a trial):
    OMPL's simplifiers (`simplifier`, `simplify_time_s`), roboplan's shortcutter (`shortcut`,
    `shortcut_max_iters`), or "none" for a planner with neither (its path is its answer)."""
    config = config or {}
    simplify_s = config.get("simplify_time_s")
    if "simplifier" in config:
        if not simplify_s:
            return "none"
        return {"rope": "rope shortcut (OMPL ropeShortcutPath)",
                "full": f"OMPL PathSimplifier.simplify ({simplify_s:g} s)",
                "rope+full": f"rope shortcut, then OMPL PathSimplifier.simplify ({simplify_s:g} s)",
                }.get(str(config["simplifier"]), str(config["simplifier"]))
    if "shortcut" in config:
        if not config["shortcut"]:
            return "none"
        return f"roboplan PathShortcutter ({config.get('shortcut_max_iters', '?')} random shortcuts)"
    if simplify_s:
        return f"OMPL PathSimplifier.simplify ({simplify_s:g} s)"
    return "none"


def search_summary(records: Sequence[TrialRecord], planner: str) -> dict[str, Any] | None:
    """Medians over a planner's warm successful trials that carry the four OMPL figures; None if
    none does (not an OMPL planner). `length_kept` is the median of after/before per trial."""
    from suite.report.outcomes import is_cold

    mine = [r for r in records if r.planner == planner and r.status == "success" and not is_cold(r)
            and all(isinstance((r.stats or {}).get(f), (int, float)) for f in SEARCH_FIELDS)]
    if not mine:
        return None
    out: dict[str, Any] = {"trials": len(mine), "post_processing": post_processing(mine[0].planner_config)}
    for f in SEARCH_FIELDS:
        out[f] = float(np.median([float(r.stats[f]) for r in mine]))
    kept = [r.stats["length_after_rad"] / r.stats["length_before_rad"] for r in mine
            if r.stats["length_before_rad"] > 0]
    out["length_kept"] = float(np.median(kept)) if kept else math.nan
    return out


def search_rows(records: Sequence[TrialRecord], planners: Sequence[str]) -> tuple[list[str], list[list[Any]]]:
    """The summary's table: one row per planner that records the OMPL figures."""
    from suite.report.summary_tables import format_number

    headers = ["planner", "post-processing", "successes (warm)", "solve time (s)", "simplify time (s)",
               "length before (rad)", "length after (rad)", "after / before"]
    rows = []
    for p in planners:
        s = search_summary(records, p)
        if s is None:
            continue
        rows.append([p, s["post_processing"], s["trials"], *(format_number(s[f]) for f in SEARCH_FIELDS),
                     format_number(s["length_kept"])])
    return headers, rows


SEARCH_INTRO = (
    "The OMPL planners' search and simplification apart, as OMPL's Benchmark reports them: the solve time "
    "(search alone), the simplification time, and the path's length in joint space before and after "
    "simplification. Medians over warm successful trials (the planning time of the other tables is their sum "
    "plus set-up around them). The post-processing is each planner's as configured.")
