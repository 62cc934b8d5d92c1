"""Depth-camera sensor models: what a real RGB-D camera does to the rendered (perfect) frame.

A camera's `sensor` (`scenes.spec_parts.CameraSpec.sensor`, off by default) names one of two models:

- `gaussian`: additive Gaussian depth noise of one sigma everywhere, and a fraction of pixels
  dropped at random (the suite's first, simple option; kept for comparison).
- `structured-light`: a triangulating sensor (Kinect v1 class) modelled in disparity, with its
  parameters from Khoshelham & Elberink, "Accuracy and Resolution of Kinect Depth Data for Indoor
  Mapping Applications", Sensors 12(2):1437-1454, 2012 (doi:10.3390/s120201437). Their depth model
  is 1/Z = (m / (f b)) d' + const for the integer normalised disparity d', calibrated
  m / (f b) = 2.85e-5 cm^-1 (2.85e-3 m^-1), and their random error is
  sigma_Z = (m / (f b)) Z^2 sigma_d' with sigma_d' = 1/2 (in d' units): sigma_Z = 1.43e-3 Z^2
  (metres), about 0.76 mm at the top camera's plate (0.73 m) and 3.6 cm at 5 m (their "about
  4 cm at the maximum range"). Here, in inverse depth w = 1/Z:
    1. Gaussian noise of sigma (in d' units) on w, then rounding w to whole d' steps
       (quantization: the depth step is 2.85e-3 Z^2, 1.5 mm at 0.73 m, their 7 cm at 5 m). The
       noise before rounding is sqrt(sigma_d'^2 - 1/12), so that noise and rounding together
       give their measured sigma_d' = 1/2.
    2. Invalid (NaN) pixels: the projector's shadow (points the projector, `baseline_m` to the
       image's +x side of the camera, cannot see past a nearer object: a band as wide as the
       disparity jump, f b (1/Z_near - 1/Z_far) pixels), grazing surfaces (incidence angle above
       `max_incidence_deg`: the pattern is smeared; the angle is the surface's own, from
       differences that do not cross a depth edge), pixels near a depth edge (within
       `edge_band_px` pixels, on both sides, of a disparity jump of more than `edge_jump_px`
       between neighbours of the clean frame, the far surface and the background included; each
       dropped with probability `edge_drop_probability`: the matcher's correlation window, several
       pixels wide, straddles the edge and holds two disparities), and a fraction dropped anywhere
       (specular or dark spots). The grazing angle once came from central differences, which
       straddle every depth edge: every edge pixel read as grazing and the edge rule decided
       nothing (on a `clutter` top frame, 0 of about 7000 edge pixels were dropped by it alone).
    3. Colour: additive Gaussian noise on each 8-bit channel (`rgb_sigma`).
  The shadow, grazing-angle and edge parameters and the colour noise are this model's choices,
  not measured by Khoshelham & Elberink; the noise and quantization are theirs.

Both kinds may have spatially correlated noise (`correlation_px` > 0; 0, the default, is
independent per pixel): the noise field (the Gaussian depth noise, or the structured-light
disparity noise before rounding) is white noise smoothed by a Gaussian kernel and rescaled so that
each pixel's sigma is unchanged. The correlation length L (pixels) is where the field's
autocorrelation falls to 1/e: a Gaussian kernel of sigma s gives the autocorrelation
exp(-r^2 / (4 s^2)), so s = L / 2 and the autocorrelation is exp(-(r / L)^2). A structured-light
sensor's errors come in patches because its matcher correlates a window of the speckle pattern:
neighbouring windows share most of their pixels. The length is this model's choice (Khoshelham &
Elberink give none); `SensorSpec.with_noise` sets it and scales the sigma.

Every model draws from an explicit `np.random.Generator`.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Literal

import cv2
import numpy as np

from scenes.schema import NonNeg, NonNegInt, Pos, Unit

#: the sensor models a camera may have
SENSOR_KINDS = ("gaussian", "structured-light")


@dataclasses.dataclass(frozen=True)
class SensorSpec:
    """A camera's sensor model (see the module docstring for each kind and its sources).

    Attributes:
        kind: `gaussian` or `structured-light`.
        depth_sigma_m: `gaussian`: the depth noise's standard deviation, metres.
        drop_fraction: fraction of depth pixels dropped anywhere (NaN), both kinds.
        inverse_depth_step_per_m: `structured-light`: m / (f b), the change of 1/Z per step of
            the normalised disparity, 1/metres (Khoshelham & Elberink: 2.85e-3).
        disparity_sigma: `structured-light`: the disparity's total random error (noise and
            rounding together), in normalised disparity steps (Khoshelham & Elberink: 1/2).
        baseline_m: `structured-light`: camera-projector baseline, metres (Kinect v1: 0.075),
            the projector on the image's +x side.
        max_incidence_deg: `structured-light`: surfaces seen more obliquely than this return no depth.
        edge_jump_px, edge_band_px, edge_drop_probability: `structured-light`: pixels within
            `edge_band_px` of a disparity jump larger than `edge_jump_px` pixels, on both sides,
            are dropped with this probability (the band's 2 px: this model's choice, a matcher's
            window several pixels wide straddling the edge; it was 1 px, and decided nothing).
        rgb_sigma: `structured-light`: colour noise, 8-bit levels (0 for none).
        correlation_px: both kinds: the depth noise's correlation length, pixels (its
            autocorrelation falls to 1/e there; 0: independent per pixel).
    """

    kind: Literal["gaussian", "structured-light"]
    depth_sigma_m: NonNeg = 0.0
    drop_fraction: Unit = 0.01
    inverse_depth_step_per_m: Pos = 2.85e-3
    disparity_sigma: NonNeg = 0.5
    baseline_m: Pos = 0.075
    max_incidence_deg: Pos = 75.0
    edge_jump_px: Pos = 1.0
    edge_band_px: NonNegInt = 2
    edge_drop_probability: Unit = 0.5
    rgb_sigma: NonNeg = 2.0
    correlation_px: NonNeg = 0.0

    def depth_sigma_at_m(self, z_m: float) -> float:
        """The depth's standard deviation (metres) at distance `z_m` (noise and quantization)."""
        if self.kind == "gaussian":
            return self.depth_sigma_m
        return self.inverse_depth_step_per_m * self.disparity_sigma * z_m * z_m

    def with_noise(self, *, scale: float = 1.0, correlation_px: float | None = None) -> SensorSpec:
        """A copy whose depth noise sigma is `scale` times this one's (the Gaussian sigma, or the
        structured-light disparity's total error), with the correlation length `correlation_px`
        (pixels; None: this one's)."""
        if not (math.isfinite(scale) and scale > 0):
            raise ValueError(f"noise scale must be a finite number > 0, got {scale}")
        if correlation_px is not None and not (math.isfinite(correlation_px) and correlation_px >= 0):
            raise ValueError(f"noise correlation length must be a finite number of pixels >= 0, got {correlation_px}")
        return dataclasses.replace(self, depth_sigma_m=scale * self.depth_sigma_m,
                                   disparity_sigma=scale * self.disparity_sigma,
                                   correlation_px=self.correlation_px if correlation_px is None else float(correlation_px))


