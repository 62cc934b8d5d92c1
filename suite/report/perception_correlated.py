"""docs/perception.md's detection table under correlated Kinect v1 noise: one row per committed
evaluation (`perceive --evaluate --scenes N --json`) in `CORRELATED_RUNS`, each naming its sensor,
the noise's correlation length and scale, the pipeline and the cameras it looked through."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np

#: the evaluations: `perceive --evaluate --json` under kinect-v1 at 4 and 8 px, 1x and 2x sigma
CORRELATED_RUNS = Path("results") / "perception" / "correlated-97100"
#: the rows' order of pipelines (and segmentations)
_ORDER = [("paper", "color"), ("paper", "geometric"), ("robust-top", "geometric"), ("robust", "geometric")]


def correlated_table(root: Path, *, check_commit: Callable[[str, object], None] | None = None) -> str:
    """The table (markdown) of every evaluation in `CORRELATED_RUNS` under `root`; `check_commit(shown,
    commit)` may refuse an evaluation whose code was not a commit's."""
    docs = []
    for path in sorted((root / CORRELATED_RUNS).glob("*.json")):
        d = json.loads(path.read_text(encoding="utf-8"))
        if check_commit is not None:
            check_commit((CORRELATED_RUNS / path.name).as_posix(), d.get("git_commit"))
        docs.append(d)

    def key(d):
        pipe = (d.get("pipeline", "paper"), d["segmentation"])
        return (d.get("sensor", ""), float(d.get("noise_correlation_px", 0.0)), float(d.get("noise_scale", 1.0)),
                _ORDER.index(pipe) if pipe in _ORDER else len(_ORDER), pipe)

    lines = ["| sensor | correlation (px) | σ scale | pipeline | cameras | segmentation | scenes (seeds) | cans "
             "| recall | precision | xy error, median / p95 (mm) | grasps on distractors | noise measured on the plate, "
             "median (mm) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for d in sorted(docs, key=key):
        e = d["evaluation"]
        seeds = d.get("seeds") or []
        found = e.get("detections", 0) > 0
        xy = (f"{e['xy_error_median_mm']:.2f} / {e['xy_error_p95_mm']:.2f}"
              if found and e.get("xy_error_p95_mm") == e.get("xy_error_p95_mm") else "-")
        cells = [d.get("sensor", "-"), f"{float(d.get('noise_correlation_px', 0.0)):g}",
                 f"{float(d.get('noise_scale', 1.0)):g}x", d.get("pipeline", "paper"), ", ".join(d.get("cameras", ["top"])),
                 d["segmentation"], f"{e['scenes']} ({seeds[0]}-{seeds[-1]})" if seeds else str(e["scenes"]),
                 str(e["cans"]), f"{e['recall']:.3f}", f"{e['precision']:.3f}" if found else "-", xy,
                 f"{e['distractor_grasps']} of {e['distractors']}"]
        noise = [r["plate_noise_m"] for r in d.get("scenes", []) if "plate_noise_m" in r]
        cells.append(f"{1e3 * float(np.median(noise)):.2f}" if noise else "-")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
