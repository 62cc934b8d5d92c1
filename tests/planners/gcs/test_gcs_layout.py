"""`gcs`'s modules are named where they live: every module of `planners.gcs` that the code, the tests
and the docs name (dotted, or as a path) resolves, nothing names the flat `planners/gcs_*.py` files
they moved from, the registry's `gcs` is the package's planner, and the region caches resolve to
the repository's own directories."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

from layout_scan import ROOT, repo_texts

NAMED = re.compile(r"(?<!tests/)planners[./]gcs[./](\w+)")
OLD = re.compile("planners[./]" + "gcs_" + r"(cover|regions|sets|solve)|planners\.gcs" + r"(:| import Gcs)"
                 + "|planners/" + r"gcs\.py|tests/planners/test_" + "gcs")


def test_every_named_gcs_module_resolves_and_no_old_name_is_left():
    missing, old, named = [], [], set()
    for rel, text in repo_texts():
        for m in NAMED.finditer(text):
            named.add(m.group(1))
            if importlib.util.find_spec(f"planners.gcs.{m.group(1)}") is None:
                missing.append(f"{rel}: {m.group(0)}")
        old += [f"{rel}: {m.group(0)}" for m in OLD.finditer(text)]
    assert not missing, missing
    assert not old, old
    assert {"planner", "regions", "iris", "sets", "solve", "cover"} <= named  # the scan sees them
    assert not list(ROOT.glob("planners/gcs_*.py")) and not (ROOT / "planners" / "gcs.py").exists()  # no shim


def test_the_registry_and_the_region_caches_resolve_from_the_package():
    from planners.gcs.sets import DATASETS_DIR, DEFAULT_CACHE_DIR
    from planners.registry import planner_class

    cls = planner_class("gcs")
    assert cls.name == "gcs"
    assert Path(importlib.util.find_spec(cls.__module__).origin) == ROOT / "planners" / "gcs" / "planner.py"
    assert DEFAULT_CACHE_DIR == ROOT / "results" / "regions"
    assert DATASETS_DIR == ROOT / "scenes" / "datasets" and any(DATASETS_DIR.glob("*/regions/*.npz"))
