"""Shared fixtures: small scenes, and the transit of their first can, built once per test session."""

import pytest

from scenes.generate import generate_scene
from scenes.grasp_rule import truth_grasp
from scenes.spec import load_spec
from suite.problems.cycle import build_problems


@pytest.fixture(scope="session")
def open_scene():
    return generate_scene(load_spec(variant="open").with_can_count(3), seed=1)


@pytest.fixture(scope="session")
def wall_scene():
    return generate_scene(load_spec(variant="wall").with_can_count(3), seed=2)


def _first_can_problem(scene, kind):
    problems = build_problems(scene, [truth_grasp(scene, scene.cans[0])], time_limit_s=5.0, seed=3)
    (p,) = [p for p in problems if p.kind == kind]
    assert p.pre_status is None
    return p


@pytest.fixture(scope="session")
def open_transit(open_scene):
    return _first_can_problem(open_scene, "transit")


@pytest.fixture(scope="session")
def wall_transit(wall_scene):
    return _first_can_problem(wall_scene, "transit")
