"""Shared figure helpers: pyplot on the Agg backend, planner colours, the plots directory, saving.

Every figure module imports `plt` from here, so the backend is set before pyplot is used.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

log = logging.getLogger(__name__)

PLOTS_DIR = "plots"
DPI = 110

#: Fixed colours of the built-in planners; other planners take the spare ones in order.
BUILTIN_COLORS = {
    "ik": "#1f77b4",
    "rrt": "#ff7f0e",
    "trajopt": "#2ca02c",
    "rrtstar": "#d62728",
    "bitstar": "#9467bd",
    "aorrtc": "#8c564b",
    "prm": "#e377c2",
    "gcs": "#17becf",
    "roboplan-rrt": "#00a087",
}
SPARE_COLORS = ("#bcbd22", "#7f7f7f", "#393b79", "#637939", "#843c39", "#7b4173")


def planner_colors(planners: Sequence[str]) -> dict[str, str]:
    """One colour per planner: the built-ins' fixed colours, then spare colours in order."""
    spare = iter(c for c in SPARE_COLORS)
    out = {}
    for p in planners:
        out[p] = BUILTIN_COLORS.get(p) or next(spare, "#7f7f7f")
    return out


def save_figure(fig, path: Path) -> Path:
    """Write the figure to path at the plots' DPI and close it."""
    fig.savefig(path, dpi=DPI, bbox_inches="tight")
    plt.close(fig)
    log.debug("wrote %s", path)
    return path
