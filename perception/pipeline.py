"""The whole perception pass on a scene: observe, then detect the cans in the top camera."""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from perception.grasps import CanDetection, FrameAnalysis, PerceptionParams, analyse_frame, detect_cans
from perception.observe import observe
from scenes.errors import SuiteError
from scenes.scene import Scene
from scenes.sensor import SENSOR_PRESETS, SensorSpec

#: the camera whose frame gives the grasps (the paper's: one camera above the plate)
GRASP_CAMERA = "top"
#: the pipelines: the paper's (the default) and the robust one (`perception.robust`)
PIPELINES = ("paper", "robust")
#: the segmentations of `PerceptionParams`: the paper's HSV rule, or colour-free plane removal
SEGMENTATIONS = ("color", "geometric")
#: a scene's sensor noise is drawn from a generator seeded with (scene seed, this), so `perceive`
#: and the executions that perceive their grasps see the same frames of the same scene
NOISE_STREAM = 7919
#: the Gaussian sensor's (`--depth-noise-m`) fraction of dropped depth pixels
GAUSSIAN_DROP_FRACTION = 0.01


def noise_rng(scene_seed: int, *extra: int) -> np.random.Generator:
    """The sensor noise's generator for a scene (`extra`: e.g. the frame's index in a closed loop)."""
    return np.random.default_rng([scene_seed, NOISE_STREAM, *extra])


@dataclasses.dataclass(frozen=True)
class PerceptionSetup:
    """How grasps are perceived: the pipeline, the segmentation, and the cameras' sensor.

    Invalid values raise `SuiteError` naming the value and what is allowed.

    Attributes:
        pipeline: `paper` (the seed paper's, the default) or `robust` (`perception.robust`).
        segmentation: `color` (the paper's HSV rule, the default) or `geometric`.
        sensor: a named sensor model (`scenes.sensor.SENSOR_PRESETS`, e.g. `kinect-v1`), or None.
        depth_noise_m: instead of a named sensor, Gaussian depth noise of this sigma (metres)
            with 1% of the pixels dropped; 0 (and no `sensor`): the spec's cameras, by default a
            perfect sensor.
    """

    pipeline: str = "paper"
    segmentation: str = "color"
    sensor: str | None = None
    depth_noise_m: float = 0.0

    def __post_init__(self):
        if self.pipeline not in PIPELINES:
            raise SuiteError(f"unknown perception pipeline {self.pipeline!r}; allowed: {', '.join(PIPELINES)}")
        if self.segmentation not in SEGMENTATIONS:
            raise SuiteError(f"unknown segmentation {self.segmentation!r}; allowed: {', '.join(SEGMENTATIONS)}")
        if self.sensor is not None and self.sensor not in SENSOR_PRESETS:
            raise SuiteError(f"unknown sensor {self.sensor!r}; allowed: {', '.join(sorted(SENSOR_PRESETS))}")
        if not (math.isfinite(self.depth_noise_m) and self.depth_noise_m >= 0):
            raise SuiteError(f"depth noise must be a finite number of metres >= 0, got {self.depth_noise_m}")
        if self.sensor is not None and self.depth_noise_m > 0:
            raise SuiteError(f"sensor {self.sensor} cannot go with a Gaussian depth noise of {self.depth_noise_m} m: "
                             "choose one sensor model")

    def sensor_spec(self) -> SensorSpec | None:
        """The sensor model this setup names (None: the spec's cameras')."""
        if self.sensor is not None:
            return SENSOR_PRESETS[self.sensor]
        if self.depth_noise_m > 0:
            return SensorSpec(kind="gaussian", depth_sigma_m=self.depth_noise_m, drop_fraction=GAUSSIAN_DROP_FRACTION)
        return None

    def params(self) -> PerceptionParams:
        return PerceptionParams(segmentation=self.segmentation)

    def label(self) -> str:
        """A short name for tables: e.g. `robust, kinect-v1` or `paper, clean`."""
        noise = self.sensor or (f"Gaussian {1e3 * self.depth_noise_m:g} mm" if self.depth_noise_m > 0 else "clean")
        seg = "" if self.segmentation == "color" else f", {self.segmentation}"
        return f"{self.pipeline}{seg}, {noise}"

    def to_json(self) -> dict:
        return dataclasses.asdict(self)


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


def perceive_with(scene: Scene, *, setup: PerceptionSetup) -> PerceptionResult:
    """`perceive` as `setup` says, its noise drawn from `noise_rng(scene.seed)` (as `perceive`'s CLI)."""
    return perceive(scene, rng=noise_rng(scene.seed), params=setup.params(), pipeline=setup.pipeline,
                    sensor=setup.sensor_spec())


def detect_in_frames(images, spec, *, setup: PerceptionSetup, rng: np.random.Generator):
    """Detections in clean rendered frames (camera name -> `CameraImage`, the top camera's and, for
    the robust pipeline's side check, the side cameras') after `setup`'s sensor model (the spec's
    cameras' when it names none)."""
    from perception.observe import sense
    from perception.side_view import SIDE_CAMERAS

    sensor = setup.sensor_spec() or spec.cameras.sensor
    names = [GRASP_CAMERA] + ([n for n in SIDE_CAMERAS if n in images] if setup.pipeline == "robust" else [])
    frames = {n: images[n] if sensor is None else sense(images[n], sensor=sensor, rng=rng) for n in names}
    detections, _, _ = detect(frames[GRASP_CAMERA], spec, params=setup.params(), pipeline=setup.pipeline,
                              side_images={n: im for n, im in frames.items() if n != GRASP_CAMERA})
    return detections


def detect(image, spec, *, params: PerceptionParams = PerceptionParams(), pipeline: str = "paper", side_images=None):
    """One top-camera frame through the named pipeline: (detections, frame analysis, the plate noise
    the robust pipeline measured in metres, None for the paper's). The robust pipeline checks
    upright cans' sides in `side_images` (camera name -> frame) when given; the paper's ignores them."""
    if pipeline == "robust":
        from perception.robust import RobustParams, detect_cans_robust

        return detect_cans_robust(image, spec, RobustParams(base=params), side_images=side_images)
    detections, fa = detect_cans(image, spec, params)
    return detections, fa, None
