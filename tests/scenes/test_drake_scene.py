"""The Drake scene: sim mode with free cans and cameras, plan mode with exactly the arm's joints."""

import numpy as np

from scenes.drake_scene import build_drake_scene, look_at
from scenes.render import render


def test_sim_mode_free_cans(open_scene):
    ds = build_drake_scene(open_scene, mode="sim", cameras=False)
    n = len(open_scene.cans)
    assert ds.plant.num_positions() == 7 + 2 + 7 * n
    ctx = ds.plant.CreateDefaultContext()
    for can in open_scene.cans:
        X = ds.plant.EvalBodyPoseInWorld(ctx, ds.plant.GetBodyByName(f"can_{can.id}"))
        np.testing.assert_allclose(X.translation(), can.p_WC_m, atol=1e-12)


def test_plan_mode_is_the_arm(open_scene):
    ds = build_drake_scene(open_scene, mode="plan", cameras=False)
    assert ds.plant.num_positions() == 7


def test_top_camera_sees_red_cans_on_grey_plate(open_scene):
    img = render(open_scene, cameras=["top"])["top"]
    assert img.rgb.shape == (480, 640, 3) and img.depth_m.shape == (480, 640)
    rgb = img.rgb.astype(int)
    red = (rgb[..., 0] > 150) & (rgb[..., 1] < 60) & (rgb[..., 2] < 60)
    grey = (np.abs(rgb[..., 0] - rgb[..., 1]) < 10) & (np.abs(rgb[..., 1] - rgb[..., 2]) < 10) & (rgb[..., 0] > 100)
    assert red.sum() > 3 * 1500  # three cans of >= 1500 px each
    assert grey.sum() > 20000
    centre_depth = img.depth_m[240, 320]
    cam_z = open_scene.spec.cameras.poses["top"].p_m[2]
    assert 0.4 < centre_depth <= cam_z - open_scene.spec.plate_top_z_m + 1e-3


def test_look_at_points_the_optical_axis():
    X = look_at([1.0, 0.0, 1.0], [0.0, 0.0, 0.0])
    z = X.rotation().matrix()[:, 2]
    np.testing.assert_allclose(z, np.array([-1, 0, -1]) / np.sqrt(2), atol=1e-12)
    y = X.rotation().matrix()[:, 1]
    assert y[2] < 0  # image down is world down
