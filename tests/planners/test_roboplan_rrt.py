"""roboplan-rrt: the missing extra is one line naming it; with roboplan installed, its scene is the
python-fcl world's (verdicts, the held can's placement), it solves dataset problems that the
validator accepts, and its failures have honest statuses."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from planners.base import PlanStatus
from planners.registry import known_planners, parse_planner_list, planner_class
from scenes.errors import SuiteError

MISSING = "planner 'roboplan-rrt' needs the optional extra: pip install -e .[peers]"


@pytest.fixture
def without_roboplan(monkeypatch):
    """Make `roboplan` unimportable (as in a default install) and forget the modules that use it."""
    monkeypatch.setitem(sys.modules, "roboplan", None)
    for name in [m for m in sys.modules if m.startswith("roboplan.")] + ["planners.roboplan_rrt", "planners.roboplan_scene"]:
        monkeypatch.delitem(sys.modules, name, raising=False)


def test_missing_extra_is_one_line_naming_the_extra(without_roboplan):
    assert "roboplan-rrt" in known_planners()
    for call in (lambda: planner_class("roboplan-rrt"), lambda: parse_planner_list("rrt,roboplan-rrt")):
        with pytest.raises(SuiteError) as exc:
            call()
        assert str(exc.value) == MISSING
    assert planner_class("rrt").name == "rrt"  # the others are untouched


def test_missing_extra_from_the_cli_exits_2_with_one_line(without_roboplan, capsys, tmp_path):
    from suite.cli import main

    rc = main(["compare", "--planners", "rrt,roboplan-rrt", "--dataset", "recycle-v2.1:quick:family=window,kind=transit",
               "--out", str(tmp_path / "run"), "--no-progress"])
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert rc == 2
    assert err == [f"error: {MISSING}"]
    assert not (tmp_path / "run").exists()


# --- with roboplan ----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def roboplan():
    return pytest.importorskip("roboplan")


@pytest.fixture(scope="module")
def quick(roboplan):
    from suite.problems import DEFAULT_DATASET
    from suite.problems.dataset import load_dataset

    return load_dataset(f"{DEFAULT_DATASET}:quick")


def _first(ds, *, family: str, kind: str | None = None, held: bool | None = None):
    for pid, p in zip(ds.ids, ds.problems):
        m = ds.meta[pid]
        if m["family"] == family and kind in (None, m["kind"]) and held in (None, p.held is not None) and not m["trivial"]:
            return pid, p
    raise LookupError(f"no {family} {kind} problem")


@pytest.mark.parametrize("family, kind", [("open", None), ("wall", "transit")])
def test_solves_dataset_problems_and_the_validator_accepts(quick, family, kind):
    from suite.run.trial import run_problem

    pid, problem = _first(quick, family=family, kind=kind)
    # a budget with a wide margin: what is tested is the success, not how fast it comes
    rec = run_problem(problem.with_(time_limit_s=60.0), planner="roboplan-rrt", planner_config={}, run_seed=0)
    assert rec.status == "success", rec.stats  # success after the suite's validator and TOPP-RA
    assert rec.stats.get("invalid_reason") is None
    path = np.asarray(rec.path)
    assert np.allclose(path[0], problem.q_start, atol=1e-9) and np.allclose(path[-1], problem.q_goal, atol=1e-9)
    assert rec.planner_config == {} and rec.stats["resolution_rad"] == 0.01
    part = rec.attribution["parts"]["roboplan"]
    assert part["queries"] > 0 and part["timing"] == "lower_bound"


def test_scene_verdicts_agree_with_the_python_fcl_world(quick):
    from planners.roboplan_scene import build_roboplan_world
    from planners.worlds import collision_world

    _, problem = _first(quick, family="window", kind="transit")  # a held can and the window's frame
    world = collision_world(problem)
    rw = build_roboplan_world(world)
    Q = world.robot.random_configurations(np.random.default_rng(11), 400)
    fcl_free = np.array([world.is_free(q) for q in Q])
    rp_free = np.array([rw.is_free(q) for q in Q])
    assert 0.2 < fcl_free.mean() < 0.9  # both verdicts occur
    assert np.array_equal(fcl_free, rp_free)


def test_held_can_sits_where_the_python_fcl_world_puts_it(quick):
    """Probe spheres (1 mm) at points just inside and just outside the held can's surface, as the
    python-fcl world places it: roboplan must find the inside ones in contact with its held can and
    the outside ones free. A can off by centimetres (roboplan's frame-offset quirk) fails this."""
    import fcl
    import roboplan.core as rpc

    from planners.roboplan_scene import HELD_CAN, WORLD_FRAME, build_roboplan_world
    from planners.worlds import collision_world

    _, problem = _first(quick, family="wall", kind="transit", held=True)
    world = collision_world(problem)
    rw = build_roboplan_world(world)
    (part,) = [p for p in world.parts if p.name == HELD_CAN]
    r_m, h_m = part.dims
    probe_r = 0.001
    for q in (problem.q_start, problem.q_goal):
        X_WC = world.robot.link_poses(q)[part.body] @ part.X_BS
        assert np.allclose(np.asarray(rw.scene.forwardKinematics(q, HELD_CAN)), X_WC, atol=1e-12)
        for p_C, inside in [((r_m - 0.002, 0, 0), True), ((r_m + 0.002, 0, 0), False), ((0, -r_m + 0.002, 0), True),
                            ((0, r_m + 0.002, 0), False), ((0, 0, h_m / 2 - 0.002), True), ((0, 0, -h_m / 2 - 0.002), False)]:
            p_W = X_WC[:3, :3] @ np.asarray(p_C) + X_WC[:3, 3]
            X_WP = np.eye(4)
            X_WP[:3, 3] = p_W
            scene = rw.scene
            scene.addSphereGeometry("probe", WORLD_FRAME, rpc.Sphere(probe_r), np.asfortranarray(X_WP), np.ones(4))
            try:
                others = [b for b in rw.robot_bodies if b != HELD_CAN] + [o[0] for o in rw.obstacles]
                scene.setCollisions([(b, "probe") for b in others], False)
                rp_hit = scene.hasCollisions(np.asarray(q, float))
            finally:
                scene.removeGeometry("probe")
            probe = fcl.CollisionObject(fcl.Sphere(probe_r), fcl.Transform(p_W))
            can = fcl.CollisionObject(fcl.Cylinder(r_m, h_m), fcl.Transform(X_WC[:3, :3], X_WC[:3, 3]))
            fcl_hit = fcl.collide(probe, can, fcl.CollisionRequest(), fcl.CollisionResult()) > 0
            assert rp_hit == fcl_hit == inside, (p_C, rp_hit, fcl_hit)
        assert rw.is_free(q)  # the probe is gone again


def test_failures_have_honest_statuses(quick):
    from planners.roboplan_rrt import RoboplanRRTConfig, RoboplanRRTPlanner

    _, problem = _first(quick, family="window", kind="return")
    nodes = RoboplanRRTPlanner(RoboplanRRTConfig(max_nodes=2)).plan(problem)
    assert nodes.status is PlanStatus.NO_SOLUTION and "maximum number of nodes" in nodes.stats["reason"]
    late = RoboplanRRTPlanner(RoboplanRRTConfig(time_limit_s=0.002, shortcut=False)).plan(problem)
    assert late.status is PlanStatus.TIMEOUT and late.path is None
    start_in_collision = problem.with_(q_start=np.zeros(7) + np.array([0, 2.0, 0, -2.0, 0, 2.0, 0]))
    from planners.worlds import collision_world

    assert not collision_world(problem).is_free(start_in_collision.q_start)
    assert RoboplanRRTPlanner().plan(start_in_collision).status is PlanStatus.INVALID_START
    with pytest.raises(SuiteError, match="collision_check_step_rad"):
        RoboplanRRTConfig(collision_check_step_rad=0.0)
