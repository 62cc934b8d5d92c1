"""`gcs`: GCS over cached IRIS regions. Its path passes the validator, region building is offline
cost recorded apart from planning time, a world's regions are built once and reused from disk,
and a different world (held can, opening) does not reuse them; a region that is not really
collision-free gives a path the validator rejects (or, with the planner's own check, no path)."""

import json

import numpy as np
import pytest

from planners.base import PlanStatus
from planners.gcs import iris, regions
from planners.gcs.planner import GcsConfig, GcsPlanner
from planners.gcs.sets import WORLD_BUILT, RegionSet, problem_hash, world_hash
from planners.registry import make_planner
from planners.worlds import collision_world
from scenes.errors import SuiteError
from suite.run.trial import run_problem
from suite.scoring.validate import validate_path

# Small, fast regions for tests: IrisZo with one alternation (about 1 s a region on one core).
FAST = {"iris": "zo", "max_iterations": 1, "num_particles": 100, "check_rounds": 1}
#: The planning budget of tests whose outcome is not about the budget: a wide margin over what gcs
#: needs (under a second, or a few with an online region), so that a busy machine changes nothing;
#: gcs returns as soon as it has its answer.
ROOMY_S = 60.0


@pytest.fixture(scope="module")
def built(open_transit, tmp_path_factory):
    """One trial of gcs on the open transit with an empty region cache (regions built in prepare)."""
    cache = tmp_path_factory.mktemp("regions")
    grown_before = iris.GROWN_IN_PROCESS
    record = run_problem(open_transit.with_(time_limit_s=ROOMY_S), planner="gcs",
                         planner_config={**FAST, "regions_dir": str(cache)}, run_seed=0)
    return record, cache, iris.GROWN_IN_PROCESS - grown_before


def test_path_passes_the_validator_and_offline_time_is_recorded_apart(built, open_transit):
    record, cache, grown = built
    assert record.status == "success", record.stats
    path = np.asarray(record.path)
    assert validate_path(open_transit, path, collision_world(open_transit)) is None
    s = record.stats
    assert s["solver"] == "Clarabel" and s["iris"] == "zo"
    assert s["regions_cache"] == "built" and s["num_regions"] == grown >= 1
    # Building regions is offline: recorded as offline_s and in the set-up time, not in planning.
    assert s["offline_s"] > 0
    assert record.setup_time_s >= s["offline_s"] > record.planning_time_s - s["solve_time_s"]
    assert len(list(cache.glob("*.npz"))) == 1
    assert record.metrics["length_over_straight"] >= 1.0 - 1e-9


def test_second_prepare_reuses_the_cache(built, open_transit):
    record, cache, _ = built
    planner = GcsPlanner(GcsConfig(**FAST, regions_dir=str(cache)))  # a fresh process-level planner
    before = iris.GROWN_IN_PROCESS
    planner.prepare(open_transit)
    r = planner.plan(open_transit.with_(time_limit_s=ROOMY_S))
    assert iris.GROWN_IN_PROCESS == before
    assert r.status is PlanStatus.SUCCESS and r.stats["regions_cache"] == "hit"
    assert r.stats["offline_s"] == pytest.approx(record.stats["offline_s"])
    assert r.stats["world_hash"] == record.stats["world_hash"]


def test_a_different_world_misses_the_cache(built, open_transit):
    _, cache, _ = built
    options = GcsConfig(**FAST).region_options()
    h = world_hash(open_transit, options)
    other_can = open_transit.held.can if open_transit.held is not None else None
    assert other_can is not None  # a transit carries the can
    X_GC = open_transit.held.X_GC.copy()
    X_GC[2, 3] += 0.01
    moved = open_transit.with_(held=type(open_transit.held)(other_can, X_GC))
    assert world_hash(moved, options) != h
    assert world_hash(open_transit.with_(held=None), options) != h
    assert world_hash(open_transit.with_(gripper_opening_m=open_transit.gripper_opening_m + 0.01), options) != h
    assert world_hash(open_transit, GcsConfig(**{**FAST, "epsilon": 0.02}).region_options()) != h
    # Same world, other ends: same hash.
    assert world_hash(open_transit.with_(q_start=open_transit.q_goal, q_goal=open_transit.q_start), options) == h

    planner = GcsPlanner(GcsConfig(**FAST, regions_dir=str(cache), build_regions=False))
    r = planner.plan(moved)
    assert r.status is PlanStatus.NO_SOLUTION and r.stats["regions_cache"] == "miss"