#: named sensors (`perceive --sensor NAME`); `kinect-v1` is Khoshelham & Elberink's calibration
SENSOR_PRESETS: dict[str, SensorSpec] = {
    "kinect-v1": SensorSpec(kind="structured-light"),
}


#: a correlated field's Gaussian kernel is cut at this many of its sigmas
KERNEL_TRUNCATE_SIGMAS = 4.0


def correlation_kernel_sigma_px(correlation_px: float) -> float:
    """The Gaussian kernel's sigma (pixels) that smooths white noise into a field whose
    autocorrelation is exp(-(r / correlation_px)^2): half the correlation length."""
    return 0.5 * correlation_px


def correlated_normal(shape: tuple[int, int], *, correlation_px: float, rng: np.random.Generator) -> np.ndarray:
    """A standard normal field (H, W) (each pixel's sigma 1) correlated over `correlation_px`
    pixels (see the module docstring); 0: independent per pixel. The white noise is drawn with a
    margin of the kernel's radius and cropped, so every pixel's sigma is exactly 1."""
    if correlation_px <= 0:
        return rng.standard_normal(shape)
    s = correlation_kernel_sigma_px(correlation_px)
    r = max(1, int(math.ceil(KERNEL_TRUNCATE_SIGMAS * s)))
    x = np.arange(-r, r + 1, dtype=np.float64)
    k = np.exp(-0.5 * (x / s) ** 2)
    k /= k.sum()
    h, w = shape
    white = rng.standard_normal((h + 2 * r, w + 2 * r))
    field = cv2.sepFilter2D(white, cv2.CV_64F, k, k, borderType=cv2.BORDER_CONSTANT)[r:r + h, r:r + w]
    # separable kernel: the 2-D kernel's sum of squares is the 1-D one's squared
    return field / float(np.sum(k * k))


