"""The picture of a collision between two samples of the 0.01 rad rule (docs/certification.md)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from suite.report.plots_common import DPI, plt


def plot_between_samples(*, s_rad: np.ndarray, distance_m: np.ndarray, sample_s_rad: np.ndarray,
                         sample_distance_m: np.ndarray, pair: tuple[str, str], title: str, path: Path) -> Path:
    """Distance of one body pair along a stretch of a straight segment, with the fixed-step
    validator's states marked: every marked state is free, the curve between two of them is not.

    Args:
        s_rad: joint motion from the segment's start (max-norm, rad) of the dense curve.
        distance_m: the pair's FCL distance there (negative: penetration depth).
        sample_s_rad, sample_distance_m: the validator's states in the same stretch.
        pair: the two bodies' names.
        title: the figure's title.
        path: the PNG to write.
    """
    fig, ax = plt.subplots(figsize=(7.5, 3.8))
    ax.axhline(0.0, color="black", lw=0.8)
    ax.plot(s_rad, 1e3 * distance_m, color="#1f77b4", lw=1.6, label=f"distance {pair[0]} - {pair[1]} (proved bound; below 0: depth)")
    neg = distance_m < 0
    ax.fill_between(s_rad, 1e3 * distance_m, 0.0, where=neg, color="#d62728", alpha=0.35, label="in collision")
    ax.plot(sample_s_rad, 1e3 * sample_distance_m, "o", color="#ff7f0e", ms=7, zorder=3,
            label="states the 0.01 rad rule checks (all free)")
    ax.set_xlabel("joint motion along the segment (max over joints, rad)")
    ax.set_ylabel("distance (mm)")
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8, loc="upper center")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path
