"""Executions planned in a perceived world against the true world: paired per scene, and what
the perceived worlds cost and caused."""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence

import numpy as np

from suite.execution.execution_records import ExecutionRecord


def _rate(record: ExecutionRecord) -> float:
    """Cans in the bin per can on the plate (an execution that ended in an error delivered none)."""
    if record.error is not None or not record.cans_total:
        return 0.0
    return record.cans_in_bin / record.cans_total


def paired_lines(base: Sequence[ExecutionRecord], other: Sequence[ExecutionRecord], *,
                 planners: Sequence[str]) -> list[str]:
    """Per planner, over the scenes both ran: cans in the bin (base, other), their paired
    difference other - base in points with a 95% bootstrap interval over scenes, contacts, and
    the other's perception-induced failures."""
    from suite.report.summary_moving_bin_paired import bootstrap_mean_ci

    lines = []
    for p in planners:
        a = {(r.variant, r.scene_seed): r for r in base if r.planner == p}
        b = {(r.variant, r.scene_seed): r for r in other if r.planner == p}
        keys = sorted(set(a) & set(b))
        if not keys:
            continue
        d = np.array([_rate(b[k]) - _rate(a[k]) for k in keys])
        ci = bootstrap_mean_ci(d) if len(d) > 1 else (float("nan"), float("nan"))
        cans_a = sum(a[k].cans_in_bin for k in keys if a[k].error is None)
        cans_b = sum(b[k].cans_in_bin for k in keys if b[k].error is None)
        total = sum(a[k].cans_total for k in keys)
        contacts = (sum(a[k].collisions for k in keys), sum(b[k].collisions for k in keys))
        induced = sum(len(b[k].perception_induced or []) for k in keys)
        lines.append(f"  {p}: {len(keys)} scenes, cans in the bin {cans_a}/{total} -> {cans_b}/{total}; "
                     f"paired difference {100 * d.mean():+.1f} points [{100 * ci[0]:+.1f}, {100 * ci[1]:+.1f}], "
                     f"scenes worse {int((d < 0).sum())}, better {int((d > 0).sum())}; "
                     f"contacts {contacts[0]} -> {contacts[1]}; perception-induced failures {induced}")
    return lines


def perceived_world_lines(records: Sequence[ExecutionRecord], *, planners: Sequence[str]) -> list[str]:
    """What the perceived worlds were (voxel boxes, build time against the planning time they
    fed) and the perception-induced failures by cause."""
    worlds = [w for r in records for w in (r.perceived_worlds or [])]
    lines = []
    if worlds:
        build = [w["build_time_s"] for w in worlds]
        boxes = [w["boxes"] for w in worlds]
        plan = [r.planning_time_s for r in records if r.planning_time_s]
        lines.append(f"  perceived worlds: {len(worlds)}, voxel {worlds[0]['voxel_m'] * 1e3:g} mm, cans padded "
                     f"{worlds[0]['can_padding_m'] * 1e3:g} mm, boxes median {np.median(boxes):.0f} (max {max(boxes)}); "
                     f"build median {np.median(build):.2f} s each, {sum(build):.0f} s in all against "
                     f"{sum(plan):.0f} s of planning ({100 * sum(build) / max(sum(plan), 1e-9):.1f}%)")
    for p in planners:
        causes = Counter(f["cause"] for r in records if r.planner == p for f in (r.perception_induced or []))
        if causes:
            lines.append(f"  {p}: perception-induced failures " + ", ".join(f"{c} {n}" for c, n in causes.most_common()))
    return lines
