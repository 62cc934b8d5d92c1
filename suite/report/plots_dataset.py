"""The composition of a dataset as a figure: problems per family and kind, and how hard they are."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from suite.report.plots_common import plt, save_figure

KINDS = ("approach", "descend", "lift", "transit", "return")


def plot_dataset(ds, path: Path) -> Path:
    """Three panels: problems per family split by kind (trivial hatched), the difficulty (fraction
    of the straight segment in collision) per family, and reference length / straight distance."""
    families = sorted({m["family"] for m in ds.meta.values()})
    fig, (ax_n, ax_d, ax_r) = plt.subplots(1, 3, figsize=(16, 5.2))
    colors = dict(zip(KINDS, ("#9ecae1", "#6baed6", "#3182bd", "#e6550d", "#fd8d3c")))
    x = np.arange(len(families))
    bottom = np.zeros(len(families))
    for kind in KINDS:
        for trivial in (False, True):
            n = np.array([sum(1 for m in ds.meta.values() if m["family"] == f and m["kind"] == kind
                              and bool(m["trivial"]) == trivial) for f in families], float)
            ax_n.bar(x, n, bottom=bottom, color=colors[kind], edgecolor="white", hatch="//" if trivial else None,
                     label=kind if not trivial else None)
            bottom += n
    ax_n.bar(x, np.zeros(len(families)), color="white", edgecolor="0.4", hatch="//", label="trivial (hatched)")
    ax_n.set_xticks(x, families)
    ax_n.set_ylabel("problems")
    ax_n.set_title(f"{len(ds.meta)} distinct problems by family and kind")
    ax_n.legend(frameon=False, fontsize=8)
    for ax, key, title, ylabel in (
        (ax_d, "difficulty", "Difficulty: straight segment in collision", "fraction of the straight segment"),
        (ax_r, "ratio", "Reference length / straight distance", "ratio (1 = straight line)"),
    ):
        data = []
        for f in families:
            ms = [m for m in ds.meta.values() if m["family"] == f and not m["trivial"]]
            if key == "difficulty":
                data.append([m["difficulty"] for m in ms])
            else:
                data.append([m["reference_length_rad"] / max(m["straight_length_rad"], 1e-9) for m in ms])
        ax.boxplot([d if d else [np.nan] for d in data], showfliers=True)
        ax.set_xticks(np.arange(1, len(families) + 1), [f"{f}\nn={len(d)}" for f, d in zip(families, data)])
        ax.set_title(title + " (non-trivial)")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3, axis="y")
    fig.suptitle(f"Dataset {ds.name} ({ds.tier}, hash {ds.hash})")
    fig.tight_layout()
    return save_figure(fig, path)
