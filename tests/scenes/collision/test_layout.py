"""The collision engine's modules are named where they live: every module of `scenes.collision`
that the code, the tests and the docs name (dotted, or as a path) resolves, and nothing names the
flat `scenes/fcl_*.py` files they moved from."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

from layout_scan import ROOT, repo_texts

from scenes.collision import kernel_data

NAMED = re.compile(r"(?<!tests/)scenes[./]collision[./](\w+)")
TEST_PATH = re.compile(r"tests/scenes/collision/\w+\.py")
OLD = re.compile("scenes[./]" + "fcl_" + r"(world|build|shapes|tables|motion|certify|compiled|kernel)"
                 + "|tests/scenes/test_" + "fcl_")


def test_every_named_collision_module_resolves_and_no_old_name_is_left():
    missing, old, named = [], [], set()
    for rel, text in repo_texts():
        for m in NAMED.finditer(text):
            named.add(m.group(1))
            if importlib.util.find_spec(f"scenes.collision.{m.group(1)}") is None:
                missing.append(f"{rel}: {m.group(0)}")
        missing += [f"{rel}: {m.group(0)}" for m in TEST_PATH.finditer(text) if not (ROOT / m.group(0)).is_file()]
        old += [f"{rel}: {m.group(0)}" for m in OLD.finditer(text)]
    assert not missing, missing
    assert not old, old
    assert {"world", "certify", "compiled", "kernel_state", "kernel_motion"} <= named  # the scan sees them
    assert not list(ROOT.glob("scenes/fcl_*.py"))  # no shim left behind


def test_the_kernel_modules_are_the_engines():
    for m in kernel_data.KERNEL_MODULES:
        spec = importlib.util.find_spec(f"{kernel_data.__package__}.{m}")
        assert spec is not None and Path(spec.origin).parent == ROOT / "scenes" / "collision", m
