"""The perception noise sweep's figure, drawn from the sweep's evaluation files alone."""

from __future__ import annotations

import json
from pathlib import Path

from suite.report.plots_common import plt

_STYLE = {"paper": ("tab:red", "paper's pipeline"), "robust": ("tab:blue", "robust pipeline")}
_MARK = {"gaussian": ("o", "-", "Gaussian"), "structured-light": ("s", "--", "structured light (Kinect v1 model)")}


def _kind(doc: dict) -> str:
    model = doc.get("sensor_model")
    return "structured-light" if model and model.get("kind") == "structured-light" else "gaussian"


def noise_sweep_figure(sweep_dir: str | Path, out: str | Path) -> Path:
    """Recall, precision, xy error p95 and lying-can yaw error p95 against the depth noise at the
    plate, for each pipeline and sensor model, from `perceive --sweep`'s JSON files in `sweep_dir`."""
    docs = [json.loads(p.read_text(encoding="utf-8")) for p in sorted(Path(sweep_dir).glob("*.json"))]
    panels = [("recall", "recall", 1.0, (0.95, 1.0)), ("precision", "precision", 1.0, (0.99, 1.0)),
              ("xy_error_p95_mm", "centre xy error p95 (mm)", 1.0, (5.0, None)),
              ("yaw_error_p95_deg", "lying-can axis error p95 (°)", 1.0, (3.0, None))]
    fig, axes = plt.subplots(1, 4, figsize=(17, 4.4))
    for ax, (key, label, _, (target, _unused)) in zip(axes, panels):
        for pipeline, (colour, plabel) in _STYLE.items():
            for kind, (marker, ls, klabel) in _MARK.items():
                # precision and errors say nothing where nothing was detected: no point there
                pts = sorted((1e3 * d["depth_sigma_at_plate_m"], d["evaluation"].get(key))
                             for d in docs if d.get("pipeline", "paper") == pipeline and _kind(d) == kind
                             and (key == "recall" or d["evaluation"].get("detections", 0) > 0))
                pts = [(x, y) for x, y in pts if isinstance(y, (int, float)) and y == y]
                if not pts:
                    continue
                xs, ys = zip(*pts)
                ax.plot(xs, ys, color=colour, marker=marker, ls=ls, lw=1.6, ms=5, label=f"{plabel}, {klabel}")
        ax.axhline(target, color="0.4", lw=1, ls=":", label="target" if key == "recall" else None)
        ax.set_xlabel("depth noise sigma at the plate (mm)")
        ax.set_title(label)
        ax.grid(alpha=0.3)
        if key in ("recall", "precision"):
            ax.set_ylim(-0.03, 1.03)
    d0 = docs[0] if docs else {}
    seeds = d0.get("seeds") or ["?", "?"]
    fig.suptitle(f"Perception under depth noise: {d0.get('variant', '?')} scenes, seeds {seeds[0]}-{seeds[-1]}, "
                 f"{d0.get('segmentation', '?')} segmentation (dotted: the issue's targets; no point where "
                 "nothing was detected)", fontsize=11)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=5, fontsize=9, frameon=False)
    fig.tight_layout(rect=(0, 0.08, 1, 0.95))
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return out