def _invalid_region_cache(problem, directory, options):
    """A cache whose only region is the whole joint-limit box (it holds the wall)."""
    world = collision_world(problem)
    lo, hi = world.robot.lower_rad, world.robot.upper_rad
    A = np.vstack([np.eye(7), -np.eye(7)])
    b = np.concatenate([hi, -lo])
    h = world_hash(problem, options)
    rs = RegionSet(h, [A], [b], [np.asarray(problem.q_start, float)], [0.0], offline_s=1.0,
                   problems=[problem_hash(problem)], edges=[], iris=options.iris,
                   checked=[problem_hash(problem), WORLD_BUILT])
    rs.save(directory / f"{h}.npz")


def test_an_invalid_region_gives_a_path_the_validator_rejects(wall_transit, tmp_path):
    cfg = GcsConfig(**FAST, regions_dir=str(tmp_path), build_regions=False, max_repairs=0)
    _invalid_region_cache(wall_transit, tmp_path, cfg.region_options())
    record = run_problem(wall_transit.with_(time_limit_s=ROOMY_S), planner="gcs",
                         planner_config={**FAST, "regions_dir": str(tmp_path), "build_regions": False,
                                         "max_repairs": 0}, run_seed=0)
    assert record.stats["num_regions"] == 1 and record.stats["regions_cache"] == "hit"
    assert record.status == "invalid_solution"
    assert "collision" in record.stats["invalid_reason"]


def test_with_repairs_on_a_colliding_path_is_not_returned(wall_transit, tmp_path):
    # One convex region holding both ends holds the whole straight segment through the wall: no
    # face can cut the collision off, and the planner says so instead of returning the path.
    cfg = GcsConfig(**FAST, regions_dir=str(tmp_path), build_regions=False)
    assert cfg.max_repairs > 0
    _invalid_region_cache(wall_transit, tmp_path, cfg.region_options())
    r = GcsPlanner(cfg).plan(wall_transit.with_(time_limit_s=ROOMY_S))
    assert r.status is PlanStatus.NO_SOLUTION and r.path is None
    assert "collides" in r.stats["reason"]


def test_repairs_stopped_by_the_budget_are_a_timeout(wall_transit, tmp_path):
    # The same colliding region, with a budget spent before the first repair: that is the budget's
    # doing, not a proof that no path exists.
    cfg = GcsConfig(**FAST, regions_dir=str(tmp_path), build_regions=False)
    _invalid_region_cache(wall_transit, tmp_path, cfg.region_options())
    r = GcsPlanner(cfg).plan(wall_transit.with_(time_limit_s=1e-9))
    assert r.status is PlanStatus.TIMEOUT and r.path is None
    assert r.stats["timed_out"] and "budget" in r.stats["reason"]


def test_registry_and_config_errors():
    assert isinstance(make_planner("gcs"), GcsPlanner)
    with pytest.raises(SuiteError, match="iris"):
        GcsConfig(iris="iris2000")
    with pytest.raises(SuiteError, match="solver"):
        GcsConfig(solver="mosek")
    with pytest.raises(SuiteError, match="epsilon"):
        GcsConfig(epsilon=0.0)
    with pytest.raises(SuiteError, match="seeding"):
        GcsConfig(seeding="by-hand")
    with pytest.raises(SuiteError, match="min_clique"):
        GcsConfig(min_clique=3)


