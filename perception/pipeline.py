"""The whole perception pass on a scene: observe, then detect the cans in the top camera (and, for
the robust pipeline's side check, see their sides in the side cameras)."""

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
#: the pipelines: the paper's (the default), the robust one (`perception.robust`) with its side
#: check, and the robust one on the top camera alone (no side check), to compare on the same rig
PIPELINES = ("paper", "robust", "robust-top")
#: the cameras each pipeline looks through (the robust pipeline's side cameras when the spec has them)
PIPELINE_CAMERAS = {"paper": ("top",), "robust": ("top", "front", "back"), "robust-top": ("top",)}
#: the segmentations of `PerceptionParams`: the paper's HSV rule, or colour-free plane removal
SEGMENTATIONS = ("color", "geometric")
#: a scene's sensor noise is drawn from a generator seeded with (scene seed, this), so `perceive`
#: and the executions that perceive their grasps see the same frames of the same scene
NOISE_STREAM = 7919
#: the Gaussian sensor's (`--depth-noise-m`) fraction of dropped depth pixels
GAUSSIAN_DROP_FRACTION = 0.01
#: What a scene without a plate or a can model is told (`SceneSpec.require`).
NEEDED_BY = "perception (it crops the plate and looks for cans on it)"


def noise_rng(scene_seed: int, *extra: int) -> np.random.Generator:
    """The sensor noise's generator for a scene (`extra`: e.g. the frame's index in a closed loop)."""
    return np.random.default_rng([scene_seed, NOISE_STREAM, *extra])


