"""Where planning time goes: collision queries against the rest, per planner and family."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from suite.report.outcomes import family_of, is_cold
from suite.report.plots_common import planner_colors, plt, save_figure
from suite.run.records import SUCCESS, TrialRecord

#: How each engine's share is drawn: its hatch, and the legend words (the timing kind decides
#: how far the share is to be trusted: clocked around each call, replayed from a sample of the
#: solver's own iterates, or a lower bound).
ENGINE_STYLE = {
    "python-fcl": ("", "python-fcl queries (clocked)"),
    "drake": ("////", "Drake distance queries (replayed)"),
    "roboplan": ("xx", "roboplan checks (lower bound)"),
}


def plot_time_attribution(records: Sequence[TrialRecord], *, planners: Sequence[str], path: Path) -> Path | None:
    """Stacked bars per planner in each family: the shares of planning time spent in each
    engine's collision queries (python-fcl, Drake, roboplan: one hatch each) and in the rest
    (medians over warm successful trials that carry `attribution`, scaled so the parts add up to
    the median query share), the median planning time written above; a planner that does not
    count its queries gets a hatched bar marked "not counted". None if no record carries an
    attribution."""
    if not any(r.attribution for r in records):
        return None
    warm = [r for r in records if r.status == SUCCESS and not is_cold(r)]
    families = sorted({family_of(r) for r in warm})
    if not families:
        return None
    fig, ax = plt.subplots(figsize=(max(7.0, 0.9 * len(families) * max(1, len(planners))), 4.4))
    width = 0.8 / max(1, len(planners))
    x = np.arange(len(families))
    colors = planner_colors(planners)
    engines_seen: list[str] = []
    for k, planner in enumerate(planners):
        color = colors[planner]
        pos = x + (k - (len(planners) - 1) / 2) * width
        for i, fam in enumerate(families):
            mine = [r for r in warm if r.planner == planner and family_of(r) == fam]
            if not mine:
                continue
            att = [r.attribution for r in mine if r.attribution]
            t = float(np.median([r.planning_time_s for r in mine]))
            if att:
                share = float(np.median([a["query_share"] for a in att]))
                parts = _engine_shares(att, share)
                bottom = 0.0
                for engine, s in parts.items():
                    hatch = ENGINE_STYLE.get(engine, ("..", engine))[0]
                    ax.bar(pos[i], s, width, bottom=bottom, color=color, hatch=hatch, edgecolor="white", linewidth=0)
                    bottom += s
                    if engine not in engines_seen:
                        engines_seen.append(engine)
                ax.bar(pos[i], 1 - share, width, bottom=share, color=color, alpha=0.3)
            else:
                ax.bar(pos[i], 1, width, color="white", edgecolor=color, hatch="//")
            ax.text(pos[i], 1.01, f"{t:.2g} s", ha="center", va="bottom", fontsize=7, rotation=90)
    from matplotlib.patches import Patch

    handles = [Patch(color=colors[p], label=p) for p in planners]
    checkers = sorted({str(r.checker) for r in warm if r.checker})  # what python-fcl's decisions ran in
    labels = {e: ENGINE_STYLE.get(e, ("..", e))[1] for e in engines_seen}
    if "python-fcl" in labels and checkers:
        labels["python-fcl"] = f"python-fcl queries, {' and '.join(checkers)} (clocked)"
    handles += [Patch(facecolor="grey", hatch=ENGINE_STYLE.get(e, ("..", e))[0], edgecolor="white",
                      label=labels[e]) for e in engines_seen]
    handles.append(Patch(facecolor="grey", alpha=0.3, label="the rest (planner code, Python, solver)"))
    ax.set_xticks(x)
    ax.set_xticklabels(families)
    ax.set_ylim(0, 1.25)
    ax.set_ylabel("share of planning time (median)")
    ax.set_title("Where planning time goes (warm successful trials; median planning time above each bar)", fontsize=10)
    ax.legend(handles=handles, fontsize=7, ncol=4, loc="upper center", bbox_to_anchor=(0.5, -0.1))
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    return save_figure(fig, path)


def _engine_shares(attributions: Sequence[dict], share: float) -> dict[str, float]:
    """The median query share split between engines in proportion to each engine's median
    seconds (engines in a fixed order: python-fcl, Drake, roboplan, any other)."""
    names = sorted({e for a in attributions for e in (a.get("parts") or {})},
                   key=lambda e: (list(ENGINE_STYLE).index(e) if e in ENGINE_STYLE else len(ENGINE_STYLE), e))
    if not names:
        return {"queries": share}
    med = {e: float(np.median([(a.get("parts") or {}).get(e, {}).get("query_s", 0.0) for a in attributions]))
           for e in names}
    total = sum(med.values())
    if total <= 0:
        return {names[0]: share}
    return {e: share * v / total for e, v in med.items()}
