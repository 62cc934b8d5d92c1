"""A perceived world beside the truth it was built from: top and side views of the plate."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from suite.report.plots_common import plt, save_figure
from suite.report.scene_outlines import SIDE, TOP, primitive_outline
from suite.report.scene_outlines import _translation as _at


def perceived_world_figure(truth, world, out: str | Path, *, title: str = "") -> Path:
    """Two panels (from above; from the front, +x): the truth's loose objects (grey) and cans
    (red outlines), the perceived world's voxel boxes (blue, translucent) and perceived cans (black
    dashed, padded) over the plate."""
    from perception.world import LOOSE_PREFIXES, VOXEL_PREFIX

    spec = truth.spec
    spec.require("plate", "can", needed_by="the perceived world's figure")
    fig, axes = plt.subplots(1, 2, figsize=(13, 5.2), gridspec_kw={"width_ratios": [1.15, 1]})
    for ax, dims, name in ((axes[0], TOP, "from above (x, y)"), (axes[1], SIDE, "from the front (y, z)")):
        ax.add_patch(plt.Polygon(primitive_outline("box", spec.plate.size_m, _at(spec.plate.center_m), dims=dims),
                                 fc="0.92", ec="0.6", lw=1, label="plate"))
        for o in spec.extra:
            if o.name.startswith(LOOSE_PREFIXES):
                ax.add_patch(plt.Polygon(primitive_outline(o.shape, o.size_m, o.pose(), dims=dims), fc="0.55",
                                         ec="0.3", lw=1, alpha=0.9, label="object (truth)"))
        for b in world.scene.spec.extra:
            if b.name.startswith(VOXEL_PREFIX):
                ax.add_patch(plt.Polygon(primitive_outline(b.shape, b.size_m, b.pose(), dims=dims), fc="tab:blue",
                                         ec="tab:blue", lw=0.4, alpha=0.25, label="seen: voxel boxes"))
        for c in truth.cans:
            ax.add_patch(plt.Polygon(primitive_outline("cylinder", (spec.can.radius_m, spec.can.height_m), c.X_WC(),
                                                       dims=dims), fc="none", ec="tab:red", lw=1.6, label="can (truth)"))
        ws = world.scene.spec
        for c in world.scene.cans:
            ax.add_patch(plt.Polygon(primitive_outline("cylinder", (ws.can.radius_m, ws.can.height_m), c.X_WC(),
                                                       dims=dims), fc="none", ec="k", lw=1.1, ls="--",
                                     label="can (perceived, padded)"))
        ax.set_title(name)
        ax.set_aspect("equal")
        ax.autoscale_view()
        ax.set_xlabel(f"{'xyz'[dims[0]]} (m)")
        ax.set_ylabel(f"{'xyz'[dims[1]]} (m)")
    lo = np.asarray(spec.plate.center_m[:2]) - np.asarray(spec.plate.size_m[:2]) / 2 - 0.03
    hi = np.asarray(spec.plate.center_m[:2]) + np.asarray(spec.plate.size_m[:2]) / 2 + 0.03
    axes[0].set_xlim(lo[0], hi[0])
    axes[0].set_ylim(lo[1], hi[1])
    axes[1].set_xlim(lo[1], hi[1])
    axes[1].set_ylim(spec.plate_top_z_m - 0.02, spec.plate_top_z_m + world.params.height_m)
    handles, labels = axes[0].get_legend_handles_labels()
    keep = dict(zip(labels, handles))
    fig.legend(keep.values(), keep.keys(), loc="lower center", ncol=len(keep), frameon=False)
    s = world.summary()
    fig.suptitle(title or f"The world the planners see: {s['boxes']} voxel boxes ({1e3 * s['voxel_m']:g} mm voxels), "
                          f"{s['cans']} cans padded {1e3 * s['can_padding_m']:g} mm, cameras {', '.join(s['cameras'])}")
    fig.tight_layout(rect=(0, 0.07, 1, 0.95))
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    return save_figure(fig, out)

