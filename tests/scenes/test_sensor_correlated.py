"""Correlated depth noise, the noise scale and the depth-edge rule of the sensor models
(scenes/sensor.py), and how a perception setup names them (perception/pipeline.py)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from perception.pipeline import PIPELINE_CAMERAS, PIPELINES, PerceptionSetup
from scenes.errors import SuiteError
from scenes.sensor import (SENSOR_PRESETS, SensorSpec, correlated_normal, dropout_causes, gaussian_depth,
                           incidence_deg, structured_light_depth)
from scenes.spec import load_spec, loads_spec

K = np.array([[579.4, 0.0, 320.0], [0.0, 579.4, 240.0], [0.0, 0.0, 1.0]])
KINECT = SENSOR_PRESETS["kinect-v1"]


def _autocorrelation(field: np.ndarray, lag: int) -> float:
    """The field's normalised autocorrelation at a lag of `lag` pixels, along rows and columns."""
    f = (field - field.mean()) / field.std()
    return 0.5 * float(np.mean(f[:, lag:] * f[:, :-lag]) + np.mean(f[lag:, :] * f[:-lag, :]))


@pytest.mark.parametrize("length_px", [4.0, 8.0])
def test_the_correlation_length_is_where_the_autocorrelation_falls_to_1_over_e(length_px):
    field = correlated_normal((480, 640), correlation_px=length_px, rng=np.random.default_rng(3))
    assert abs(float(field.std()) - 1.0) < 0.03  # each pixel's sigma unchanged
    for lag in (1, 2, int(length_px), int(2 * length_px)):
        expected = math.exp(-(lag / length_px) ** 2)
        assert abs(_autocorrelation(field, lag) - expected) < 0.04, (lag, expected)
    assert abs(_autocorrelation(field, int(length_px)) - 1 / math.e) < 0.04


def test_independent_noise_is_drawn_as_before():
    depth = np.full((40, 50), 0.7, np.float32)
    out = gaussian_depth(depth, sigma_m=0.002, drop_fraction=0.0, rng=np.random.default_rng(5))
    ref = depth + np.random.default_rng(5).normal(0.0, 0.002, size=depth.shape).astype(np.float32)
    assert np.array_equal(out, ref)
    assert _autocorrelation(out, 1) < 0.05


@pytest.mark.parametrize("length_px", [4.0, 8.0])
def test_both_kinds_keep_their_sigma_when_correlated(length_px):
    wall = np.full((240, 320), 0.73, np.float32)
    g = SensorSpec(kind="gaussian", depth_sigma_m=0.003, drop_fraction=0.0).with_noise(correlation_px=length_px)
    out = gaussian_depth(wall, sigma_m=g.depth_sigma_m, drop_fraction=0.0, rng=np.random.default_rng(1),
                         correlation_px=g.correlation_px)
    assert abs(float(np.std(out)) - 0.003) < 0.1 * 0.003
    assert abs(_autocorrelation(out, int(length_px)) - 1 / math.e) < 0.06
    k = dataclasses.replace(KINECT, drop_fraction=0.0).with_noise(correlation_px=length_px)
    sl = structured_light_depth(wall, K=K, sensor=k, rng=np.random.default_rng(1))
    valid = sl[np.isfinite(sl)]
    expected = 1.43e-3 * 0.73 ** 2  # Khoshelham & Elberink's sigma_Z, noise and rounding together
    assert abs(float(np.std(valid)) - expected) < 0.15 * expected
    # the noise comes in patches: neighbours mostly share their depth step
    assert _autocorrelation(np.where(np.isfinite(sl), sl, np.nanmean(sl)), 1) > 0.5


def test_the_noise_scale_multiplies_sigma():
    wall = np.full((200, 200), 0.73, np.float32)
    x2 = dataclasses.replace(KINECT, drop_fraction=0.0).with_noise(scale=2.0)
    assert x2.disparity_sigma == 1.0 and math.isclose(x2.depth_sigma_at_m(0.73), 2 * KINECT.depth_sigma_at_m(0.73))
    out = structured_light_depth(wall, K=K, sensor=x2, rng=np.random.default_rng(2))
    assert abs(float(np.nanstd(out)) - 2 * 1.43e-3 * 0.73 ** 2) < 0.1 * 2 * 1.43e-3 * 0.73 ** 2
    g = SensorSpec(kind="gaussian", depth_sigma_m=0.002).with_noise(scale=1.5, correlation_px=4)
    assert math.isclose(g.depth_sigma_m, 0.003) and g.correlation_px == 4.0
    for bad in ({"scale": 0.0}, {"scale": float("nan")}, {"correlation_px": -1.0}):
        with pytest.raises(ValueError):
            KINECT.with_noise(**bad)


def test_a_spec_names_the_correlation_and_the_default_is_independent():
    assert KINECT.correlation_px == 0.0
    text = (load_spec.__globals__["DEFAULT_SPEC_PATH"]).read_text()
    spec = loads_spec(text.replace("  clipping_m: [0.05, 3.0]\n",
                                   "  clipping_m: [0.05, 3.0]\n  sensor: {kind: structured-light, correlation_px: 4.0}\n"))
    assert spec.cameras.sensor == KINECT.with_noise(correlation_px=4.0)
    with pytest.raises(SuiteError, match="correlation_px"):
        loads_spec(text.replace("  clipping_m: [0.05, 3.0]\n",
                                "  clipping_m: [0.05, 3.0]\n  sensor: {kind: structured-light, correlation_px: -1.0}\n"))


