"""`bench certify --breakdown`: where the exact check's time goes, part by part."""

from __future__ import annotations

import numpy as np

from suite.bench.certify import PARTS, breakdown
from suite.problems.dataset import load_dataset


def test_breakdown_parts_add_up_to_the_check_and_leave_the_worlds_certifier_alone():
    from planners.worlds import collision_world
    from scenes.collision.certify import certifier

    ds = load_dataset("recycle-v3:quick:family=window")
    items = [(p, ds.references[pid]) for pid, p in zip(ds.ids, ds.problems) if not ds.meta[pid]["trivial"]][:2]
    b = breakdown(items)
    assert b["paths"] == 2 and set(b["parts_s"]) == set(PARTS)
    assert all(v >= 0 for v in b["parts_s"].values()) and b["rest_s"] >= -1e-9
    assert b["certify_s"] > 0 and b["exact_queries"] > 0 and b["parts_s"]["_exact"] > 0
    assert b["fixed_numpy_s"] > 0 and b["fixed_compiled_s"] > 0
    # the timing wrappers sit on a certifier of their own, not on the one the judge keeps
    cached = certifier(collision_world(items[0][0]))
    assert all(name not in vars(cached) for name in PARTS)
    assert cached.certify(np.asarray(items[0][1], float)).verdict == "certified"
