"""The command line: help, scene JSON and image, one-line errors."""

import json
import subprocess
import sys

import pytest


def suite(*args, check=True):
    return subprocess.run([sys.executable, "-m", "suite", *args], capture_output=True, text=True, check=check)


def test_help_lists_subcommands():
    out = suite("--help").stdout
    for cmd in ("scene", "perceive", "plan", "compare", "plot", "bench"):
        assert cmd in out


def test_scene_json_and_image(tmp_path):
    img = tmp_path / "top.png"
    out = suite("scene", "--seed", "4", "--cans", "2", "--variant", "wall", "--json", "--image", str(img))
    truth = json.loads(out.stdout)
    assert truth["seed"] == 4 and truth["variant"] == "wall"
    assert set(truth["plate"]) == {"center_m", "size_m"} and len(truth["plate"]["size_m"]) == 2
    assert len(truth["cans"]) == 2
    for c in truth["cans"]:
        assert set(c) == {"id", "p_WC_m", "lying", "axis_yaw_rad"} and len(c["p_WC_m"]) == 3
    assert img.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(
    "args, needle",
    [
        (["scene", "--variant", "moon"], "unknown variant 'moon'"),
        (["scene", "--cans", "-2"], "--cans"),
        (["scene", "--cans", "400"], "cans.count"),
        (["scene", "--spec", "/nonexistent.yaml"], "cannot read scene spec"),
    ],
)
def test_bad_input_one_line(args, needle):
    res = suite(*args, check=False)
    assert res.returncode != 0
    lines = [l for l in res.stderr.splitlines() if l.strip()]
    assert len(lines) == 1, res.stderr
    assert needle in lines[0]
