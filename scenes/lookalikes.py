"""The seed paper's look-alikes, built from the obstacle primitives every engine already loads
(Drake rendering, the Drake collision scene and the python-fcl world see them as they see any
`extra` obstacle): a red hourglass that matches a can from above, and a dented can.

- Hourglass (`hourglass_N_k`, k = 0 at the bottom): `HOURGLASS_SECTIONS` coaxial cylinders
  stacked to the can's height; the bottom and top sections have the can's radius (a can's flat top
  and rim from above), the ones between narrow linearly to a waist of `waist_fraction` of it at
  mid-height (`HOURGLASS_WAIST_FRACTION` by default; the family's `hourglass_waist`, and
  `with_hourglass_waist` for a sweep over the same scenes). The top camera sees a can's disc; only
  a side view shows the waist.
- Dented can (`dented_N_bottom`, `_band`, `_top`): a can of the spec's size and colour whose side
  is pushed in over a band of its length. Primitives cannot be cut, so the dent is approximated:
  over the band, the body is a cylinder of radius r - d/2 whose axis is moved d/2 away from the
  dent, which keeps the far side at r and pushes the near side in by `DENT_DEPTH_M` (d): at an
  angle t from the dent's direction the side lies about r - (d/2)(1 + cos t) from the can's axis
  (d at the dent, d/2 at right angles to it, nothing on the far side). A real dent is local (a
  crease a few centimetres wide); this one runs all round but the far side, and has sharp edges at
  the band's ends.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from scenes.errors import SuiteError
from scenes.spec import SceneSpec
from scenes.spec_parts import Obstacle, pose_tuple

HOURGLASS_PREFIX = "hourglass_"
DENTED_PREFIX = "dented_"
#: stacked cylinders of an hourglass, and its waist's radius over the can's
HOURGLASS_SECTIONS = 9
HOURGLASS_WAIST_FRACTION = 0.55
#: how far a dent pushes the side in (metres) and the band's length over the can's
DENT_DEPTH_M = 0.008
DENT_BAND_FRACTION = 0.35


def _X(R: np.ndarray, p) -> np.ndarray:
    X = np.eye(4)
    X[:3, :3] = R
    X[:3, 3] = p
    return X


def _rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def hourglass(index: int, *, p_xy_m, plate_top_z_m: float, radius_m: float, height_m: float, color_rgba,
              waist_fraction: float = HOURGLASS_WAIST_FRACTION) -> list[Obstacle]:
    """The parts of an upright hourglass standing at `p_xy_m` on the plate (see the module
    docstring), its waist `waist_fraction` of `radius_m`."""
    if not 0.0 < waist_fraction <= 1.0:
        raise SuiteError(f"hourglass waist fraction {waist_fraction}: allowed (0, 1] of the can's radius")
    n = HOURGLASS_SECTIONS
    dz = height_m / n
    waist = waist_fraction * radius_m
    half = (n - 1) / 2
    out = []
    for k in range(n):
        d = abs(k - half) / half  # 1 at the ends, 0 at the waist
        r = radius_m if k in (0, n - 1) else waist + (radius_m - waist) * d
        X = _X(np.eye(3), (p_xy_m[0], p_xy_m[1], plate_top_z_m + (k + 0.5) * dz))
        out.append(Obstacle(f"{HOURGLASS_PREFIX}{index}_{k}", "cylinder", (float(r), float(dz)), pose_tuple(X),
                            tuple(color_rgba)))
    return out


def dented_can(index: int, *, X_WC: np.ndarray, dent_dir_rad: float, band_center_m: float, radius_m: float,
               height_m: float, color_rgba) -> list[Obstacle]:
    """The parts of a dented can at pose `X_WC` (the can's frame: its axis is z, its centre the
    origin). The dent faces `dent_dir_rad` about the axis from the frame's x; its band is centred
    `band_center_m` along the axis."""
    h, r = height_m, radius_m
    b = DENT_BAND_FRACTION * h
    z1, z2 = band_center_m - b / 2, band_center_m + b / 2
    away = -np.array([math.cos(dent_dir_rad), math.sin(dent_dir_rad), 0.0])
    parts = {"bottom": (r, z1 + h / 2, np.array([0.0, 0.0, (-h / 2 + z1) / 2])),
             "band": (r - DENT_DEPTH_M / 2, b, np.array([0.0, 0.0, band_center_m]) + DENT_DEPTH_M / 2 * away),
             "top": (r, h / 2 - z2, np.array([0.0, 0.0, (z2 + h / 2) / 2]))}
    return [Obstacle(f"{DENTED_PREFIX}{index}_{name}", "cylinder", (float(rad), float(length)),
                     pose_tuple(X_WC @ _X(np.eye(3), p_C)), tuple(color_rgba)) for name, (rad, length, p_C) in parts.items()]


def lying_frame(*, p_xy_m, yaw_rad: float, plate_top_z_m: float, radius_m: float, roll_rad: float) -> np.ndarray:
    """X_WC of a can lying on the plate, its axis along yaw, turned by roll about its axis (at roll
    0 the frame's x points down)."""
    Ry = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # z -> world x, x -> -z
    return _X(_rz(yaw_rad) @ Ry @ _rz(roll_rad), (p_xy_m[0], p_xy_m[1], plate_top_z_m + radius_m))


def groups(extra, prefix: str) -> dict[str, list[Obstacle]]:
    """The look-alikes among obstacles, by object (`hourglass_0`, `dented_1`, ...)."""
    out: dict[str, list[Obstacle]] = {}
    for o in extra:
        if o.name.startswith(prefix):
            out.setdefault(o.name.rsplit("_", 1)[0], []).append(o)
    return out


def dented_pose(parts: list[Obstacle], *, height_m: float) -> tuple[np.ndarray, np.ndarray]:
    """A dented can's centre (3,) and axis (3,) in the world, from its bottom and top parts."""
    by = {o.name.rsplit("_", 1)[1]: o for o in parts}
    bot, top = by["bottom"], by["top"]
    X0 = bot.pose()
    axis = X0[:3, 2]
    centre = X0[:3, 3] + axis * (height_m / 2 - bot.size_m[1] / 2)
    return centre, axis


def with_hourglass_waist(spec: SceneSpec, waist_fraction: float) -> SceneSpec:
    """The same drawn scene with every hourglass rebuilt to a waist of `waist_fraction` of the
    can's radius (same place, size and colour; nothing else moves). At the family's waist it is
    the scene as drawn: the hourglass's waist does not enter any draw."""
    r, h = spec.can.radius_m, spec.can.height_m
    rebuilt: dict[str, list[Obstacle]] = {}
    for name, parts in groups(spec.extra, HOURGLASS_PREFIX).items():
        bottom = min(parts, key=lambda o: o.pose()[2, 3])
        p = bottom.pose()[:3, 3]
        rebuilt[name] = hourglass(int(name[len(HOURGLASS_PREFIX):]), p_xy_m=(float(p[0]), float(p[1])),
                                  plate_top_z_m=float(p[2] - bottom.size_m[1] / 2), radius_m=r, height_m=h,
                                  color_rgba=bottom.color_rgba, waist_fraction=waist_fraction)
    extra, done = [], set()
    for o in spec.extra:
        name = o.name.rsplit("_", 1)[0]
        if o.name.startswith(HOURGLASS_PREFIX) and name in rebuilt:
            if name not in done:
                extra += rebuilt[name]
                done.add(name)
        else:
            extra.append(o)
    return dataclasses.replace(spec, extra=tuple(extra))
