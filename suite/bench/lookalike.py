"""`python -m suite bench lookalike`: the hourglass refusal curve.

The `lookalike` family's scenes (`--seed`, `--scenes`) are drawn once; each is then rendered with
its hourglasses rebuilt at every waist of `--waists` (`scenes.lookalikes.with_hourglass_waist`:
nothing else moves), through each sensor of `--sensors` with the same noise draws at every waist
(`perception.pipeline.noise_rng` of the scene's seed, cameras in the order top, front, back), and
every pipeline sees the same frames:

- `paper`: the seed paper's pipeline, the top camera only;
- `robust`: the robust pipeline with its side check, the top camera and the side cameras;
- `robust-top`: the robust pipeline without the side check, the top camera only.

A sensor is `none` (a perfect sensor), a name of `scenes.sensor.SENSOR_PRESETS`, or such a name
with a noise correlation length in pixels after `@` (`kinect-v1@8`: `SensorSpec.with_noise`).

Per waist and pipeline it reports the hourglasses refused (none of their detections grasped), with
a 95% Wilson interval, the cans found (recall) with the dented cans counted as cans
(`perception.evaluate.truth_cans`), and the cans the side check refused: found by `robust-top`,
not by `robust` on the same frames. One JSON per sensor is written to `--out`.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import subprocess
import time
from pathlib import Path

from suite.cli.args import nonneg_int, positive_int

log = logging.getLogger(__name__)

#: the default waists (fractions of the can's radius): the family's 0.55 up to 0.95
DEFAULT_WAISTS = (0.55, 0.65, 0.75, 0.80, 0.85, 0.90, 0.95)
#: the cameras rendered: every camera a pipeline of `perception.pipeline.PIPELINE_CAMERAS` uses
CAMERAS = ("top", "front", "back")
#: the code the sweep runs: a figure is from a clean tree when none of it differs from the commit
CODE_PATHS = ("perception", "scenes", "suite/bench/lookalike.py")
#: where the figures are written by default
DEFAULT_OUT = Path("results") / "perception"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--seed", type=nonneg_int, default=0, help="first `lookalike` scene seed (default 0)")
    p.add_argument("--scenes", type=positive_int, default=40, help="scenes (default 40)")
    p.add_argument("--waists", default=",".join(f"{w:g}" for w in DEFAULT_WAISTS),
                   help="hourglass waists, fractions of the can's radius in (0, 1] (default %(default)s)")
    p.add_argument("--sensors", default="none,kinect-v1,kinect-v1@8",
                   help="sensor models, comma-separated: none (a perfect sensor), a name of "
                        "scenes.sensor.SENSOR_PRESETS, or NAME@L for its noise correlated over L pixels "
                        "(default %(default)s)")
    p.add_argument("--segmentation", choices=("color", "geometric"), default="geometric",
                   help="the pipelines' segmentation (default geometric, as the look-alike table)")
    p.add_argument("--out", metavar="DIR", default=None,
                   help="write one JSON per sensor to DIR (e.g. results/perception/lookalike-sweep-97300)")
    p.add_argument("--json", action="store_true", help="print the JSON instead of the table")


def parse_waists(text: str) -> tuple[float, ...]:
    """Waist fractions from a comma-separated list; each in (0, 1]."""
    from scenes.errors import SuiteError

    out = []
    for item in text.split(","):
        try:
            w = float(item)
        except ValueError:
            raise SuiteError(f"--waists: {item!r} is not a number; give fractions of the can's radius in (0, 1]") from None
        if not 0.0 < w <= 1.0:
            raise SuiteError(f"--waists: {w:g} is outside (0, 1] of the can's radius")
        out.append(w)
    return tuple(out)


def sensor_model(name: str):
    """The sensor a name of `--sensors` stands for (None for `none`).

    Raises:
        SuiteError: an unknown preset or a bad correlation length, naming it and what is allowed.
    """
    from scenes.errors import SuiteError
    from scenes.sensor import SENSOR_PRESETS

    if name == "none":
        return None
    preset, _, corr = name.partition("@")
    if preset not in SENSOR_PRESETS:
        raise SuiteError(f"--sensors: unknown sensor {name!r}; allowed: none, {', '.join(sorted(SENSOR_PRESETS))}, "
                         "or one of them with @L for a noise correlation length of L pixels")
    if not corr:
        return SENSOR_PRESETS[preset]
    try:
        length = float(corr)
    except ValueError:
        length = -1.0
    if not (length >= 0 and length < float("inf")):
        raise SuiteError(f"--sensors: {name!r}: the correlation length after @ must be a number of pixels >= 0")
    return SENSOR_PRESETS[preset].with_noise(correlation_px=length)


def parse_sensors(text: str) -> tuple[str, ...]:
    """Sensor names of `--sensors` (each checked by `sensor_model`)."""
    from scenes.errors import SuiteError

    names = tuple(s.strip() for s in text.split(",") if s.strip())
    if not names:
        raise SuiteError(f"--sensors {text!r}: name at least one sensor (none for a perfect one)")
    for name in names:
        sensor_model(name)
    return names


def file_name(sensor: str) -> str:
    """The JSON a sensor's figures are written to: `kinect-v1@8` -> `kinect-v1-corr8px.json`."""
    preset, _, corr = sensor.partition("@")
    return f"{preset}-corr{corr}px.json" if corr else f"{preset}.json"


