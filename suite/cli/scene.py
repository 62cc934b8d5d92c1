"""`python -m suite scene`: generate a scene and print its ground truth."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from suite.cli.args import add_scene_arguments, scene_from_args
from scenes.errors import SuiteError


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_scene_arguments(p)
    p.add_argument("--json", action="store_true", help="print the ground truth as JSON")
    p.add_argument("--image", metavar="PATH", help="write what the top camera sees to PATH (PNG)")


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
    if args.image:
        import cv2

        from scenes.render import render

        path = Path(args.image)
        if path.suffix.lower() != ".png":
            raise SuiteError(f"--image must name a .png file, got {args.image!r}")
        img = render(scene, cameras=["top"])["top"]
        path.parent.mkdir(parents=True, exist_ok=True)
        if not cv2.imwrite(str(path), img.rgb[:, :, ::-1]):
            raise SuiteError(f"cannot write image {args.image!r}")
        if not args.json:
            print(f"top camera image written to {path}")
    return 0
