"""`bench execution` on perceived grasps under a sensor model: the options, their refusals, and the
perceived-grasps path (rendered through the sensor, the named pipeline). Nothing here times anything."""

from __future__ import annotations

import argparse
import subprocess
import sys

import numpy as np
import pytest

from perception.pipeline import PerceptionSetup, detect_in_frames, noise_rng, perceive_with
from scenes.errors import SuiteError
from scenes.generate import generate_scene
from scenes.grasp_rule import truth_grasp
from scenes.spec import load_spec
from suite.bench.execution import add_arguments, perception_setups, source_label
from suite.run.runner import scene_grasps


def _args(*argv: str) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    add_arguments(p)
    return p.parse_args(list(argv))


def test_defaults_are_the_papers_pipeline_on_a_perfect_sensor():
    (setup,) = perception_setups(_args())
    assert setup == PerceptionSetup()
    assert setup.sensor_spec() is None  # the spec's cameras: a perfect sensor
    assert _args().grasps == "truth,perceived"


def test_sensor_and_pipelines_parse_to_one_grasp_source_each():
    setups = perception_setups(_args("--sensor", "kinect-v1", "--pipeline", "robust,paper"))
    assert [s.pipeline for s in setups] == ["robust", "paper"]
    assert all(s.sensor == "kinect-v1" and s.sensor_spec().kind == "structured-light" for s in setups)
    assert source_label("perceived", setups[0], "perceived") == ("perceived grasps (robust (top, front, back), kinect-v1), "
                                                                 "perceived world")
    assert source_label("truth", None) == "truth grasps"
    (gauss,) = perception_setups(_args("--depth-noise-m", "0.003", "--segmentation", "geometric"))
    spec = gauss.sensor_spec()
    assert spec.kind == "gaussian" and spec.depth_sigma_m == 0.003 and spec.drop_fraction == 0.01
    assert gauss.label() == "paper (top), geometric, Gaussian 3 mm"
    assert gauss.to_json() == {"pipeline": "paper", "segmentation": "geometric", "sensor": None, "depth_noise_m": 0.003,
                               "correlation_px": 0.0, "noise_scale": 1.0}


def test_worlds_parse_and_a_bad_one_is_named():
    from suite.bench.execution import world_list

    assert world_list("truth,perceived") == ["truth", "perceived"]
    for bad in ("true", ","):
        with pytest.raises(SuiteError, match="allowed: truth, perceived"):
            world_list(bad)


@pytest.mark.parametrize("argv, words", [
    (["--sensor", "kinect-v2"], ["'kinect-v2'", "kinect-v1"]),
    (["--pipeline", "paper,fancy"], ["'fancy'", "paper, robust"]),
    (["--pipeline", ","], ["names no pipeline", "paper, robust"]),
    (["--pipeline", "robust,robust"], ["twice"]),
    (["--segmentation", "hsv"], ["'hsv'", "color, geometric"]),
    (["--sensor", "kinect-v1", "--depth-noise-m", "0.003"], ["choose one sensor model"]),
])
def test_bad_values_raise_a_suite_error_naming_them(argv, words):
    with pytest.raises(SuiteError) as err:
        perception_setups(_args(*argv))
    assert all(w in str(err.value) for w in words), str(err.value)


def test_setup_checks_its_values():
    with pytest.raises(SuiteError, match="depth noise"):
        PerceptionSetup(depth_noise_m=float("nan"))
    with pytest.raises(SuiteError, match="'dark'"):
        PerceptionSetup(pipeline="dark")


def test_the_command_refuses_a_bad_value_in_one_line_before_any_work():
    r = subprocess.run([sys.executable, "-m", "suite", "bench", "execution", "--sensor", "kinect-v2"],
                       capture_output=True, text=True)
    assert r.returncode == 2
    assert r.stderr.strip() == "error: unknown sensor 'kinect-v2'; allowed: kinect-v1"
    assert "executions" not in r.stdout  # nothing was planned


