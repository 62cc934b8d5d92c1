"""Observe: render the scene's RGB-D cameras through their sensor model (`scenes.sensor`)."""

from __future__ import annotations

import dataclasses

import numpy as np

from scenes.render import CameraImage, render
from scenes.scene import Scene
from scenes.sensor import SensorSpec, apply_sensor, gaussian_depth

#: fraction of depth pixels a noisy sensor returns no value for (NaN), e.g. specular dropouts
DEFAULT_DROP_FRACTION = 0.01


def add_depth_noise(
    image: CameraImage,
    *,
    sigma_m: float,
    drop_fraction: float = DEFAULT_DROP_FRACTION,
    rng: np.random.Generator,
) -> CameraImage:
    """A copy of `image` whose depth has Gaussian noise and dropped (NaN) pixels.

    Args:
        image: the clean frame.
        sigma_m: standard deviation of the additive Gaussian depth noise, metres.
        drop_fraction: fraction of pixels (chosen uniformly) that lose their depth.
        rng: the source of randomness.
    """
    return dataclasses.replace(image, depth_m=gaussian_depth(image.depth_m, sigma_m=sigma_m,
                                                             drop_fraction=drop_fraction, rng=rng))


def sense(image: CameraImage, *, sensor: SensorSpec, rng: np.random.Generator) -> CameraImage:
    """A copy of a clean frame as the sensor returns it (noisy colour and depth, NaN for no depth)."""
    rgb, depth = apply_sensor(image.rgb, image.depth_m, K=image.K, sensor=sensor, rng=rng)
    return dataclasses.replace(image, rgb=rgb, depth_m=depth)


def observe(
    scene: Scene,
    *,
    cameras: list[str] | None = None,
    depth_noise_m: float = 0.0,
    rng: np.random.Generator | None = None,
    drake_scene=None,
    sensor: SensorSpec | None = None,
) -> dict[str, CameraImage]:
    """Render the named cameras (all by default) as their sensor sees them.

    The sensor is `sensor` if given, else the spec's cameras' (`CameraSpec.sensor`), else, with
    `depth_noise_m` > 0, Gaussian depth noise of that sigma with `DEFAULT_DROP_FRACTION` of the
    pixels dropped; with none of them, the frames are the clean renders.

    Args:
        scene: the scene to look at.
        cameras: camera names from the spec; all of them if None.
        depth_noise_m: Gaussian depth noise sigma (metres); 0 for a perfect sensor.
        rng: required when a sensor model applies.
        drake_scene: an already built scene with cameras, to reuse across calls.
        sensor: a sensor model for this call, overriding the spec's.
    """
    images = render(scene, cameras=cameras, drake_scene=drake_scene)
    if sensor is None:
        sensor = scene.spec.cameras.sensor
    if sensor is None and depth_noise_m > 0:
        sensor = SensorSpec(kind="gaussian", depth_sigma_m=depth_noise_m, drop_fraction=DEFAULT_DROP_FRACTION)
    if sensor is None:
        return images
    if rng is None:
        raise ValueError("observe: a sensor model needs an explicit np.random.Generator")
    return {n: sense(im, sensor=sensor, rng=rng) for n, im in images.items()}
