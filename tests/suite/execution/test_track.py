"""Release on the move: the gripper follows the bin at its velocity from a real drop pose."""

import numpy as np
import pytest

from scenes.drake_scene import build_drake_scene
from scenes.ik import Q_READY, PoseIk
from scenes.moving_bin import drop_pose
from scenes.robot_model import load_robot
from scenes.scene import Scene
from scenes.spec import load_spec
from suite.execution import track
from suite.execution.commands import CommandStream
from suite.execution.config import ExecutionConfig

V_XY = np.array([0.3, -0.1])
RAMP_S, DURATION_S = 0.15, 0.65


@pytest.fixture(scope="module")
def drop():
    """The robot name and an arm configuration at the open family's drop pose over the bin's place."""
    spec = load_spec(variant="open")
    X = drop_pose(spec, spec.bin.center_xy_m)
    q = PoseIk(build_drake_scene(Scene(spec, 0, ()), mode="plan", cameras=False)).solve(
        X, q_seed=Q_READY, rng=np.random.default_rng(0))
    assert q is not None
    assert np.linalg.norm(load_robot(spec.robot).gripper_pose(q[None])[0][:3, 3] - X[:3, 3]) < 2e-3
    return spec.robot, q


def _rotation_angle(R: np.ndarray) -> float:
    return float(np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0)))


def test_the_plants_frame_is_the_robot_models_gripper_frame(drop):
    name, _ = drop
    robot = load_robot(name)
    plant, G = track._arm(name)
    ctx = plant.CreateDefaultContext()
    rng = np.random.default_rng(4)
    for q in robot.random_configurations(rng, 5):
        plant.SetPositions(ctx, q)
        X = plant.CalcRelativeTransform(ctx, plant.world_frame(), G).GetAsMatrix4()
        assert np.max(np.abs(X - robot.gripper_pose(q[None])[0])) < 1e-6
        qd = rng.uniform(-1, 1, 7)
        h = 1e-6
        fd = (robot.gripper_pose((q + h * qd)[None])[0] - robot.gripper_pose((q - h * qd)[None])[0])[:2, 3] / (2 * h)
        assert np.allclose(track.gripper_velocity_xy(name, q, qd), fd, atol=1e-6)


def test_the_gripper_follows_the_bin_at_its_velocity(drop):
    name, q0 = drop
    robot = load_robot(name)
    tr = track.tracking_motion(name, q0, V_XY, ramp_s=RAMP_S, duration_s=DURATION_S)
    assert tr is not None and tr.ok and tr.duration_s == DURATION_S
    assert np.array_equal(tr.q[0], q0) and np.all(tr.qd[0] == 0)
    X0, X1 = robot.gripper_pose(np.stack([q0, tr.q[-1]]))
    moved = X1[:2, 3] - X0[:2, 3]
    assert np.linalg.norm(moved - V_XY * (DURATION_S - RAMP_S / 2)) < 5e-3
    assert np.allclose(V_XY * DURATION_S - moved, track.ramp_lag_m(V_XY, RAMP_S), atol=5e-3)
    assert abs(X1[2, 3] - X0[2, 3]) < 2e-3
    assert _rotation_angle(X1[:3, :3] @ X0[:3, :3].T) < 0.01
    # the gripper's speed follows the smoothstep ramp, and it ends moving with the bin
    u = np.minimum(tr.t_s / RAMP_S, 1.0)
    speed = np.array([track.gripper_velocity_xy(name, q, qd) for q, qd in zip(tr.q, tr.qd)])
    assert np.max(np.abs(speed - V_XY * (3 * u**2 - 2 * u**3)[:, None])) < 2e-3
    assert np.allclose(track.gripper_velocity_xy(name, tr.q[-1], tr.qd[-1]), V_XY, atol=2e-3)
    assert np.linalg.norm(track.gripper_velocity_xy(name, tr.q[-1], tr.qd[-1])) > 0.3

    # the samples: within the velocity limits, continuous, height and orientation held all along
    dt = 1e-3
    t = np.arange(0.0, DURATION_S + dt / 2, dt)
    q, v, a = tr.sample(t)
    assert q.shape == v.shape == a.shape == (len(t), 7)
    assert np.all(np.abs(v) <= robot.velocity_limits_rad_s * (1 + 1e-6))
    assert np.all(np.abs(np.diff(q, axis=0)) <= robot.velocity_limits_rad_s * dt)
    assert np.all(np.abs(np.diff(v, axis=0)) <= robot.acceleration_limits_rad_s2 * dt)
    X = robot.gripper_pose(q)
    assert np.max(np.abs(X[:, 2, 3] - X0[2, 3])) < 2e-3
    assert max(_rotation_angle(R @ X0[:3, :3].T) for R in X[::10, :3, :3]) < 0.01
    assert np.allclose(q[0], q0) and np.allclose(v[0], 0.0) and np.allclose(q[-1], tr.q[-1])
    q_s, v_s, a_s = tr.sample(DURATION_S + 1.0)  # clipped
    assert q_s.shape == (7,) and np.allclose(q_s, tr.q[-1]) and np.allclose(v_s, tr.qd[-1])