def code_commit(root: Path | None = None) -> str | None:
    """HEAD, with "+dirty" when a tracked file of `CODE_PATHS` differs from it (other files of a
    shared checkout do not change what the sweep computes)."""
    here = root or Path(__file__).resolve().parents[2]
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=here, capture_output=True, text=True, timeout=5).stdout.strip()
        if not head:
            return None
        changed = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", *CODE_PATHS], cwd=here,
                                 capture_output=True, text=True, timeout=10)
        return head + "+dirty" if changed.returncode == 0 and changed.stdout.strip() else head
    except (OSError, subprocess.SubprocessError):
        return None


def _detect(pipeline: str, frames: dict, spec, params):
    """One pipeline's detections on the frames it uses (`PIPELINE_CAMERAS`)."""
    from perception.pipeline import GRASP_CAMERA, PIPELINE_CAMERAS, detect

    side = {n: frames[n] for n in PIPELINE_CAMERAS[pipeline] if n != GRASP_CAMERA}
    return detect(frames[GRASP_CAMERA], spec, params=params, pipeline=pipeline, side_images=side or None)[0]


def measure(*, seed: int, scenes: int, waists: tuple[float, ...], sensors: tuple[str, ...],
            segmentation: str = "geometric") -> dict[str, dict]:
    """Run the sweep (see the module docstring).

    Returns:
        sensor name -> its document: the settings, `curve` (one row per waist and pipeline) and
        `scene_records` (per scene, waist and pipeline: hourglasses grasped, the ids of the
        cans found, of `perception.evaluate.truth_cans`).
    """
    from perception.evaluate import match_lookalikes, match_scene, truth_cans
    from perception.grasps import PerceptionParams
    from perception.observe import sense
    from perception.pipeline import PIPELINE_CAMERAS, noise_rng
    from scenes import lookalikes as la
    from scenes.errors import SuiteError
    from scenes.generate import generate_scene
    from scenes.render import render
    from scenes.spec import load_spec

    commit = code_commit()  # before the run: the code imported is the code of this moment
    spec = load_spec(variant="lookalike")
    params = PerceptionParams(segmentation=segmentation)
    drawn, skipped, s = [], [], seed - 1
    while len(drawn) < scenes:
        s += 1
        if len(skipped) > scenes:
            raise SuiteError(f"the generator could not draw {len(skipped)} of the scenes from seed {seed}")
        try:
            drawn.append(generate_scene(spec, seed=s))
        except SuiteError as exc:
            log.warning("seed %d skipped: %s", s, exc)
            skipped.append(s)
    records = {name: [] for name in sensors}
    t0 = time.perf_counter()
    for i, scene in enumerate(drawn):
        truth = truth_cans(scene)
        n_cans = len(scene.cans)
        for name in sensors:
            records[name].append({"seed": scene.seed, "key": scene.key(), "cans": n_cans, "dented": len(truth) - n_cans,
                                  "dented_ids": [c.id for c in truth[n_cans:]], "by_waist": {}})
        for w in waists:
            sc = dataclasses.replace(scene, spec=la.with_hourglass_waist(scene.spec, w))
            clean = render(sc, cameras=list(CAMERAS))
            for name in sensors:
                sensor = sensor_model(name)
                if sensor is None:
                    frames = clean
                else:
                    rng = noise_rng(scene.seed)
                    frames = {n: sense(clean[n], sensor=sensor, rng=rng) for n in CAMERAS}
                row = {}
                for pipeline in PIPELINE_CAMERAS:
                    dets = _detect(pipeline, frames, sc.spec, params)
                    m, look = match_scene(dets, sc), match_lookalikes(dets, sc)
                    row[pipeline] = {"hourglasses": look.hourglasses, "hourglasses_grasped": look.hourglasses_grasped,
                                     "found": sorted(c for c, _ in m.pairs), "detections": m.n_detected,
                                     "distractor_grasps": len(m.distractor_grasps)}
                records[name][-1]["by_waist"][f"{w:g}"] = row
        log.info("scene %d/%d (seed %d) done, %.0f s", i + 1, len(drawn), scene.seed, time.perf_counter() - t0)
    out = {}
    for name in sensors:
        out[name] = {
            "variant": "lookalike", "seeds": [drawn[0].seed, drawn[-1].seed], "skipped_seeds": skipped,
            "scenes": len(drawn), "sensor": name,
            "sensor_model": None if name == "none" else dataclasses.asdict(sensor_model(name)),
            "segmentation": segmentation, "waists": list(waists), "git_commit": commit,
            "pipelines": {p: {"cameras": list(c)} for p, c in PIPELINE_CAMERAS.items()},
            "side_check": _side_check_settings(),
            "curve": curve(records[name], waists), "scene_records": records[name],
        }
    return out


