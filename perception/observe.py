"""Observe: render the scene's RGB-D cameras, optionally with a noisy depth sensor."""

from __future__ import annotations

import dataclasses

import numpy as np

from scenes.render import CameraImage, render
from scenes.scene import Scene

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
    depth = image.depth_m.astype(np.float32, copy=True)
    if sigma_m > 0:
        depth += rng.normal(0.0, sigma_m, size=depth.shape).astype(np.float32)
    if drop_fraction > 0:
        depth[rng.random(depth.shape) < drop_fraction] = np.nan
    return dataclasses.replace(image, depth_m=depth)


def observe(
    scene: Scene,
    *,
    cameras: list[str] | None = None,
    depth_noise_m: float = 0.0,
    rng: np.random.Generator | None = None,
    drake_scene=None,
) -> dict[str, CameraImage]:
    """Render the named cameras (all by default); with `depth_noise_m` > 0 the depth is noisy.

    Args:
        scene: the scene to look at.
        cameras: camera names from the spec; all of them if None.
        depth_noise_m: Gaussian depth noise sigma (metres); 0 for a perfect sensor. Noise also
            drops `DEFAULT_DROP_FRACTION` of the depth pixels.
        rng: required when `depth_noise_m` > 0.
        drake_scene: an already built scene with cameras, to reuse across calls.
    """
    images = render(scene, cameras=cameras, drake_scene=drake_scene)
    if depth_noise_m > 0:
        if rng is None:
            raise ValueError("observe: depth noise needs an explicit np.random.Generator")
        images = {n: add_depth_noise(im, sigma_m=depth_noise_m, rng=rng) for n, im in images.items()}
    return images
