"""The seed paper's look-alikes: the top camera's pipeline grasps a red hourglass as a can; the
robust pipeline's side check refuses it; dented cans standing upright are still grasped."""

from __future__ import annotations

import pytest

from perception.evaluate import match_lookalikes, match_scene
from perception.grasps import PerceptionParams, detect_cans
from perception.observe import observe
from perception.robust import detect_cans_robust
from perception.side_view import SideView, looks_alike
from scenes.generate import generate_scene
from scenes.spec import load_spec


def test_a_side_narrower_than_a_cans_in_every_camera_that_sees_it_is_a_lookalike():
    r, tol = 0.033, 0.005
    waist, can, hidden = SideView("front", 200, 0.021), SideView("back", 200, 0.032), SideView("back", 3, 0.010)
    assert looks_alike([waist, hidden], radius_m=r, tolerance_m=tol)
    assert not looks_alike([waist, can], radius_m=r, tolerance_m=tol)  # a dent faces one camera only
    assert not looks_alike([hidden], radius_m=r, tolerance_m=tol)  # nobody sees it: the top view cannot tell


@pytest.fixture(scope="module")
def lookalike_frames():
    # lookalike seed 9403 (a tuning seed): one hourglass, one upright dented can, 7 cans
    scene = generate_scene(load_spec(variant="lookalike"), seed=9403)
    return scene, observe(scene, cameras=["top", "front", "back"])


def test_the_paper_pipeline_grasps_the_hourglass_and_the_robust_one_refuses_it(lookalike_frames):
    scene, images = lookalike_frames
    paper, _ = detect_cans(images["top"], scene.spec, PerceptionParams(segmentation="geometric"))
    assert match_lookalikes(paper, scene).hourglass_grasps == 1
    robust, _, _ = detect_cans_robust(images["top"], scene.spec, side_images={k: images[k] for k in ("front", "back")})
    look = match_lookalikes(robust, scene)
    assert look.hourglasses == 1 and look.hourglass_grasps == 0
    assert look.dented == 1 and len(look.dented_xy_error_m) == 1 and look.dented_xy_error_m[0] < 0.002
    m = match_scene(robust, scene)
    assert len(m.pairs) == m.n_truth  # no can refused as a look-alike