def gaussian_depth(depth_m: np.ndarray, *, sigma_m: float, drop_fraction: float, rng: np.random.Generator,
                   correlation_px: float = 0.0) -> np.ndarray:
    """A copy of a depth image (H, W) with Gaussian noise (correlated over `correlation_px` pixels,
    0: independent) and `drop_fraction` of its pixels NaN."""
    depth = depth_m.astype(np.float32, copy=True)
    if sigma_m > 0 and correlation_px > 0:
        depth += (sigma_m * correlated_normal(depth.shape, correlation_px=correlation_px, rng=rng)).astype(np.float32)
    elif sigma_m > 0:
        depth += rng.normal(0.0, sigma_m, size=depth.shape).astype(np.float32)
    if drop_fraction > 0:
        depth[rng.random(depth.shape) < drop_fraction] = np.nan
    return depth


def projector_shadow(disparity_px: np.ndarray, *, eps_px: float = 0.25) -> np.ndarray:
    """Pixels (H, W) the projector cannot light: it sits on the image's +x side, so a pixel's
    projector column is u - d(u); a pixel is lit only if every pixel to its right maps to a
    projector column beyond its own (else a nearer surface there lies on its projector ray)."""
    h, w = disparity_px.shape
    d = np.where(np.isfinite(disparity_px), disparity_px, 0.0)
    p = np.arange(w, dtype=np.float64)[None, :] - d
    # running minimum of p over the pixels to the right of each pixel
    right_min = np.minimum.accumulate(p[:, ::-1], axis=1)[:, ::-1]
    beyond = np.full((h, w), np.inf)
    beyond[:, :-1] = right_min[:, 1:]
    return p > beyond - eps_px


def _own_side_difference(p: np.ndarray, axis: int) -> np.ndarray:
    """Per pixel, the one-sided difference of the points `p` (H, W, 3) along `axis` (forward or
    backward) whose depth change is the smaller: the difference on the pixel's own surface, which
    a central difference at a depth edge would not be (NaN where neither neighbour has depth)."""
    d = np.diff(p, axis=axis)
    pad_shape = list(p.shape)
    pad_shape[axis] = 1
    nan = np.full(pad_shape, np.nan)
    fwd = np.concatenate([d, nan], axis=axis)
    bwd = np.concatenate([nan, d], axis=axis)
    with np.errstate(invalid="ignore"):
        take_bwd = ~(np.abs(fwd[..., 2]) <= np.abs(bwd[..., 2])) & np.isfinite(bwd[..., 2])
    return np.where(take_bwd[..., None], bwd, fwd)