@pytest.fixture(scope="module")
def scene():
    return generate_scene(load_spec(variant="open").with_can_count(3), seed=4)


def _xy(grasps):
    return np.array(sorted((float(g.X_WG[0, 3]), float(g.X_WG[1, 3])) for g in grasps))


def test_perceived_grasps_go_through_the_sensor(scene):
    """Under Kinect v1 every can is still found, by each pipeline, but not where a perfect sensor
    (or the truth) puts it; and the noise is drawn from the scene's seed, so it repeats."""
    truth = _xy(scene_grasps(scene, grasps="truth"))
    clean = _xy(scene_grasps(scene, grasps="perceived", perception=PerceptionSetup(pipeline="robust")))
    for pipeline in ("robust", "paper"):
        setup = PerceptionSetup(pipeline=pipeline, sensor="kinect-v1")
        noisy = _xy(scene_grasps(scene, grasps="perceived", perception=setup))
        assert noisy.shape == truth.shape == (3, 2)
        err_m = np.linalg.norm(noisy - truth, axis=1)
        assert np.all(err_m < 0.01) and np.all(err_m > 0)  # close to the cans, never exactly on them
        if pipeline == "robust":
            assert not np.array_equal(noisy, clean)  # the sensor changed the frames
            assert np.array_equal(noisy, _xy(scene_grasps(scene, grasps="perceived", perception=setup)))


def test_closed_loop_frames_see_the_same_sensor_as_perceive(scene):
    """The closed loop's detection on clean frames, sensed with `noise_rng(seed)`, is `perceive`'s."""
    from perception.side_view import SIDE_CAMERAS
    from scenes.render import render

    setup = PerceptionSetup(pipeline="robust", sensor="kinect-v1")
    frames = render(scene, cameras=["top", *SIDE_CAMERAS])
    looped = detect_in_frames(frames, scene.spec, setup=setup, rng=noise_rng(scene.seed))
    once = perceive_with(scene, setup=setup).detections
    assert len(looped) == len(once) == 3
    assert _xy([d.grasp for d in looped]).tolist() == _xy([d.grasp for d in once]).tolist()
    clean = detect_in_frames(frames, scene.spec, setup=PerceptionSetup(pipeline="robust"), rng=noise_rng(scene.seed))
    assert _xy([d.grasp for d in clean]).tolist() != _xy([d.grasp for d in looped]).tolist()


@pytest.mark.slow
def test_perceived_kinect_grasps_recycle_a_can_in_physics():
    from planners.registry import planner_class
    from suite.execution.job_spec import ExecutionJob
    from suite.execution.jobs import run_execution
    from suite.run.trial import config_dict, make_config

    scene = generate_scene(load_spec(variant="open").with_can_count(1), seed=2)
    setup = PerceptionSetup(pipeline="robust", sensor="kinect-v1")
    rec = run_execution(ExecutionJob("rrt", config_dict(make_config(planner_class("rrt"), None)), scene,
                                     "perceived", 5.0, scene.seed, perception=setup))
    assert rec.perception == setup.to_json()
    assert rec.cans_in_bin == 1, rec


def test_an_execution_record_is_told_apart_by_its_grasp_source():
    from suite.bench.execution import _source, _source_of
    from suite.execution.execution_records import ExecutionRecord

    base = {"planner": "rrt", "scene_seed": 0, "variant": "open", "cans_total": 1}
    setup = PerceptionSetup().to_json()
    perceived = ExecutionRecord.from_json({**base, "grasps": "perceived", "perception": setup,
                                           "worlds": {"planned": "perceived"}})
    truth = ExecutionRecord.from_json({**base, "grasps": "truth"})  # a record without worlds: planned in the truth
    assert _source_of(perceived) == _source("perceived", setup, "perceived") != _source("perceived", setup, "truth")
    assert _source_of(truth) == _source("truth", None, "truth")
