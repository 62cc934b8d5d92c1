"""Shared fixtures: small scenes built once per test session."""

import pytest

from scenes.generate import generate_scene
from scenes.spec import load_spec


@pytest.fixture(scope="session")
def open_scene():
    return generate_scene(load_spec(variant="open").with_can_count(3), seed=1)


@pytest.fixture(scope="session")
def wall_scene():
    return generate_scene(load_spec(variant="wall").with_can_count(3), seed=2)