@dataclasses.dataclass(frozen=True)
class PerceptionSetup:
    """How grasps are perceived: the pipeline, the segmentation, and the cameras' sensor.

    Invalid values raise `SuiteError` naming the value and what is allowed.

    Attributes:
        pipeline: `paper` (the seed paper's, the default, top camera), `robust` (`perception.robust`,
            top camera and the side cameras for its side check) or `robust-top` (the robust
            pipeline on the top camera alone).
        segmentation: `color` (the paper's HSV rule, the default) or `geometric`.
        sensor: a named sensor model (`scenes.sensor.SENSOR_PRESETS`, e.g. `kinect-v1`), or None.
        depth_noise_m: instead of a named sensor, Gaussian depth noise of this sigma (metres)
            with 1% of the pixels dropped; 0 (and no `sensor`): the spec's cameras, by default a
            perfect sensor.
        correlation_px: the sensor's depth noise correlated over this many pixels (0: independent;
            `scenes.sensor.SensorSpec.correlation_px`); needs `sensor` or `depth_noise_m`.
        noise_scale: the sensor's depth noise sigma times this (1: as named); needs `sensor` or
            `depth_noise_m`.
    """

    pipeline: str = "paper"
    segmentation: str = "color"
    sensor: str | None = None
    depth_noise_m: float = 0.0
    correlation_px: float = 0.0
    noise_scale: float = 1.0

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
        if not (isinstance(self.correlation_px, (int, float)) and math.isfinite(self.correlation_px)
                and self.correlation_px >= 0):
            raise SuiteError(f"noise correlation length must be a finite number of pixels >= 0, got {self.correlation_px}")
        if not (isinstance(self.noise_scale, (int, float)) and math.isfinite(self.noise_scale) and self.noise_scale > 0):
            raise SuiteError(f"noise scale must be a finite number > 0, got {self.noise_scale}")
        if (self.correlation_px > 0 or self.noise_scale != 1) and self.sensor is None and not self.depth_noise_m > 0:
            raise SuiteError(f"noise correlation {self.correlation_px:g} px and scale {self.noise_scale:g} need a sensor "
                             "model: a named sensor or a Gaussian depth noise")

    def sensor_spec(self) -> SensorSpec | None:
        """The sensor model this setup names, its noise scaled and correlated as set (None: the
        spec's cameras')."""
        if self.sensor is not None:
            base = SENSOR_PRESETS[self.sensor]
        elif self.depth_noise_m > 0:
            base = SensorSpec(kind="gaussian", depth_sigma_m=self.depth_noise_m, drop_fraction=GAUSSIAN_DROP_FRACTION)
        else:
            return None
        if self.correlation_px == 0 and self.noise_scale == 1:
            return base
        return base.with_noise(scale=self.noise_scale, correlation_px=self.correlation_px)

    def cameras(self) -> tuple[str, ...]:
        """The cameras the pipeline looks through (`PIPELINE_CAMERAS`)."""
        return PIPELINE_CAMERAS[self.pipeline]

    def params(self) -> PerceptionParams:
        return PerceptionParams(segmentation=self.segmentation)

    def label(self) -> str:
        """A short name for tables, with the pipeline's cameras: e.g. `robust (top, front, back),
        kinect-v1`, `paper (top), geometric, kinect-v1 x2, correlated 4 px` or `paper (top), clean`."""
        noise = self.sensor or (f"Gaussian {1e3 * self.depth_noise_m:g} mm" if self.depth_noise_m > 0 else "clean")
        if self.noise_scale != 1:
            noise += f" x{self.noise_scale:g}"
        if self.correlation_px > 0:
            noise += f", correlated {self.correlation_px:g} px"
        seg = "" if self.segmentation == "color" else f", {self.segmentation}"
        return f"{self.pipeline} ({', '.join(self.cameras())}){seg}, {noise}"

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
            robust pipeline renders the side cameras anyway (its side check); the others render
            the top camera only.
        params: pipeline settings (the robust pipelines run with them as their base).
        pipeline: `paper`, `robust` or `robust-top` (`PIPELINES`).
        sensor: the cameras' sensor model for this pass (default: the spec's, or `depth_noise_m`).
    """
    if pipeline not in PIPELINES:
        raise SuiteError(f"unknown perception pipeline {pipeline!r}; allowed: {', '.join(PIPELINES)}")
    scene.spec.require("plate", "can", needed_by=NEEDED_BY)  # before rendering
    cams = None if all_cameras else [GRASP_CAMERA] + [c for c in side_cameras(pipeline) if c in scene.spec.cameras.poses]
    t0 = time.perf_counter()
    images = observe(scene, cameras=cams, depth_noise_m=depth_noise_m, rng=rng, sensor=sensor)
    t1 = time.perf_counter()
    detections, fa, noise = detect(images[GRASP_CAMERA], scene.spec, params=params, pipeline=pipeline,
                                   side_images={n: im for n, im in images.items() if n in side_cameras(pipeline)})
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
    cameras' when it names none). Only the frames of the pipeline's cameras are sensed, in the
    order top, then its side cameras."""
    from perception.observe import sense

    sensor = setup.sensor_spec() or spec.cameras.sensor
    names = [GRASP_CAMERA] + [n for n in side_cameras(setup.pipeline) if n in images]
    frames = {n: images[n] if sensor is None else sense(images[n], sensor=sensor, rng=rng) for n in names}
    detections, _, _ = detect(frames[GRASP_CAMERA], spec, params=setup.params(), pipeline=setup.pipeline,
                              side_images={n: im for n, im in frames.items() if n != GRASP_CAMERA})
    return detections


def side_cameras(pipeline: str) -> tuple[str, ...]:
    """The side cameras a pipeline looks through (none but `robust`'s)."""
    return tuple(c for c in PIPELINE_CAMERAS[pipeline] if c != GRASP_CAMERA)


def detect(image, spec, *, params: PerceptionParams = PerceptionParams(), pipeline: str = "paper", side_images=None):
    """One top-camera frame through the named pipeline: (detections, frame analysis, the plate noise
    the robust pipelines measured in metres, None for the paper's). The robust pipeline checks
    upright cans' sides in `side_images` (camera name -> frame; it logs once when there are none);
    `robust-top` and the paper's ignore them."""
    if pipeline not in PIPELINES:
        raise SuiteError(f"unknown perception pipeline {pipeline!r}; allowed: {', '.join(PIPELINES)}")
    spec.require("plate", "can", needed_by=NEEDED_BY)
    if pipeline in ("robust", "robust-top"):
        from perception.robust import RobustParams, detect_cans_robust

        top_only = pipeline == "robust-top"
        side = None if top_only else {n: im for n, im in (side_images or {}).items() if n in side_cameras(pipeline)}
        return detect_cans_robust(image, spec, RobustParams(base=params, side_check=not top_only), side_images=side)
    detections, fa = detect_cans(image, spec, params)
    return detections, fa, None
