"""Command-line arguments shared by the subcommands, validated at the boundary."""

from __future__ import annotations

import argparse
from pathlib import Path
from collections.abc import Callable
from typing import Any

from scenes.errors import SuiteError
from scenes.schema import NonNeg, NonNegInt, Pos, PosInt, Unit, refusal


def flag(tp: Any, kind: type) -> Callable[[str], Any]:
    """An argparse type: the text read as `kind` (int or float), then checked against the schema
    type `tp` (`scenes.schema`'s aliases), so a flag and a YAML field of one type allow the same
    values, with the same words."""
    noun = "an integer" if kind is int else "a number"

    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not {noun}") from None
        why = refusal(tp, value)
        if why is not None:
            raise argparse.ArgumentTypeError(f"{text!r}: {why}")
        return value

    return parse


positive_int = flag(PosInt, int)
nonneg_int = flag(NonNegInt, int)
positive_float = flag(Pos, float)
nonneg_float = flag(NonNeg, float)


def add_scene_arguments(p: argparse.ArgumentParser) -> None:
    """--seed, --cans, --variant, --spec, --min-gap-m, --can-color."""
    p.add_argument("--seed", type=nonneg_int, default=0, help="scene seed (default 0)")
    p.add_argument("--cans", type=nonneg_int, default=None, help="number of cans (default: the spec's, 5)")
    p.add_argument("--variant", default="open", help="scene variant: open or wall (default open)")
    p.add_argument("--spec", default=None, metavar="YAML", help="scene spec file (default: scenes/specs/default.yaml)")
    p.add_argument("--min-gap-m", type=nonneg_float, default=None, help="minimum gap between cans (default: the spec's, 0.03)")
    p.add_argument("--can-color", default=None, metavar="R,G,B", help="can colour, three values in [0, 1] (default: the spec's red)")


def add_noise_arguments(p: argparse.ArgumentParser) -> None:
    """--noise-correlation-px and --noise-scale: the sensor model's noise, correlated and scaled
    (`perception.pipeline.PerceptionSetup`; they need --sensor or --depth-noise-m)."""
    p.add_argument("--noise-correlation-px", type=nonneg_float, default=0.0, metavar="PX",
                   help="the sensor's depth noise correlated over PX pixels (its autocorrelation falls to 1/e there; "
                        "default 0: independent per pixel); needs --sensor or --depth-noise-m")
    p.add_argument("--noise-scale", type=positive_float, default=1.0, metavar="K",
                   help="the sensor's depth noise sigma times K (default 1); needs --sensor or --depth-noise-m")


def add_planning_arguments(p: argparse.ArgumentParser) -> None:
    """--planner, the scene arguments, --grasps and --time-limit-s (one scene, one planner)."""
    p.add_argument("--planner", required=True, help="planner name (e.g. ik, rrt, trajopt)")
    add_scene_arguments(p)
    p.add_argument("--grasps", choices=("perceived", "truth"), default="truth",
                   help="grasps from perception or from ground truth (default truth)")
    p.add_argument("--time-limit-s", type=positive_float, default=5.0, help="budget per problem, seconds (default 5)")


def parse_color(text: str) -> tuple[float, float, float, float]:
    try:
        vals = [float(v) for v in text.split(",")]
    except ValueError:
        vals = []
    if len(vals) != 3 or any(refusal(Unit, v) for v in vals):
        raise SuiteError(f"--can-color must be three numbers in [0, 1] like 0.1,0.3,0.9, got {text!r}")
    return (vals[0], vals[1], vals[2], 1.0)


def spec_from_args(args: argparse.Namespace):
    from scenes.spec import load_spec

    spec = load_spec(args.spec, variant=args.variant)
    if args.cans is not None:
        spec = spec.with_can_count(args.cans)
    if args.min_gap_m is not None:
        spec = spec.with_min_gap(args.min_gap_m)
    if args.can_color is not None:
        spec = spec.with_can_color(parse_color(args.can_color))
    return spec


def scene_from_args(args: argparse.Namespace):
    from scenes.generate import generate_scene

    return generate_scene(spec_from_args(args), seed=args.seed)


def settings_file(path: str, *, flag: str) -> dict:
    """The YAML mapping of settings a flag names (`--config`, `--moving-bin-scenario`); its fields
    are checked by the caller's schema. A file that cannot be read, or is not a mapping, is one line."""
    import yaml

    try:
        raw = yaml.safe_load(Path(path).read_text())
    except OSError as exc:
        raise SuiteError(f"cannot read {flag} {path!r}: {exc.strerror}") from None
    except yaml.YAMLError:
        raise SuiteError(f"{flag} {path!r} is not valid YAML") from None
    raw = raw or {}
    if not isinstance(raw, dict):
        raise SuiteError(f"{flag} {path!r} must be a YAML mapping of settings")
    return raw
