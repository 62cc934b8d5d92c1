"""The whole perception pass on a scene: observe, then detect the cans in the top camera."""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from perception.grasps import CanDetection, FrameAnalysis, PerceptionParams, analyse_frame, detect_cans
from perception.observe import observe
from scenes.errors import SuiteError
from scenes.scene import Scene
from scenes.sensor import SensorSpec

#: the camera whose frame gives the grasps (the paper's: one camera above the plate)
GRASP_CAMERA = "top"
#: the pipelines: the paper's (the default) and the robust one (`perception.robust`)
PIPELINES = ("paper", "robust")


@dataclasses.dataclass(frozen=True)
class PerceptionResult:
    """Detections of one scene, how long it took, and the frames' intermediate results.

    Attributes:
        detections: the cans found in the top camera's frame.
        render_time_s: rendering (scene build included), seconds.
        process_time_s: everything after rendering for the grasp camera, seconds.
        frames: camera name -> its analysis (the grasp camera always; the others when asked).
    """

    detections: tuple[CanDetection, ...]
    render_time_s: float
    process_time_s: float
    frames: dict[str, FrameAnalysis]
    plate_noise_m: float | None = None


def perceive(
    scene: Scene,
    *,
    depth_noise_m: float = 0.0,
    rng: np.random.Generator | None = None,
    all_cameras: bool = False,
    params: PerceptionParams = PerceptionParams(),
    pipeline: str = "paper",
    sensor: SensorSpec | None = None,
) -> PerceptionResult:
    """Render the scene and detect its cans.

    Args:
        scene: the scene.
        depth_noise_m: Gaussian depth noise sigma (metres), with 1% of the pixels dropped; 0 for
            a perfect sensor.
        rng: the noise's generator (required when `depth_noise_m` > 0).
        all_cameras: also crop, segment and analyse the other cameras (for the debug images). The
            robust pipeline renders the side cameras anyway (its side check).
        params: pipeline settings (the robust pipeline runs with them as its base).
        pipeline: `paper` or `robust`.
        sensor: the cameras' sensor model for this pass (default: the spec's, or `depth_noise_m`).
    """
    if pipeline not in PIPELINES:
        raise SuiteError(f"unknown perception pipeline {pipeline!r}; allowed: {', '.join(PIPELINES)}")
    from perception.side_view import SIDE_CAMERAS

    cams = None if all_cameras else [GRASP_CAMERA] + ([c for c in SIDE_CAMERAS if c in scene.spec.cameras.poses]
                                                      if pipeline == "robust" else [])
    t0 = time.perf_counter()
    images = observe(scene, cameras=cams, depth_noise_m=depth_noise_m, rng=rng, sensor=sensor)
    t1 = time.perf_counter()
    detections, fa, noise = detect(images[GRASP_CAMERA], scene.spec, params=params, pipeline=pipeline,
                                   side_images={n: im for n, im in images.items() if n in SIDE_CAMERAS})
    t2 = time.perf_counter()
    frames = {GRASP_CAMERA: fa}
    for name, image in images.items():
        if name != GRASP_CAMERA and all_cameras:
            frames[name] = analyse_frame(image, scene.spec, params)
    return PerceptionResult(tuple(detections), t1 - t0, t2 - t1, frames, noise)


def detect(image, spec, *, params: PerceptionParams = PerceptionParams(), pipeline: str = "paper", side_images=None):
    """One top-camera frame through the named pipeline: (detections, frame analysis, the plate noise
    the robust pipeline measured in metres, None for the paper's). The robust pipeline checks
    upright cans' sides in `side_images` (camera name -> frame) when given; the paper's ignores them."""
    if pipeline == "robust":
        from perception.robust import RobustParams, detect_cans_robust

        return detect_cans_robust(image, spec, RobustParams(base=params), side_images=side_images)
    detections, fa = detect_cans(image, spec, params)
    return detections, fa, None