def test_regions_build_cli_builds_once_per_world(tmp_path, capsys):
    from suite.cli import main

    argv = ["regions", "build", "--dataset", "recycle-v1:quick", "--limit", "1", "--iris", "zo",
            "--jobs", "1", "--out", str(tmp_path)]
    assert main(argv) == 0
    (built,) = tmp_path.glob("*.npz")
    summary = json.loads((tmp_path / "build-quick.json").read_text())
    assert summary["worlds"] == 1 and summary["worlds_built_now"] == 1 and summary["iris"] == "zo"
    assert summary["worlds_detail"][0]["world_hash"] == built.stem and summary["offline_s_median"] > 0
    # each region's IRIS run is recorded (iterations, why it stopped), and the build's CPU time
    assert summary["iris_runs"]["regions_recorded"] == summary["worlds_detail"][0]["regions"] >= 1
    assert summary["iris_runs"]["iterations_max"] == 1 and summary["iris_runs"]["stop"] == {"iteration_limit": 1 * summary["iris_runs"]["regions_recorded"]}
    assert 0 < summary["worlds_detail"][0]["offline_cpu_s"] and RegionSet.load(built).offline_cpu_s > 0
    capsys.readouterr()
    assert main(argv) == 0  # the second build finds the world built and verified
    assert "(0 built now)" in capsys.readouterr().out
    assert main([*argv, "--rebuild"]) == 0  # --rebuild grows it again from nothing
    assert "(1 built now)" in capsys.readouterr().out
    assert main(["regions", "build", "--dataset", "recycle-v1:quick", "--scheduler", "tcp://h:1"]) == 2
    capsys.readouterr()
    # --tune-sample takes the tune split of a dataset named alone: a tier is one clear line
    assert main(["regions", "build", "--dataset", "recycle-v1:quick", "--tune-sample", "3", "--out", str(tmp_path)]) == 2
    assert "--dataset takes a dataset name" in capsys.readouterr().err


class _BallWorld:
    """A 7-D world whose only obstacle is a ball (what cut_regions asks of the python-fcl world)."""

    def __init__(self, center, radius):
        self.center, self.radius = np.asarray(center, float), radius

    def interpolate(self, path, resolution_rad):
        from scenes.collision.world import CollisionWorld

        return CollisionWorld.interpolate(path, resolution_rad)

    def first_collision(self, Q):
        bad = np.flatnonzero(np.linalg.norm(np.atleast_2d(Q) - self.center, axis=1) < self.radius)
        return int(bad[0]) if len(bad) else -1

    def motion_free(self, q0, q1, *, resolution_rad):
        return self.first_collision(self.interpolate(np.array([q0, q1]), resolution_rad)[1:]) < 0


def test_a_region_whose_start_goal_segment_collides_is_cut_keeping_both_covered():
    from planners.gcs.solve import cut_regions

    box = lambda lo, hi: (np.vstack([np.eye(7), -np.eye(7)]), np.concatenate([np.full(7, hi), -np.full(7, lo)]))
    q0, q1 = np.r_[-1.0, np.zeros(6)], np.r_[1.0, np.zeros(6)]
    (A0, b0), (A1, b1) = box(-1.5, 1.5), box(0.5, 1.5)  # region 0 holds both ends, region 1 the goal
    b1 = b1.copy()
    b1[1:7] = 0.2  # region 1: x in [0.5, 1.5], the other joints in [-0.5, 0.2]: around the goal
    b1[8:14] = 0.5
    A, b, edges = [A0, A1], [b0, b1], [(0, 1), (1, 0)]
    seeds = [np.r_[0.0, 1.0, np.zeros(5)], q1]
    world = _BallWorld(np.zeros(7), 0.3)  # between start and goal, on region 0's segment
    assert cut_regions(A, b, edges, seeds, np.zeros(7), keep=[q0, q1], world=world) == 1
    holds = lambda i, q: bool(np.all(A[i] @ q <= b[i] + 1e-9))
    assert not holds(0, np.zeros(7)) and holds(0, q0)  # the start, which only it holds, is kept
    assert holds(1, q1)  # the goal stays covered, by the region that was not cut


