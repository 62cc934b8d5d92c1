"""The cameras' sensor models (scenes/sensor.py): noise and quantization as published, invalid
pixels where a structured-light sensor has none, and a spec whose scene keys do not change."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from scenes.sensor import SENSOR_PRESETS, SensorSpec, apply_sensor, projector_shadow, structured_light_depth
from scenes.spec import load_spec, loads_spec

K = np.array([[579.4, 0.0, 320.0], [0.0, 579.4, 240.0], [0.0, 0.0, 1.0]])
KINECT = SENSOR_PRESETS["kinect-v1"]


def test_kinect_noise_follows_khoshelham_elberink():
    # A wall square to the camera at 0.73 m (the plate from the top camera) and at 2 m.
    for z in (0.73, 2.0):
        depth = np.full((200, 200), z, np.float32)
        out = structured_light_depth(depth, K=K, sensor=dataclasses.replace(KINECT, drop_fraction=0.0),
                                     rng=np.random.default_rng(1))
        valid = out[np.isfinite(out)]
        expected = 1.43e-3 * z * z  # their sigma_Z = 1.43e-3 Z^2 m (noise and rounding together)
        assert abs(float(np.std(valid)) - expected) < 0.15 * expected
        assert abs(float(np.mean(valid)) - z) < 0.2 * expected
        # quantized: whole steps of 2.85e-3 in 1/Z
        steps = (1.0 / valid.astype(np.float64)) / KINECT.inverse_depth_step_per_m
        assert np.allclose(steps, np.round(steps), atol=1e-3)
        assert math.isclose(KINECT.depth_sigma_at_m(z), expected, rel_tol=0.01)


def test_projector_shadow_beside_a_nearer_object():
    # A box 0.1 m nearer than the wall behind it: the projector (on the image's +x side) cannot
    # light a band of the wall on the box's -x side, as wide as the disparity jump.
    z_far, z_near = 0.73, 0.63
    depth = np.full((60, 200), z_far)
    depth[:, 100:140] = z_near
    f, b = K[0, 0], KINECT.baseline_m
    shadow = projector_shadow(f * b / depth)
    width = f * b * (1 / z_near - 1 / z_far)  # 9.4 px
    row = shadow[30]
    assert not row[100:].any()  # the box and the wall right of it are lit
    assert abs(int(row[:100].sum()) - width) <= 1.5
    assert row[100 - int(width) + 1:100].all()


def test_grazing_surfaces_and_depth_edges_return_no_depth():
    # A wall tilted 80 degrees from facing the camera (beyond 75) returns nothing but dropouts.
    h, w = 100, 100
    u = np.arange(w)[None, :].repeat(h, 0)
    tilt = math.radians(80)
    x_over_z = (u - K[0, 2]) / K[0, 0]
    depth = 1.0 / (1.0 + math.tan(tilt) * x_over_z)  # the plane z + tan(tilt) x = 1
    depth = np.where(depth > 0, depth, np.nan).astype(np.float32)
    sensor = dataclasses.replace(KINECT, drop_fraction=0.0, edge_band_px=0)
    out = structured_light_depth(depth, K=K, sensor=sensor, rng=np.random.default_rng(0))
    assert np.isnan(out[5:-5, 5:-5]).all()
    flat = structured_light_depth(np.full((h, w), 0.7, np.float32), K=K, sensor=sensor, rng=np.random.default_rng(0))
    assert np.isfinite(flat).all()


def test_colour_noise_and_gaussian_kind():
    rgb = np.full((50, 50, 3), 128, np.uint8)
    depth = np.full((50, 50), 0.7, np.float32)
    rgb2, _ = apply_sensor(rgb, depth, K=K, sensor=KINECT, rng=np.random.default_rng(0))
    assert 1.5 < float(np.std(rgb2.astype(float))) < 2.5
    g = SensorSpec(kind="gaussian", depth_sigma_m=0.003, drop_fraction=0.0)
    rgb3, d3 = apply_sensor(rgb, depth, K=K, sensor=g, rng=np.random.default_rng(0))
    assert (rgb3 == rgb).all() and abs(float(np.std(d3)) - 0.003) < 0.0003


def test_sensor_is_off_by_default_and_out_of_the_scene_key():
    spec = load_spec(variant="clutter")
    assert spec.cameras.sensor is None
    assert "sensor" not in spec.to_dict()["cameras"]
    text = (load_spec.__globals__["DEFAULT_SPEC_PATH"]).read_text()
    with_sensor = loads_spec(text.replace("  clipping_m: [0.05, 3.0]\n",
                                          "  clipping_m: [0.05, 3.0]\n  sensor: {kind: structured-light}\n"))
    assert with_sensor.cameras.sensor == KINECT
    assert with_sensor.to_dict()["cameras"]["sensor"]["kind"] == "structured-light"