def incidence_deg(depth_m: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Angle (degrees, H x W) between each pixel's viewing ray and its surface's normal, from the
    clean depth's one-sided differences on the pixel's own side of any depth edge (NaN where no
    neighbour has depth)."""
    h, w = depth_m.shape
    z = np.where(np.isfinite(depth_m), depth_m, np.nan).astype(np.float64)
    u = np.arange(w, dtype=np.float64)[None, :]
    v = np.arange(h, dtype=np.float64)[:, None]
    p = np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], axis=-1)
    du = _own_side_difference(p, 1)
    dv = _own_side_difference(p, 0)
    n = np.cross(du, dv)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.abs(np.einsum("ijk,ijk->ij", n, p)) / (np.linalg.norm(n, axis=-1) * np.linalg.norm(p, axis=-1))
    return np.degrees(np.arccos(np.clip(cos, 0.0, 1.0)))


def dropout_causes(depth_m: np.ndarray, *, K: np.ndarray, sensor: SensorSpec) -> dict[str, np.ndarray]:
    """The structured-light model's deterministic reasons (boolean images, H x W) for a pixel of a
    clean depth image to return no depth: `unseen` (no surface), `shadow` (the projector's),
    `grazing` (incidence above `max_incidence_deg`) and `edge_band` (within `edge_band_px` of a
    disparity jump; each of these pixels is dropped with probability `edge_drop_probability`)."""
    z = depth_m.astype(np.float64)
    seen = np.isfinite(z) & (z > 0)
    f = float(K[0, 0])
    disparity = np.where(seen, f * sensor.baseline_m / np.where(seen, z, 1.0), np.nan)
    with np.errstate(invalid="ignore"):
        grazing = incidence_deg(depth_m, K) > sensor.max_incidence_deg
    # depth edges: a disparity jump between 4-neighbours larger than edge_jump_px (both pixels of the
    # pair, so both sides; no surface counts as disparity 0, so the background's edge is one too)
    d0 = np.where(seen, disparity, 0.0)
    jump = np.zeros(z.shape, bool)
    dx = np.abs(np.diff(d0, axis=1)) > sensor.edge_jump_px
    dy = np.abs(np.diff(d0, axis=0)) > sensor.edge_jump_px
    jump[:, :-1] |= dx
    jump[:, 1:] |= dx
    jump[:-1, :] |= dy
    jump[1:, :] |= dy
    if sensor.edge_band_px > 1:
        k = 2 * (sensor.edge_band_px - 1) + 1
        jump = cv2.dilate(jump.astype(np.uint8), np.ones((k, k), np.uint8)).astype(bool)
    if sensor.edge_band_px == 0:
        jump[:] = False
    return {"unseen": ~seen, "shadow": projector_shadow(disparity), "grazing": grazing, "edge_band": jump}


def structured_light_depth(depth_m: np.ndarray, *, K: np.ndarray, sensor: SensorSpec,
                           rng: np.random.Generator) -> np.ndarray:
    """The depth a structured-light sensor returns for a clean depth image (H, W), metres; NaN
    where it returns none (see the module docstring)."""
    z = depth_m.astype(np.float64)
    causes = dropout_causes(depth_m, K=K, sensor=sensor)
    seen = ~causes["unseen"]
    invalid = causes["unseen"] | causes["shadow"] | causes["grazing"]
    if sensor.edge_band_px > 0:
        invalid |= causes["edge_band"] & (rng.random(z.shape) < sensor.edge_drop_probability)
    if sensor.drop_fraction > 0:
        invalid |= rng.random(z.shape) < sensor.drop_fraction
    # noise and rounding in inverse depth (whole normalised-disparity steps)
    step = sensor.inverse_depth_step_per_m
    pre = math.sqrt(max(sensor.disparity_sigma ** 2 - 1.0 / 12.0, 0.0))
    w = np.where(seen, 1.0 / np.where(seen, z, 1.0), np.nan)
    if sensor.correlation_px > 0:
        w = w + pre * step * correlated_normal(z.shape, correlation_px=sensor.correlation_px, rng=rng)
    else:
        w = w + rng.normal(0.0, pre * step, size=z.shape)
    w = np.round(w / step) * step
    out = np.where(invalid | ~(w > 0), np.nan, 1.0 / np.where(w > 0, w, 1.0))
    return out.astype(np.float32)


def noisy_rgb(rgb: np.ndarray, *, sigma: float, rng: np.random.Generator) -> np.ndarray:
    """A copy of an 8-bit colour image (H, W, 3) with Gaussian noise of `sigma` levels."""
    if sigma <= 0:
        return rgb.copy()
    noisy = rgb.astype(np.float32) + rng.normal(0.0, sigma, size=rgb.shape).astype(np.float32)
    return np.clip(np.round(noisy), 0, 255).astype(np.uint8)


def apply_sensor(rgb: np.ndarray, depth_m: np.ndarray, *, K: np.ndarray, sensor: SensorSpec,
                 rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """What the sensor returns for a clean frame: (colour (H, W, 3) uint8, depth (H, W) float32
    metres with NaN for no return)."""
    if sensor.kind == "gaussian":
        return rgb, gaussian_depth(depth_m, sigma_m=sensor.depth_sigma_m, drop_fraction=sensor.drop_fraction, rng=rng,
                                   correlation_px=sensor.correlation_px)
    depth = structured_light_depth(depth_m, K=K, sensor=sensor, rng=rng)
    return noisy_rgb(rgb, sigma=sensor.rgb_sigma, rng=rng), depth