def test_a_region_cuts_left_empty_is_left_out_of_the_solve():
    """Drake's GcsTrajectoryOptimization throws on an empty region when it joins subgraphs
    ("Failed to compute the lower bound of a convex set"); solve_gcs leaves such a region out."""
    from planners.gcs.solve import solve_gcs, usable_regions

    faces = np.vstack([np.eye(7), -np.eye(7)])
    box = lambda lo, hi: np.concatenate([np.full(7, hi), -np.full(7, lo)])
    A = [faces, faces, faces]
    b = [box(-1.0, 1.0), box(0.5, 2.0), box(0.5, -1.0)]  # the third: x >= 0.5 and x <= -1, empty
    assert usable_regions(A, b) == [0, 1]
    traj, result = solve_gcs(A, b, [(0, 1), (1, 0), (1, 2), (2, 1)], np.zeros(7), np.full(7, 1.5))
    assert result.is_success()
    np.testing.assert_allclose(traj.value(traj.end_time()).ravel(), np.full(7, 1.5), atol=1e-6)


def _box(lo, hi):
    return np.vstack([np.eye(7), -np.eye(7)]), np.concatenate([np.asarray(hi, float), -np.asarray(lo, float)])


def test_an_end_outside_the_regions_is_joined_by_a_free_segment_to_the_nearest_region_it_reaches():
    from planners.gcs.solve import connect_ends, join_endpoint

    # Region 0 spans x in [0, 1], region 1 x in [0.8, 3]; both span [-1, 1] in the other joints.
    (A0, b0), (A1, b1) = _box([0.0] + [-1] * 6, [1.0] + [1] * 6), _box([0.8] + [-1] * 6, [3.0] + [1] * 6)
    A, b, edges = [A0, A1], [b0, b1], [(0, 1), (1, 0)]
    q = np.r_[-0.5, np.zeros(6)]  # outside both, 0.5 rad from region 0
    free = _BallWorld(np.full(7, 50.0), 0.1)
    regions, p, tried = join_endpoint(A, b, q, world=free, inset_rad=0.02)
    assert regions == [0] and tried == 1
    assert np.all(A0 @ p <= b0 + 1e-9) and 0.0 < p[0] <= 0.03  # just inside region 0's face
    # A ball on that segment: region 0 cannot be reached straight from q; nothing else can either
    # (region 1 lies behind region 0 along the same line).
    blocked = _BallWorld(np.r_[-0.25, np.zeros(6)], 0.1)
    assert join_endpoint(A, b, q, world=blocked)[0] == []
    # An end inside a region needs no segment.
    assert join_endpoint(A, b, np.r_[0.9, np.zeros(6)], world=blocked) == ([0, 1], None, 0)
    # Linked through the region graph: start joined to region 0, goal inside region 1 only.
    out = connect_ends(A, b, edges, q, np.r_[2.5, np.zeros(6)], world=free)
    assert out["connected"] and out["start_join"] == "segment" and out["goal_join"] == "inside"
    # Without the edge, the start is joined straight into the goal's region instead; if that
    # longer segment is blocked, the goal is joined into the start's region.
    out = connect_ends(A, b, [], q, np.r_[2.5, np.zeros(6)], world=free)
    assert out["connected"] and np.all(A1 @ out["ends"][0] <= b1 + 1e-9)
    beyond = _BallWorld(np.r_[0.5, np.zeros(6)], 0.1)
    out = connect_ends(A, b, [], q, np.r_[2.5, np.zeros(6)], world=beyond)
    assert out["connected"] and out["goal_join"] == "segment" and np.all(A0 @ out["ends"][1] <= b0 + 1e-9)