def test_a_flat_tops_edge_is_not_grazing_so_the_edge_rule_decides_it():
    # A box top 0.1 m above a floor, both square to the camera: nothing is grazing, yet every pixel
    # beside the box's outline is in the edge band, on both sides, and about half are dropped.
    depth = np.full((120, 160), 0.73, np.float32)
    depth[40:80, 50:110] = 0.63
    causes = dropout_causes(depth, K=K, sensor=KINECT)
    assert not causes["grazing"].any()
    assert causes["edge_band"][40:42, 60:100].all() and causes["edge_band"][38:40, 60:100].all()  # 2 px each side
    assert not causes["edge_band"][45:75, 55:105].any()
    sensor = dataclasses.replace(KINECT, drop_fraction=0.0)
    out = structured_light_depth(depth, K=K, sensor=sensor, rng=np.random.default_rng(0))
    only_edge = causes["edge_band"] & ~(causes["unseen"] | causes["shadow"] | causes["grazing"])
    dropped = np.isnan(out) & only_edge
    assert 0.4 < dropped.sum() / only_edge.sum() < 0.6
    assert not np.isnan(out[~only_edge & ~causes["shadow"]]).any()
    # a genuinely grazing surface still is: the plane z = 0.7 + tan(80 deg) x across the optical axis
    K_c = K.copy()
    K_c[0, 2], K_c[1, 2] = 50.0, 50.0
    x_over_z = (np.arange(100)[None, :].repeat(100, 0) - 50.0) / K_c[0, 0]
    tilted = (0.7 / (1.0 - math.tan(math.radians(80)) * x_over_z)).astype(np.float32)
    assert (tilted > 0).all()
    assert (incidence_deg(tilted, K_c)[5:-5, 5:-5] > 75).all()


def test_on_a_rendered_clutter_scene_pixels_are_dropped_by_the_edge_rule_alone():
    from scenes.generate import generate_scene
    from scenes.render import render

    scene = generate_scene(load_spec(variant="clutter"), seed=9301, check_reachable=False)
    top = render(scene, cameras=["top"])["top"]
    sensor = dataclasses.replace(KINECT, drop_fraction=0.0)
    causes = dropout_causes(top.depth_m, K=top.K, sensor=sensor)
    out = structured_light_depth(top.depth_m, K=top.K, sensor=sensor, rng=np.random.default_rng(0))
    only_edge = np.isnan(out) & ~(causes["unseen"] | causes["shadow"] | causes["grazing"])
    assert only_edge.mean() > 0.005  # 1.8% of the frame (5678 pixels); 0 before the rule had its own effect
    assert (only_edge <= causes["edge_band"]).all()


def test_a_setup_scales_and_correlates_its_sensor_and_names_it():
    s = PerceptionSetup(pipeline="robust", sensor="kinect-v1", correlation_px=4, noise_scale=2)
    assert s.sensor_spec() == KINECT.with_noise(scale=2, correlation_px=4)
    assert s.label() == "robust (top, front, back), kinect-v1 x2, correlated 4 px"
    assert s.to_json()["correlation_px"] == 4 and s.to_json()["noise_scale"] == 2
    assert PerceptionSetup(**s.to_json()) == s
    assert PerceptionSetup(sensor="kinect-v1").sensor_spec() is KINECT
    g = PerceptionSetup(pipeline="robust-top", depth_noise_m=0.002, correlation_px=8)
    assert g.sensor_spec().correlation_px == 8 and g.sensor_spec().depth_sigma_m == 0.002
    assert g.label() == "robust-top (top), Gaussian 2 mm, correlated 8 px"
    assert PerceptionSetup().label() == "paper (top), clean"
    assert set(PIPELINE_CAMERAS) == set(PIPELINES) and "robust-top" in PIPELINES


@pytest.mark.parametrize("kwargs, words", [
    ({"sensor": "kinect-v1", "correlation_px": -1.0}, ["-1.0", ">= 0"]),
    ({"sensor": "kinect-v1", "correlation_px": float("inf")}, ["inf", ">= 0"]),
    ({"sensor": "kinect-v1", "noise_scale": 0.0}, ["0.0", "> 0"]),
    ({"correlation_px": 4.0}, ["correlation 4 px", "need a sensor model"]),
    ({"noise_scale": 2.0}, ["scale 2", "need a sensor model"]),
])
def test_bad_noise_settings_raise_one_line_naming_them(kwargs, words):
    with pytest.raises(SuiteError) as err:
        PerceptionSetup(**kwargs)
    assert "\n" not in str(err.value) and all(w in str(err.value) for w in words), str(err.value)


def test_the_cli_flags_reach_the_setup():
    import argparse

    from suite.cli import perceive

    p = argparse.ArgumentParser()
    perceive.add_arguments(p)
    args = p.parse_args(["--sensor", "kinect-v1", "--noise-correlation-px", "4", "--noise-scale", "2",
                         "--pipeline", "robust-top"])
    assert perceive._setup(args) == PerceptionSetup(pipeline="robust-top", sensor="kinect-v1", correlation_px=4.0,
                                                    noise_scale=2.0)
    assert perceive._sensor(args) == KINECT.with_noise(scale=2, correlation_px=4)
    with pytest.raises(SuiteError, match="need a sensor model"):
        perceive._setup(p.parse_args(["--noise-scale", "2"]))
    with pytest.raises(SystemExit):
        p.parse_args(["--noise-scale", "0"])