def _side_check_settings() -> dict:
    from perception import side_view as sv

    return {"tolerance_m": sv.SIDE_TOLERANCE_M, "band_edges": list(sv.BAND_EDGES), "sector_deg": sv.SECTOR_DEG,
            "min_sector_points": sv.MIN_SECTOR_POINTS, "max_axis_shift_m": sv.MAX_AXIS_SHIFT_M}


def curve(records: list[dict], waists) -> list[dict]:
    """One row per waist and pipeline from the scene records: hourglasses refused (with a 95%
    Wilson interval), cans and dented cans found, and those the side check refused (found by
    `robust-top`, not by `robust`)."""
    from perception.pipeline import PIPELINE_CAMERAS
    from suite.report.outcomes import wilson_interval

    rows = []
    for w in waists:
        key = f"{w:g}"
        for pipeline in PIPELINE_CAMERAS:
            n_h = k_h = n_c = f_c = n_d = f_d = det = side_c = side_d = dist = 0
            for rec in records:
                r = rec["by_waist"][key][pipeline]
                dented = set(rec["dented_ids"])
                found = set(r["found"])
                n_h += r["hourglasses"]
                k_h += r["hourglasses_grasped"]
                n_c += rec["cans"]
                n_d += rec["dented"]
                f_d += len(found & dented)
                f_c += len(found - dented)
                det += r["detections"]
                dist += r["distractor_grasps"]
                if pipeline == "robust":
                    lost = set(rec["by_waist"][key]["robust-top"]["found"]) - found
                    side_d += len(lost & dented)
                    side_c += len(lost - dented)
            lo, hi = wilson_interval(n_h - k_h, n_h) if n_h else (float("nan"), float("nan"))
            row = {"waist": w, "pipeline": pipeline, "hourglasses": n_h, "hourglasses_refused": n_h - k_h,
                   "refused": round((n_h - k_h) / n_h, 4) if n_h else None, "refused_ci95": [round(lo, 4), round(hi, 4)],
                   "cans": n_c, "cans_found": f_c, "dented": n_d, "dented_found": f_d, "detections": det,
                   "distractor_grasps": dist}
            if pipeline == "robust":
                row |= {"cans_refused_by_side_check": side_c, "dented_refused_by_side_check": side_d}
            rows.append(row)
    return rows


def table_lines(doc: dict) -> list[str]:
    """The curve as text: one line per waist and pipeline."""
    cams = "; ".join(f"{p}: {'+'.join(v['cameras'])}" for p, v in doc["pipelines"].items())
    lines = [f"lookalike seeds {doc['seeds'][0]}-{doc['seeds'][1]} ({doc['scenes']} scenes), sensor {doc['sensor']}, "
             f"{doc['segmentation']} segmentation; cameras {cams}",
             f"{'waist/r':>7} {'pipeline':>10} {'hourglasses refused (95% CI)':>30} {'cans found':>12} "
             f"{'dented found':>12} {'refused by side check (cans, dented)':>37}"]
    for r in doc["curve"]:
        lo, hi = r["refused_ci95"]
        ref = f"{r['hourglasses_refused']}/{r['hourglasses']} {100 * r['refused']:.0f}% ({100 * lo:.0f}-{100 * hi:.0f})" \
            if r["hourglasses"] else "-"
        side = f"{r['cans_refused_by_side_check']}, {r['dented_refused_by_side_check']}" if "cans_refused_by_side_check" in r else ""
        lines.append(f"{r['waist']:>7g} {r['pipeline']:>10} {ref:>30} {r['cans_found']:>6}/{r['cans']:<5} "
                     f"{r['dented_found']:>6}/{r['dented']:<5} {side:>37}")
    return lines


def run(args: argparse.Namespace) -> int:
    waists, sensors = parse_waists(args.waists), parse_sensors(args.sensors)
    # every refusal and every can-model rejection is logged as a warning: thousands in a sweep
    logging.getLogger("perception").setLevel(logging.ERROR)
    docs = measure(seed=args.seed, scenes=args.scenes, waists=waists, sensors=sensors, segmentation=args.segmentation)
    for name, doc in docs.items():
        doc["command"] = (f"python -m suite bench lookalike --seed {args.seed} --scenes {args.scenes} --waists {args.waists} "
                          f"--sensors {args.sensors} --segmentation {args.segmentation}"
                          + (f" --out {args.out}" if args.out else ""))
        if args.out:
            out = Path(args.out)
            out.mkdir(parents=True, exist_ok=True)
            (out / file_name(name)).write_text(json.dumps(doc) + "\n", encoding="utf-8")
    if args.json:
        print(json.dumps(docs))
        return 0
    for doc in docs.values():
        print("\n".join(table_lines(doc)))
    if args.out:
        print(f"written: {', '.join(str(Path(args.out) / file_name(n)) for n in docs)}")
    return 0