def test_chain_seeds_contain_consecutive_pieces_of_the_chain_within_the_cap():
    from planners.gcs.cover import chain_seeds

    chain = np.array([np.zeros(7), np.r_[2.0, np.zeros(6)], np.r_[2.0, 1.2, np.zeros(5)]])
    seeds = chain_seeds(chain, segment_rad=0.5, max_regions=12)
    assert len(seeds) == 4 + 3  # 2 rad in pieces of 0.5, then 1.2 rad in pieces of 0.4
    for (q, C), (_, C_next) in zip(seeds, seeds[1:]):
        np.testing.assert_allclose(q, C.mean(axis=1))  # the seed is the piece's midpoint
        np.testing.assert_allclose(C[:, 1], C_next[:, 0])  # consecutive pieces share an end
    np.testing.assert_allclose(seeds[0][1][:, 0], chain[0])
    np.testing.assert_allclose(seeds[-1][1][:, 1], chain[-1])
    assert max(np.linalg.norm(C[:, 1] - C[:, 0]) for _, C in seeds) <= 0.5 + 1e-9
    assert len(chain_seeds(chain, segment_rad=0.5, max_regions=3)) == 3  # the cap lengthens the pieces
    # More chain segments than the cap (up to twice it): one region per segment, each holding it.
    zigzag = np.array([np.r_[k * 0.3, (k % 2) * 0.3, np.zeros(5)] for k in range(12)])  # 11 segments
    seeds = chain_seeds(zigzag, segment_rad=0.5, max_regions=8)
    assert len(seeds) == 11
    for (q, C), a, b in zip(seeds, zigzag, zigzag[1:]):
        np.testing.assert_allclose(C, np.column_stack([a, b]))


def test_the_task_chain_is_the_worlds_alone(wall_transit):
    """World seeding reads the scene's task waypoints, never the problem's start or goal: two
    problems of one world with other ends get the same chain (and the same cache key)."""
    from planners.gcs.cover import task_chain

    chain, info = task_chain(wall_transit, seed=1234)
    other = wall_transit.with_(q_start=wall_transit.q_goal, q_goal=wall_transit.q_start)
    chain2, _ = task_chain(other, seed=1234)
    assert chain is not None and info["poses_solved"] >= 2
    np.testing.assert_allclose(chain, chain2)
    world = collision_world(wall_transit)
    assert world.path_free(chain, resolution_rad=0.01) < 0  # a free polyline
    options = GcsConfig().region_options()
    assert options.seeding == "chain" and world_hash(other, options) == world_hash(wall_transit, options)


def test_an_end_no_segment_joins_gets_an_online_region_in_planning_time(wall_transit, tmp_path):
    """A world whose only region is a small box around the goal: the start's straight segment to
    it crosses the wall. Without online regions that is `regions_disconnected` at once; with them,
    an IrisZo region grows around the start (inside the planning time) and holds it."""
    cfg = GcsConfig(**FAST, regions_dir=str(tmp_path), build_regions=False, online_iris=False)
    options = cfg.region_options()
    h = world_hash(wall_transit, options)
    q1 = np.asarray(wall_transit.q_goal, float)
    A = np.vstack([np.eye(7), -np.eye(7)])
    b = np.concatenate([q1 + 0.02, -(q1 - 0.02)])
    RegionSet(h, [A], [b], [q1], [0.0], offline_s=1.0, edges=[], iris=options.iris,
              checked=[WORLD_BUILT]).save(tmp_path / f"{h}.npz")
    problem = wall_transit.with_(time_limit_s=ROOMY_S)  # the online region grows in planning time
    r = GcsPlanner(cfg).plan(problem)
    assert r.status is PlanStatus.NO_SOLUTION and r.stats["reason_code"] == "regions_disconnected"
    assert r.stats["start_join"] == "none" and r.stats["goal_join"] == "inside" and r.stats["online_regions"] == 0
    assert "joins the start" in r.stats["reason"]
    planner = GcsPlanner(GcsConfig(**FAST, regions_dir=str(tmp_path), build_regions=False))
    planner.prepare(problem)
    r = planner.plan(problem)
    assert r.stats["online_regions"] == 1 and r.stats["start_join"] == "inside"
    assert r.stats["solve_time_s"] >= r.stats["join_s"] > 0


