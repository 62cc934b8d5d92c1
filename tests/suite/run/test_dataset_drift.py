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


@pytest.mark.parametrize("rec", _first_scene_per_family(DEFAULT_DATASET), ids=lambda r: r["family"])
def test_the_build_settings_still_pose_the_stored_problems(rec):
    """The goal IK too (a change to `build_problems` changes q_goal, hence every problem id): the
    stored problems of the scene are among those its cycle poses with the manifest's settings."""
    from scenes.generate import generate_scene
    from scenes.grasp_rule import truth_grasp
    from suite.problems.cycle import build_problems
    from suite.problems.identity import problem_id
    from suite.run.build_dataset import family_spec, pose_settings

    manifest = read_manifest(dataset_dir(DEFAULT_DATASET))
    scene = generate_scene(family_spec(rec["family"], manifest["build"]["settings"]["cans"]), seed=rec["seed"])
    posed = {problem_id(p) for p in build_problems(scene, [truth_grasp(scene, c) for c in scene.cans],
                                                   time_limit_s=1.0, seed=rec["seed"], **pose_settings(manifest))
             if p.pre_status is None}
    stored = set()
    for line in (dataset_dir(DEFAULT_DATASET) / "problems.jsonl").read_text().splitlines():
        p = json.loads(line)
        if p["scene_key"] == rec["scene_key"]:
            stored.add(p["problem_id"])
    assert stored, f"no stored problem for scene {rec['scene_key']}"
    missing = stored - posed
    assert not missing, (f"{DEFAULT_DATASET}: {rec['family']} seed {rec['seed']}: {len(missing)} of {len(stored)} stored "
                         "problems are no longer posed by the build settings: build a new dataset version")