def test_no_velocity_stays_at_the_start(drop):
    name, q0 = drop
    tr = track.tracking_motion(name, q0, np.zeros(2), ramp_s=RAMP_S, duration_s=DURATION_S)
    assert tr is not None
    q, v, _ = tr.sample(np.linspace(0, DURATION_S, 50))
    assert np.allclose(q, q0, atol=1e-9) and np.allclose(v, 0.0, atol=1e-9)


def test_a_velocity_the_arm_cannot_give_is_refused(drop):
    name, q0 = drop
    # refused by differential IK itself (5 m/s), and for falling behind (1 m/s: the elbow's speed limit)
    for v in ([5.0, 0.0], [1.0, 0.0]):
        assert track.tracking_motion(name, q0, np.array(v), ramp_s=RAMP_S, duration_s=DURATION_S) is None
    with pytest.raises(ValueError, match="ramp_s"):
        track.tracking_motion(name, q0, V_XY, ramp_s=1.0, duration_s=DURATION_S)


def test_the_command_stream_plays_it(drop):
    name, q0 = drop
    tr = track.tracking_motion(name, q0, V_XY, ramp_s=RAMP_S, duration_s=DURATION_S)
    st = CommandStream(q_home=q0, open_width_m=0.1, config=ExecutionConfig())
    st.append_hold("wait", 0, 0.2, width_from_m=0.0, carrying=True)
    st.append_motion("track", 0, tr, width_m=0.0, carrying=True)
    assert st.duration_s == pytest.approx(0.2 + DURATION_S)
    assert np.array_equal(st.q_end, tr.q[-1])
    for t in (0.1, 0.2, 0.3, 0.2 + DURATION_S):
        expect = tr.sample(t - 0.2) if t >= 0.2 else (q0, np.zeros(7), np.zeros(7))
        for got, want in zip(st.state(t), expect):
            assert np.allclose(got, want)


def test_the_pose_feedback_keeps_a_long_follow_on_course(drop):
    name, q0 = drop
    robot = load_robot(name)
    v = np.array([-0.1, 0.05])
    tr = track.tracking_motion(name, q0, v, ramp_s=RAMP_S, duration_s=2.0, dt_s=0.02)
    assert tr is not None
    X0, X1 = robot.gripper_pose(np.stack([q0, tr.q[-1]]))
    assert np.linalg.norm(X1[:3, 3] - X0[:3, 3] - np.append(v * (2.0 - RAMP_S / 2), 0.0)) < 1e-3
    assert _rotation_angle(X1[:3, :3] @ X0[:3, :3].T) < 1e-3


def test_a_release_re_aimed_from_a_moving_start_joins_it_and_reaches_the_new_velocity(drop):
    """Re-aimed at a new estimate mid-release: the motion starts in the commanded state (q, qd) of
    the one it replaces and carries the gripper at the new velocity once its ramp is over."""
    name, q0 = drop
    first = track.tracking_motion(name, q0, V_XY, ramp_s=RAMP_S, duration_s=DURATION_S)
    t_s = RAMP_S / 2
    q_s, qd_s, _ = first.sample(t_s)
    v_new = np.array([0.1, -0.15])
    again = track.tracking_motion(name, q_s, v_new, ramp_s=RAMP_S, duration_s=DURATION_S - t_s, qd0=qd_s)
    assert again is not None
    q, qd, _ = again.sample(0.0)
    assert np.allclose(q, q_s) and np.allclose(qd, qd_s)
    v_end = track.gripper_velocity_xy(name, again.q[-1], again.qd[-1])
    assert np.linalg.norm(v_end - v_new) < 0.01, v_end
    v_start = track.gripper_velocity_xy(name, q_s, qd_s)
    assert np.linalg.norm(v_start - v_new) > 0.05  # a real change of course
