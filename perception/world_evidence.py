"""What the perceived world's builder reads in its frames: whether points lie in a known shape
(a fixture, a perceived can, the robot's own parts), the sensor's depth sigma at a depth, and
the depth rows' short holes filled by the projector-shadow rule (`perception.world`)."""

from __future__ import annotations

import numpy as np

from scenes.scene import HeldCan
from scenes.spec import SceneSpec


def inside(points: np.ndarray, kind: str, dims, X_WS: np.ndarray, margin_m: float) -> np.ndarray:
    """Which points (N, 3) lie within `margin_m` of a primitive (box, cylinder, capsule, sphere)
    at pose X_WS."""
    d = np.asarray(dims, float)
    if kind == "box":
        reach = 0.5 * float(np.linalg.norm(d))
    elif kind == "sphere":
        reach = float(d[0])
    else:  # cylinder (a capsule reaches one radius further along its axis)
        reach = float(np.hypot(d[0], d[1] / 2)) + float(d[0])
    near = np.abs(points - X_WS[:3, 3]).max(axis=1) <= reach + margin_m  # a cheap cube test first
    out = np.zeros(len(points), bool)
    if near.any():
        out[near] = _inside(points[near], kind, dims, X_WS, margin_m)
    return out


def _inside(points: np.ndarray, kind: str, dims, X_WS: np.ndarray, margin_m: float) -> np.ndarray:
    p = (points - X_WS[:3, 3]) @ X_WS[:3, :3]
    if kind == "box":
        return np.all(np.abs(p) <= np.asarray(dims, float) / 2 + margin_m, axis=1)
    if kind == "sphere":
        return np.linalg.norm(p, axis=1) <= dims[0] + margin_m
    r, length = dims
    if kind == "cylinder":
        return (np.hypot(p[:, 0], p[:, 1]) <= r + margin_m) & (np.abs(p[:, 2]) <= length / 2 + margin_m)
    if kind == "capsule":
        z = np.clip(p[:, 2], -length / 2, length / 2)
        return np.hypot(np.hypot(p[:, 0], p[:, 1]), p[:, 2] - z) <= r + margin_m
    raise ValueError(f"unsupported shape {kind!r}")


def depth_sigmas(sensor, z_m: np.ndarray) -> np.ndarray:
    """The sensor's depth sigma (metres) at each depth of `z_m` (0 for a perfect sensor): constant
    for the Gaussian model, growing as z^2 for structured light (`SensorSpec.depth_sigma_at_m`)."""
    z = np.asarray(z_m, float)
    if sensor is None:
        return np.zeros(z.shape)
    if sensor.kind == "gaussian":
        return np.full(z.shape, sensor.depth_sigma_at_m(1.0))
    return sensor.depth_sigma_at_m(1.0) * z * z


def fill_row_holes(depth_m: np.ndarray, max_px: int, *, shadow_px_m: float | None = None, slack_px: int = 3) -> np.ndarray:
    """A copy of a depth image whose runs of at most `max_px` pixels without depth along a row, with
    depth at both ends, are filled: with the farther end's depth when the run is the projector's
    shadow of a structured-light camera (projector on the image's +x side: the far surface on the
    run's left, the nearer object on its right, and the run as wide as the disparity jump
    `shadow_px_m` * (1/z_near - 1/z_far) pixels within `slack_px`, where `shadow_px_m` is the
    focal length times the baseline), else with the nearer end's (a dropout on an object's edge or
    face: what lies behind it stays hidden). Longer runs, and runs open at an end, stay empty."""
    d = depth_m.astype(np.float64, copy=True)
    bad = ~np.isfinite(d) & ~np.isposinf(d)
    if max_px <= 0 or not bad.any():
        return d
    cols = np.arange(d.shape[1])
    for r in np.flatnonzero(bad.any(axis=1)):
        row, miss = d[r], bad[r]
        good = np.flatnonzero(~miss)
        if good.size < 2:
            continue
        j = np.searchsorted(good, cols[miss])  # the next good column after each hole pixel
        ok = (j > 0) & (j < good.size)
        left, right = good[np.clip(j - 1, 0, good.size - 1)], good[np.clip(j, 0, good.size - 1)]
        width = right - left - 1
        ok &= width <= max_px
        dl, dr = row[left], row[right]
        fill = np.minimum(dl, dr)
        if shadow_px_m is not None:
            with np.errstate(divide="ignore", invalid="ignore"):
                jump = shadow_px_m * (1.0 / dr - 1.0 / dl)
            shadow = (dl > dr) & (np.abs(width - jump) <= slack_px)
            fill = np.where(shadow, dl, fill)
        row[cols[miss][ok]] = fill[ok]
    return d


def robot_explains(points: np.ndarray, *, spec: SceneSpec, q: np.ndarray | None, held: HeldCan | None,
                   opening_m: float, margin_m: float) -> np.ndarray:
    """Which points lie on the robot (its collision parts at `q`, grown by `margin_m`, a held can
    with them)."""
    if q is None or len(points) == 0:
        return np.zeros(len(points), bool)
    from scenes.collision.world import robot_parts
    from scenes.robot_model import load_robot

    robot = load_robot(spec.robot)
    held_can = None if held is None else (held.X_GC, (spec.can.radius_m, spec.can.height_m))
    X_WB = robot.link_poses(np.asarray(q, float))
    hit = np.zeros(len(points), bool)
    for part in robot_parts(robot, opening_m, held_can):
        X_WS = X_WB[part.body] @ part.X_BS
        hit |= inside(points, part.kind, part.dims, X_WS, margin_m)
    return hit
