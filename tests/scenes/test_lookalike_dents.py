"""The `lookalike-dents` variant: dented cans only, lying ones dented on any side; `lookalike`'s
lying dents still face up."""

from __future__ import annotations

import math

import numpy as np

from scenes import lookalikes as la
from scenes.generate import generate_scene
from scenes.spec import load_spec


def _lying_dent_angles_deg(spec) -> list[float]:
    """For each lying dented can, the angle between its dent's direction and straight up."""
    out = []
    for parts in la.groups(spec.extra, la.DENTED_PREFIX).values():
        centre, axis = la.dented_pose(parts, height_m=spec.can.height_m)
        if abs(axis[2]) > 0.5:
            continue
        band = next(o for o in parts if o.name.endswith("_band")).pose()[:3, 3]
        off = band - centre
        away = off - (off @ axis) * axis  # the band's cylinder is moved away from the dent
        dent = -away / np.linalg.norm(away)
        out.append(math.degrees(math.acos(float(np.clip(dent[2], -1.0, 1.0)))))
    return out


def test_lying_dents_face_any_way_in_the_new_variant_and_up_in_lookalike():
    spec = load_spec(variant="lookalike-dents")
    angles = []
    for seed in range(97400, 97406):
        scene = generate_scene(spec, seed=seed)
        assert not la.groups(scene.spec.extra, la.HOURGLASS_PREFIX)
        assert 2 <= len(la.groups(scene.spec.extra, la.DENTED_PREFIX)) <= 3
        angles += _lying_dent_angles_deg(scene.spec)
    assert len(angles) >= 4 and max(angles) > 90.0  # sideways and down among them
    up = [a for seed in (9400, 9401) for a in _lying_dent_angles_deg(generate_scene(load_spec(variant="lookalike"),
                                                                                    seed=seed).spec)]
    assert up and max(up) <= 60.0 + 1e-6