def test_shortcut_keeps_a_free_polyline_and_drops_what_a_straight_motion_spans():
    from planners.gcs.cover import shortcut

    # A dense path around a ball: its middle must stay off the ball, its ends are joined straight
    # wherever the ball allows.
    world = _BallWorld(np.r_[1.0, np.zeros(6)], 0.3)
    t = np.linspace(0.0, np.pi, 200)
    path = np.zeros((200, 7))
    path[:, 0] = 1.0 - np.cos(t)  # from x = 0 to x = 2, bulging to y = 0.6 around the ball
    path[:, 1] = 0.6 * np.sin(t)
    out = shortcut(path, world)
    assert 2 < len(out) < 20
    np.testing.assert_allclose(out[0], path[0])
    np.testing.assert_allclose(out[-1], path[-1])
    assert all(world.motion_free(a, b, resolution_rad=0.01) for a, b in zip(out, out[1:]))
    free = _BallWorld(np.full(7, 50.0), 0.1)
    assert len(shortcut(path, free)) == 2  # nothing in the way: one straight segment


def test_a_chain_with_more_segments_than_regions_is_cut_by_arc_length():
    from planners.gcs.cover import chain_seeds

    t = np.linspace(0.0, np.pi, 30)  # 29 segments, 8 regions at most
    chain = np.zeros((30, 7))
    chain[:, 0], chain[:, 1] = np.cos(t), np.sin(t)
    seeds = chain_seeds(chain, segment_rad=0.5, max_regions=8)
    assert len(seeds) == 8
    np.testing.assert_allclose(seeds[0][1][:, 0], chain[0])
    np.testing.assert_allclose(seeds[-1][1][:, -1], chain[-1], atol=1e-12)
    for (_, C), (_, C_next) in zip(seeds, seeds[1:]):
        np.testing.assert_allclose(C[:, -1], C_next[:, 0])  # consecutive stretches share an end
    for q, _ in seeds:  # every seed lies on the chain (the unit circle in the first two joints)
        assert abs(np.hypot(q[0], q[1]) - 1.0) < 0.01


def test_ends_in_parts_of_the_graph_that_do_not_meet_are_joined_across_by_a_segment():
    from planners.gcs.solve import connect_ends

    # Region 0: x in [0, 1]; region 1: x in [1.5, 3]; no edge. The start (x = 0.9) is in region 0,
    # the goal (x = 2.5) in region 1; a free straight segment from the start reaches region 1.
    (A0, b0), (A1, b1) = _box([0.0] + [-1] * 6, [1.0] + [1] * 6), _box([1.5] + [-1] * 6, [3.0] + [1] * 6)
    q0, q1 = np.r_[0.9, np.zeros(6)], np.r_[2.5, np.zeros(6)]
    free = _BallWorld(np.full(7, 50.0), 0.1)
    out = connect_ends([A0, A1], [b0, b1], [], q0, q1, world=free)
    assert out["connected"] and out["start_join"] == "segment" and out["goal_join"] == "inside"
    assert np.all(A1 @ out["ends"][0] <= b1 + 1e-9)  # GCS starts just inside region 1
    blocked = _BallWorld(np.r_[1.25, np.zeros(6)], 0.2)  # between the two regions
    assert not connect_ends([A0, A1], [b0, b1], [], q0, q1, world=blocked)["connected"]


@pytest.mark.slow
def test_world_regions_carry_a_window_return_through_the_opening(tmp_path):
    """The narrow passage (issue 31): a `window` return of recycle-v3's quick tier, regions built
    from its world alone (the task chain), planned by gcs and accepted by the validator."""
    from suite.problems.dataset import load_dataset

    ds = load_dataset("recycle-v3:quick")
    pid = next(i for i in ds.ids if ds.meta[i]["family"] == "window" and ds.meta[i]["kind"] == "return")
    problem = ds.problems[ds.ids.index(pid)].with_(time_limit_s=ROOMY_S)
    cfg = GcsConfig(regions_dir=str(tmp_path))
    rs, info = regions.regions_for(problem, cfg.region_options(), cache_dir=tmp_path, fresh=True)
    assert info["build"]["ends_connected"] and 2 <= len(rs) <= 2 * cfg.max_regions_per_world
    planner = GcsPlanner(cfg)
    planner.prepare(problem)
    r = planner.plan(problem)
    assert r.status is PlanStatus.SUCCESS, r.stats
    assert validate_path(problem, r.path, collision_world(problem)) is None
    assert r.stats["regions_cache"] == "hit" and r.stats["offline_s"] == pytest.approx(rs.offline_s)
