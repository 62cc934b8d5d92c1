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


#: Content agrees within this (rad, m): far above the last-bit noise of posing on another CPU,
#: far below any change of the generator or the goal IK.
CONTENT_ATOL = 1e-7


def _content(problem) -> list:
    """A problem's content (its world, q_start, q_goal) as one flat list of its values."""
    from suite.problems.identity import world_content

    out: list = []

    def walk(v):
        if isinstance(v, dict):
            for k in sorted(v):
                out.append(k)
                walk(v[k])
        elif isinstance(v, (list, tuple)):
            out.append(len(v))
            for x in v:
                walk(x)
        else:
            out.append(v)

    walk([world_content(problem), problem.q_start.tolist(), problem.q_goal.tolist()])
    return out


def _same_content(a, b) -> bool:
    ca, cb = _content(a), _content(b)
    return len(ca) == len(cb) and all(
        abs(x - y) <= CONTENT_ATOL if isinstance(x, float) and isinstance(y, float) else x == y for x, y in zip(ca, cb))


@pytest.mark.parametrize("rec", _first_scene_per_family(DEFAULT_DATASET), ids=lambda r: r["family"])
def test_the_build_settings_still_pose_the_stored_problems(rec):
    """The goal IK too (a change to `build_problems` changes q_goal): each stored problem of the
    scene is posed again by its cycle with the manifest's settings, the same by content within
    CONTENT_ATOL. Not by id: the shipped ids are exact about the sign of a zero (rule `round9`),
    which last-bit noise of the IK flips on another CPU."""
    from scenes.generate import generate_scene
    from scenes.grasp_rule import truth_grasp
    from suite.problems.cycle import build_problems
    from suite.problems.stored import problem_from_record, scene_from_record
    from suite.run.build_dataset import family_spec, pose_settings

    manifest = read_manifest(dataset_dir(DEFAULT_DATASET))
    scene = generate_scene(family_spec(rec["family"], manifest["build"]["settings"]["cans"]), seed=rec["seed"])
    posed = {(p.can_id, p.kind): p for p in build_problems(
        scene, [truth_grasp(scene, c) for c in scene.cans], time_limit_s=1.0, seed=rec["seed"],
        **pose_settings(manifest)) if p.pre_status is None}
    stored_scene = scene_from_record(rec)
    stored = [problem_from_record(p, stored_scene, time_limit_s=1.0)
              for p in map(json.loads, (dataset_dir(DEFAULT_DATASET) / "problems.jsonl").read_text().splitlines())
              if p["scene_key"] == rec["scene_key"]]
    assert stored, f"no stored problem for scene {rec['scene_key']}"
    missing = [f"can {p.can_id} {p.kind}" for p in stored
               if (p.can_id, p.kind) not in posed or not _same_content(p, posed[(p.can_id, p.kind)])]
    assert not missing, (f"{DEFAULT_DATASET}: {rec['family']} seed {rec['seed']}: {len(missing)} of {len(stored)} stored "
                         f"problems are no longer posed by the build settings ({', '.join(missing[:4])}): "
                         "build a new dataset version")
