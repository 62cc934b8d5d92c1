"""`python -m suite regions report`: what a built region setting is, per family, from the cached sets
alone (nothing is grown): regions per world, IRIS iterations per region and why they stopped, the
inscribed ellipsoid (as the radius of the 7-ball of its volume), the problems whose ends the regions
link (after `gcs`'s online straight joins, no online region), and the offline seconds per world
(the build's CPU time where recorded: the wall time on a core of its own; and its wall time).

Sets built before a region recorded its IRIS run count one iteration per region when their options
say `max_iterations: 1` (IRIS cannot run more), and "unrecorded" otherwise; their inscribed
ellipsoids are computed here from the stored faces.
"""

from __future__ import annotations

import statistics
from typing import Any

import numpy as np


def _world_rows(problems, metas, options) -> tuple[list[dict], list[str]]:
    """One row per built world (its figures) and the world hashes with no cached set."""
    from planners.gcs.iris import inscribed_volume
    from planners.gcs.sets import RegionSet, find_cached, world_hash
    from planners.gcs.solve import connect_ends
    from planners.worlds import collision_world

    worlds: dict[str, list] = {}
    for p, meta in zip(problems, metas):
        if p.pre_status is None and p.q_goal is not None:
            worlds.setdefault(world_hash(p, options), []).append((p, meta))
    rows, missing = [], []
    for whash, members in worlds.items():
        path = find_cached(whash, None)
        if path is None:
            missing.append(whash)
            continue
        rs = RegionSet.load(path)
        if rs.region_iris:
            iris = rs.region_iris
        else:
            one = options.max_iterations == 1
            iris = [{"iterations": 1 if one else None, "stop": ["iteration_limit" if one else "unrecorded"],
                     **inscribed_volume(A, b)} for A, b in zip(rs.A, rs.b)]
        linked = 0
        for p, _ in members:
            c = connect_ends(rs.A, rs.b, rs.edges, np.asarray(p.q_start, float), np.asarray(p.q_goal, float),
                             world=collision_world(p))
            linked += bool(c["connected"])
        rows.append({"world_hash": whash, "family": str(members[0][1]["family"]), "problems": len(members),
                     "linked": linked, "regions": len(rs), "iris": iris, "offline_s": rs.offline_s,
                     "offline_cpu_s": rs.offline_cpu_s})
    return rows, missing


def _p90(values: list[float]) -> float | None:
    from suite.report.tuning import p90

    return p90(values) if values else None


def iris_summary(regions: list[dict]) -> dict[str, Any]:
    """What IRIS did over `regions` (`RegionSet.region_iris` records): iterations per region
    (median, max, histogram; unrecorded ones left out), why they stopped (counts: a region
    stopped for several reasons at once counts for each) and the inscribed radius (rad: median,
    p10)."""
    its = [int(x["iterations"]) for x in regions if x.get("iterations") is not None]
    radii = [x["radius_rad"] for x in regions if x.get("radius_rad") is not None]
    stops: dict[str, int] = {}
    for x in regions:
        for reason in x["stop"]:
            stops[reason] = stops.get(reason, 0) + 1
    return {
        "regions_recorded": len(regions),
        "iterations_median": statistics.median(its) if its else None, "iterations_max": max(its) if its else None,
        "iterations_histogram": {str(k): its.count(k) for k in sorted(set(its))},
        "stop": dict(sorted(stops.items())),
        "radius_rad_median": statistics.median(radii) if radii else None,
        "radius_rad_p10": float(np.percentile(radii, 10)) if radii else None,
    }


def family_table(rows: list[dict]) -> list[dict[str, Any]]:
    """Per family (and "all"): worlds, regions per world (median), iterations per region (median,
    max), the stops, the inscribed radius (median, rad), problems linked, offline seconds (CPU and
    wall: median, p90)."""
    out = []
    for family in [*sorted({r["family"] for r in rows}), "all"]:
        mine = [r for r in rows if family in ("all", r["family"])]
        iris = iris_summary([x for r in mine for x in r["iris"]])
        cpu = [r["offline_cpu_s"] for r in mine if r["offline_cpu_s"] is not None]
        wall = [r["offline_s"] for r in mine]
        out.append({
            "family": family, "worlds": len(mine),
            "regions_per_world": statistics.median(r["regions"] for r in mine) if mine else None,
            "iterations_median": iris["iterations_median"], "iterations_max": iris["iterations_max"],
            "stops": iris["stop"],
            "radius_rad_median": iris["radius_rad_median"],
            "linked": sum(r["linked"] for r in mine), "problems": sum(r["problems"] for r in mine),
            "offline_cpu_s_median": statistics.median(cpu) if cpu else None, "offline_cpu_s_p90": _p90(cpu),
            "offline_wall_s_median": statistics.median(wall) if wall else None, "offline_wall_s_p90": _p90(wall),
            "worlds_with_cpu": len(cpu),
        })
    return out


def report(dataset: str, *, tune_sample: int | None, options) -> dict[str, Any]:
    """The table of the cached sets of `options` for a dataset tier, or for `tune --per-family N`'s sample."""
    from suite.problems.dataset import load_dataset, tuning_problems

    if tune_sample is not None:
        _, sample = tuning_problems(dataset, per_family=tune_sample, time_limit_s=5.0)
        problems, metas = [p for p, _ in sample], [m for _, m in sample]
    else:
        ds = load_dataset(dataset)
        problems, metas = ds.problems, [ds.meta[i] for i in ds.ids]
    rows, missing = _world_rows(problems, metas, options)
    return {"dataset": dataset, "tune_sample": tune_sample, "options": options.key_fields(),
            "families": family_table(rows), "missing_worlds": missing, "worlds": rows}


def markdown(rep: dict[str, Any]) -> str:
    """The per-family table as markdown."""
    def f(v, fmt="{:.1f}"):
        return "-" if v is None else fmt.format(v)

    lines = ["| family | worlds | regions per world | IRIS iterations per region, median [max] | stops | "
             "inscribed radius (rad), median | linked | offline CPU s, median [p90] | offline wall s, median [p90] |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rep["families"]:
        stops = ", ".join(f"{k} {v}" for k, v in r["stops"].items())
        lines.append(
            f"| {r['family']} | {r['worlds']} | {f(r['regions_per_world'], '{:g}')} | "
            f"{f(r['iterations_median'], '{:g}')} [{f(r['iterations_max'], '{:g}')}] | {stops} | "
            f"{f(r['radius_rad_median'], '{:.2f}')} | {r['linked']}/{r['problems']} | "
            f"{f(r['offline_cpu_s_median'])} [{f(r['offline_cpu_s_p90'])}] | "
            f"{f(r['offline_wall_s_median'])} [{f(r['offline_wall_s_p90'])}] |")
    if rep["missing_worlds"]:
        lines.append(f"\n{len(rep['missing_worlds'])} world(s) have no cached set at these options (not built).")
    return "\n".join(lines)
