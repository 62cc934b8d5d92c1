"""Render the scene's RGB-D cameras with Drake's RenderEngineVtk (headless, on the CPU)."""

from __future__ import annotations

import dataclasses

import numpy as np

from scenes.drake_scene import DrakeScene, build_drake_scene
from scenes.scene import Scene


@dataclasses.dataclass(frozen=True)
class CameraImage:
    """One camera's frame.

    Attributes:
        name: the camera's name in the spec.
        rgb: colour image (H, W, 3) uint8.
        depth_m: depth along the optical axis (H, W) float32, metres; inf where nothing is seen
            within the clipping range.
        X_WC: camera pose in the world (4, 4), Drake's convention (+z forward, +y down).
        K: pinhole intrinsics (3, 3), pixels.
    """

    name: str
    rgb: np.ndarray
    depth_m: np.ndarray
    X_WC: np.ndarray
    K: np.ndarray


def render(
    scene: Scene,
    *,
    cameras: list[str] | None = None,
    drake_scene: DrakeScene | None = None,
    q_iiwa: np.ndarray | None = None,
) -> dict[str, CameraImage]:
    """Render colour and depth from the named cameras (all by default).

    Args:
        scene: the scene; built in "sim" mode unless `drake_scene` is given.
        cameras: which cameras; all of the spec's by default.
        drake_scene: an already built scene with cameras, to reuse across calls.
        q_iiwa: the arm's joint positions (rad) while rendering; Drake's default (zeros) if None.
    """
    ds = drake_scene or build_drake_scene(scene, mode="sim", cameras=True)
    names = list(ds.cameras) if cameras is None else cameras
    unknown = [n for n in names if n not in ds.cameras]
    if unknown:
        from scenes.errors import SuiteError

        raise SuiteError(f"unknown camera {unknown[0]!r}; allowed: {sorted(ds.cameras)}")
    context = ds.diagram.CreateDefaultContext()
    if q_iiwa is not None:
        plant_context = ds.plant.GetMyMutableContextFromRoot(context)
        ds.plant.SetPositions(plant_context, ds.iiwa, np.asarray(q_iiwa, float))
    return render_context(ds, context, cameras=names)


def render_context(ds: DrakeScene, context, *, cameras: list[str] | None = None) -> dict[str, CameraImage]:
    """Render the named cameras (all by default) of a built scene in the state of `context`
    (the diagram's root context, e.g. a running simulation's)."""
    out = {}
    for name in (list(ds.cameras) if cameras is None else cameras):
        sensor = ds.cameras[name]
        sc = sensor.GetMyContextFromRoot(context)
        rgba = sensor.color_image_output_port().Eval(sc).data
        depth = sensor.depth_image_32F_output_port().Eval(sc).data
        info = sensor.default_color_render_camera().core().intrinsics()
        out[name] = CameraImage(
            name=name,
            rgb=np.array(rgba[:, :, :3], dtype=np.uint8),
            depth_m=np.array(depth[:, :, 0], dtype=np.float32),
            X_WC=ds.X_WCameras[name].GetAsMatrix4(),
            K=np.array(info.intrinsic_matrix()),
        )
    return out


def render_overview(scene: Scene, *, q_iiwa: np.ndarray | None = None, width_px: int = 960,
                    height_px: int = 720) -> np.ndarray:
    """A 3D view of the whole station (robot, plate, bin, obstacles) from an oblique camera.

    The camera looks at the middle of base, plate and bin (of the base and the middle of the
    obstacles in a world without them) from 2.4 m away, 40 degrees above the
    table, from the side the plate and bin face (so the robot does not hide them), or from the
    robot's side when a shelf's back panel would hide the plate, and from the bin's side of a tall
    window wall (through the window).

    Returns:
        The colour image (H, W, 3) uint8.
    """
    from scenes.spec_parts import CameraPose

    spec = scene.spec
    pts = np.array([[0.0, 0.0], *spec.work_xy_m()], float)
    target = np.array([*pts.mean(axis=0), 0.25])
    facing = pts[1:].mean(axis=0)
    az = float(np.arctan2(facing[1], facing[0])) if np.linalg.norm(facing) > 1e-6 else 0.0
    az -= 0.6  # a little to the side, so depth reads
    if any(o.name.startswith("shelf") for o in spec.extra):
        az += np.pi  # a shelf's back panel faces outward: look from the robot's side instead
    d, el = 2.4, np.radians(40.0)
    if spec.bin is not None and any(o.name == "wall_lintel" for o in spec.extra):
        # a tall window wall hides the bin behind it: look through the window from the bin's side
        az, el = float(np.arctan2(spec.bin.center_xy_m[1], spec.bin.center_xy_m[0])) + 0.5, np.radians(35.0)
    eye = target + d * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    cams = dataclasses.replace(spec.cameras, width_px=width_px, height_px=height_px,
                               poses={"overview": CameraPose(tuple(eye), tuple(target))})
    viewed = dataclasses.replace(scene, spec=dataclasses.replace(spec, cameras=cams))
    return render(viewed, cameras=["overview"], q_iiwa=q_iiwa)["overview"].rgb
