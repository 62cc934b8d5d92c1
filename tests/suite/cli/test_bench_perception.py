"""`bench perception --pipeline`: both pipelines timed on the same frames. These assert what it
prints, never how fast anything is."""

from __future__ import annotations

import json

from suite.cli import main


def test_both_pipelines_are_timed_on_the_same_frames(capsys):
    assert main(["bench", "perception", "--pipeline", "both", "--variant", "clutter", "--segmentation", "geometric",
                 "--frames", "2", "--depth-noise-m", "0.003", "--json"]) == 0
    r = json.loads(capsys.readouterr().out.strip().splitlines()[-1])["perception"]
    assert r["frames"] == 2 and r["variant"] == "clutter" and r["sensor"] == "gaussian"
    assert set(r["process_median_ms_by_pipeline"]) == {"paper", "robust"}
    assert all(v > 0 for v in r["process_median_ms_by_pipeline"].values())


def test_one_sensor_model_at_a_time(capsys):
    assert main(["bench", "perception", "--sensor", "kinect-v1", "--depth-noise-m", "0.003"]) != 0
    assert "choose one sensor model" in capsys.readouterr().err
