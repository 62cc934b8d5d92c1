"""The shipped dataset is frozen data, and its manifest's build command must still reproduce it.

A change to the scene generator (families, can placement, ranges in the spec) silently changes what
`dataset build` would write; this test catches it on the first scene of each family, so the change
comes with a new dataset version (or is undone) instead of a manifest that no longer tells the truth.
"""

from __future__ import annotations

import json

import pytest

from suite.problems import DEFAULT_DATASET
from suite.problems.dataset import dataset_dir, read_manifest


def _first_scene_per_family(name: str) -> list[dict]:
    seen, out = set(), []
    for line in (dataset_dir(name) / "scenes.jsonl").read_text().splitlines():
        rec = json.loads(line)
        if rec["family"] not in seen:
            seen.add(rec["family"])
            out.append(rec)
    return out


@pytest.mark.parametrize("rec", _first_scene_per_family(DEFAULT_DATASET), ids=lambda r: r["family"])
def test_the_build_command_still_generates_the_stored_scenes(rec):
    from scenes.generate import generate_scene
    from suite.run.build_dataset import family_spec

    settings = read_manifest(dataset_dir(DEFAULT_DATASET))["build"]["settings"]
    scene = generate_scene(family_spec(rec["family"], settings["cans"]), seed=rec["seed"])
    assert scene.key() == rec["scene_key"], (
        f"{DEFAULT_DATASET}: {rec['family']} seed {rec['seed']} no longer generates its stored scene: the "
        "generator changed; build a new dataset version")
