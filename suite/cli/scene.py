"""`python -m suite scene`: generate a scene and print its ground truth."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from suite.cli.args import add_scene_arguments, scene_from_args
from scenes.errors import SuiteError


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_scene_arguments(p)
    p.add_argument("--json", action="store_true", help="print the ground truth as JSON")
    p.add_argument("--image", metavar="PATH", help="write what the top camera sees to PATH (PNG)")
    p.add_argument("--view", metavar="PATH", help="write a 3D view of the station with the arm above the plate (PNG)")


def run(args: argparse.Namespace) -> int:
    scene = scene_from_args(args)
    truth = scene.to_json()
    if args.json:
        print(json.dumps(truth))
    else:
        print(f"scene seed {scene.seed}, variant {scene.variant}: {len(scene.cans)} cans")
        for c in truth["cans"]:
            kind = "lying " if c["lying"] else "upright"
            x, y, z = c["p_WC_m"]
            print(f"  can {c['id']}: {kind} at ({x:+.3f}, {y:+.3f}, {z:.3f}) m, axis yaw {c['axis_yaw_rad']:+.3f} rad")
    for flag, path in (("--image", args.image), ("--view", args.view)):
        if path and Path(path).suffix.lower() != ".png":
            raise SuiteError(f"{flag} must name a .png file, got {path!r}")
    if args.image:
        from scenes.render import render

        _write_png(args.image, render(scene, cameras=["top"])["top"].rgb)
        if not args.json:
            print(f"top camera image written to {args.image}")
    if args.view:
        from scenes.drake_scene import build_drake_scene
        from scenes.grasp_rule import waypoint_pose
        from scenes.ik import Q_READY, PoseIk
        from scenes.render import render_overview

        q = None  # the arm above the plate; at its ready pose in a world without waypoints
        if scene.spec.waypoints is not None:
            ik = PoseIk(build_drake_scene(scene, mode="plan", cameras=False))
            q = ik.solve(waypoint_pose(scene.spec.waypoints.above_plate_m), q_seed=Q_READY,
                         rng=np.random.default_rng(scene.seed))
        _write_png(args.view, render_overview(scene, q_iiwa=Q_READY if q is None else q))
        if not args.json:
            print(f"3D view written to {args.view}")
    return 0


def _write_png(path: str, rgb) -> None:
    import cv2

    Path(path).parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), rgb[:, :, ::-1]):
        raise SuiteError(f"cannot write image {path!r}")
