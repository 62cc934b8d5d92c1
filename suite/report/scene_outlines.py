"""A scene as flat outlines on a view plane: what the gripper-path figures and the HTML report draw.

A view is a pair of world axes (`TOP` = x, y seen from above; `SIDE` = y, z seen from +x). Every
primitive (box, cylinder, sphere, at any pose) becomes the convex hull of its projection, so the
matplotlib figures (`plots_paths`) and the report's in-browser drawings (`suite.report.html`) show
the same geometry from one source.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

#: World axes of the two views: (horizontal, vertical) on the page.
TOP: tuple[int, int] = (0, 1)
SIDE: tuple[int, int] = (1, 2)


@dataclasses.dataclass(frozen=True)
class Outline:
    """One primitive's outline on a view.

    Attributes:
        kind: what it is, for its style: plate, bin, wall, shelf, distractor, obstacle, can, held can.
        label: the legend's name (e.g. an unnamed family obstacle keeps its spec name).
        xy_m: the outline's corners (K, 2), metres, in the view's axes, counter-clockwise.
        can_id: the can's id for kind "can" / "held can", else None.
    """

    kind: str
    label: str
    xy_m: np.ndarray
    can_id: int | None = None


def primitive_outline(shape: str, size_m: Sequence[float], X_WO: np.ndarray, *, dims: tuple[int, int]) -> np.ndarray:
    """The convex outline (K, 2) of a box (full sizes), cylinder (radius, length, axis z) or sphere
    (radius) at pose X_WO, projected on world axes `dims`."""
    from scipy.spatial import ConvexHull

    s = size_m
    if shape == "box":
        pts = np.array([[x, y, z] for x in (-s[0] / 2, s[0] / 2) for y in (-s[1] / 2, s[1] / 2)
                        for z in (-s[2] / 2, s[2] / 2)])
    else:
        r, half = s[0], (s[1] / 2 if shape == "cylinder" else s[0])
        a = np.linspace(0, 2 * np.pi, 24, endpoint=False)
        ring = np.column_stack([r * np.cos(a), r * np.sin(a)])
        pts = np.vstack([np.column_stack([ring, np.full(len(a), z)]) for z in (-half, half)])
    p = (pts @ X_WO[:3, :3].T + X_WO[:3, 3])[:, list(dims)]
    return p[ConvexHull(p).vertices]


def _translation(center_m) -> np.ndarray:
    X = np.eye(4)
    X[:3, 3] = center_m
    return X


def scene_outlines(spec, cans: Sequence = (), *, dims: tuple[int, int]) -> list[Outline]:
    """Plate, bin, the spec's wall, every family obstacle and the cans, on the view `dims` (those
    the scene has: a world that is no can station has no plate or bin).

    Args:
        spec: the scene's `SceneSpec`.
        cans: the cans on the plate (`CanPose`), e.g. a problem's scene without its recycled cans.
        dims: the view (`TOP` or `SIDE`).
    """
    out = []
    if spec.plate is not None:
        out.append(Outline("plate", "plate", primitive_outline("box", spec.plate.size_m, _translation(spec.plate.center_m),
                                                               dims=dims)))
    for box in (spec.bin.boxes() if spec.bin is not None else {}).values():
        out.append(Outline("bin", "bin", primitive_outline("box", box.size_m, _translation(box.center_m), dims=dims)))
    if spec.wall is not None:
        out.append(Outline("wall", "wall", primitive_outline("box", spec.wall.size_m, _translation(spec.wall.center_m),
                                                             dims=dims)))
    for o in spec.extra:  # a family's obstacles: walls, window frame, shelf, distractors
        prefix = o.name.split("_")[0]
        kind = prefix if prefix in ("wall", "shelf", "distractor") else "obstacle"
        out.append(Outline(kind, prefix if kind != "obstacle" else o.name,
                           primitive_outline(o.shape, o.size_m, o.pose(), dims=dims)))
    for can in cans:
        out.append(can_outline(spec, can.X_WC(), dims=dims, can_id=can.id))
    return out


def can_outline(spec, X_WC: np.ndarray, *, dims: tuple[int, int], can_id: int, held: bool = False) -> Outline:
    """A can (the spec's radius and height) at pose X_WC (its z axis along the cylinder)."""
    xy = primitive_outline("cylinder", (spec.can.radius_m, spec.can.height_m), X_WC, dims=dims)
    return Outline("held can" if held else "can", "held can" if held else "can", xy, can_id=can_id)
