"""Every shipped dataset keeps its specs, scene keys and problem ids: each is recomputed from the
stored lines by the current code (the spec's schema and hash, the scene key, the problem's content
hash under the dataset's identity rule, each line's record hash and the dataset hash).

This is `dataset verify` without its reference checks (validation and certification of every
reference, minutes on the larger datasets); `test_the_smallest_datasets_verify` runs the whole
of it on the datasets that verify in seconds."""

from __future__ import annotations

import json

import pytest

from suite.problems.dataset import (
    DATASETS_DIR,
    MANIFEST_FILE,
    PROBLEMS_FILE,
    SCENES_FILE,
    dataset_dir,
    identity_rule,
    read_manifest,
    verify_dataset,
)

SHIPPED = sorted(p.name for p in DATASETS_DIR.iterdir() if (p / MANIFEST_FILE).exists())
#: Datasets `dataset verify` checks whole within a few seconds.
SMALL = [name for name in SHIPPED if (dataset_dir(name) / PROBLEMS_FILE).stat().st_size < 200_000]


def _lines(path):
    return [line for line in path.read_text().splitlines() if line.strip()]


def test_the_shipped_datasets_are_found():
    assert {"recycle-v1", "recycle-v2", "recycle-v3", "recycle-v3.1", "gcs-arm", "gcs-arm-v2"} <= set(SHIPPED)
    assert {"gcs-arm", "gcs-arm-v2"} <= set(SMALL)


@pytest.mark.parametrize("name", SHIPPED)
def test_a_shipped_dataset_recomputes_its_keys_and_ids(name):
    from suite.problems.identity import problem_id
    from suite.problems.stored import dataset_hash, problem_from_record, record_hash, scene_from_record

    directory = dataset_dir(name)
    manifest = read_manifest(directory)
    rule = identity_rule(manifest)
    scene_lines = _lines(directory / SCENES_FILE)
    scenes = {}
    for line in scene_lines:
        rec = json.loads(line)
        scene = scene_from_record(rec)
        assert scene.key() == rec["scene_key"], f"{name}: scene {rec['scene_key']} has another key now"
        assert json.loads(json.dumps(scene.spec.to_dict(), default=list)) == rec["spec"], \
            f"{name}: scene {rec['scene_key']}'s spec reads back as another"
        scenes[rec["scene_key"]] = scene
    records = [json.loads(line) for line in _lines(directory / PROBLEMS_FILE)]
    for rec in records:
        assert record_hash(rec) == rec["record_hash"], f"{name}: problem {rec['problem_id']}'s line changed"
        problem = problem_from_record(rec, scenes[rec["scene_key"]], time_limit_s=1.0)
        assert problem_id(problem, rule=rule) == rec["problem_id"], f"{name}: problem {rec['problem_id']} has another id now"
    assert dataset_hash(scene_lines, records) == manifest["hash"]


@pytest.mark.parametrize("name", SMALL)
def test_the_smallest_datasets_verify(name):
    counts = verify_dataset(name)
    assert counts["problems"] > 0 and counts["references"]["collision"] == 0
