"""`python -m suite bench agreement`: roboplan's model of each world against the python-fcl world.

`roboplan-rrt` plans on a roboplan scene built from the suite's models (`planners.roboplan_scene`).
This check asks whether that scene is the suite's: for each family of a dataset, it takes the
distinct collision worlds of the family's problems (empty hand, held can, cans already removed),
draws configurations in them and compares roboplan's `Scene.hasCollisions` with
`CollisionWorld.is_free`, the verdict the validator uses:

- uniform in the joint limits (most of them), and
- near the problems: a start, a goal or a point of the stored reference path, moved by a normal
  step of 0.01, 0.05 or 0.2 rad per joint, so that configurations near contact are well
  represented (the reference paths run along the obstacles).

Each disagreement is measured pair by pair (`suite.bench.agreement_pairs`) and classified. On a
sample of the configurations it also compares the poses roboplan's kinematics gives every body
with the suite's, and both libraries' signed distances of every pair within 5 cm.

The same configurations are timed in both engines (each in its own loop: state checks per second,
a Python call each): `CollisionWorld.is_free` against roboplan's `Scene.hasCollisions`.
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import json
import time
from pathlib import Path

import numpy as np

from scenes.errors import SuiteError
from suite.cli.args import positive_int

CONFIG_SEED = 20251125
NEAR_STEPS_RAD = (0.01, 0.05, 0.2)
#: Bodies whose roboplan pose is compared with the suite's kinematics.
POSE_FRAMES = tuple(f"iiwa_link_{i}" for i in range(8)) + ("body",)
NEAR_PAIR_M = 0.05


def add_arguments(p: argparse.ArgumentParser) -> None:
    from suite.problems import DEFAULT_DATASET

    p.add_argument("--configs", type=positive_int, default=10_000, help="configurations per family (default 10000)")
    p.add_argument("--families", default=None, help="comma-separated families (default: every family of the dataset)")
    p.add_argument("--dataset", default=DEFAULT_DATASET, help=f"dataset NAME[:TIER] (default {DEFAULT_DATASET})")
    p.add_argument("--worlds", type=positive_int, default=24,
                   help="most distinct collision worlds per family (default 24; spread over held / empty hand)")
    p.add_argument("--near-share", type=float, default=0.4,
                   help="share of configurations drawn near the problems' starts, goals and reference paths (default 0.4)")
    p.add_argument("--distance-configs", type=positive_int, default=200,
                   help="configurations per family whose poses and pair distances are compared (default 200)")
    p.add_argument("--self-sweep", type=int, default=10_000,
                   help="configurations of a pair-by-pair sweep of the robot's own pairs, uniform in the limits, "
                        "held can included (default 10000; 0 to skip)")
    p.add_argument("--json", type=Path, default=None, help="also write the figures and every disagreement here")


def _family_worlds(ds, family: str, most: int) -> list[tuple]:
    """Up to `most` distinct worlds of a family's problems: (a problem of it, the endpoints and
    reference paths of all its problems), alternating between held-can and empty-hand worlds."""
    by_world: dict[tuple, list] = collections.OrderedDict()
    for pid, p in zip(ds.ids, ds.problems):
        if ds.meta[pid].get("family") == family:
            by_world.setdefault(p.world_key(), []).append((p, ds.references.get(pid)))
    held = [v for v in by_world.values() if v[0][0].held is not None]
    empty = [v for v in by_world.values() if v[0][0].held is None]
    chosen = []
    for i in range(max(len(held), len(empty))):
        for group in (held, empty):
            if i < len(group) and len(chosen) < most:
                chosen.append(group[i])
    return chosen


def _configurations(robot, entries, n: int, near_share: float, rng: np.random.Generator) -> np.ndarray:
    lo, hi = robot.lower_rad, robot.upper_rad
    n_near = int(round(n * near_share))
    Q = robot.random_configurations(rng, n - n_near)
    anchors = []
    for p, ref in entries:
        anchors += [np.asarray(p.q_start, float), np.asarray(p.q_goal, float)]
        if ref is not None and len(ref) > 1:
            seg = rng.integers(0, len(ref) - 1, size=4)
            t = rng.uniform(size=(4, 1))
            anchors += list(ref[seg] + t * (ref[seg + 1] - ref[seg]))
    A = np.asarray(anchors)[rng.integers(0, len(anchors), size=n_near)]
    step = np.asarray(NEAR_STEPS_RAD)[rng.integers(0, len(NEAR_STEPS_RAD), size=n_near)]
    near = np.clip(A + rng.normal(size=A.shape) * step[:, None], lo, hi)
    return np.vstack([Q, near])


def _time_loop(check, Q) -> tuple[np.ndarray, float]:
    out = np.empty(len(Q), bool)
    t = time.perf_counter()
    for m, q in enumerate(Q):
        out[m] = check(q)
    return out, time.perf_counter() - t


def segment_distance(p1: np.ndarray, q1: np.ndarray, p2: np.ndarray, q2: np.ndarray) -> float:
    """The exact distance between segments p1-q1 and p2-q2 (Ericson, Real-Time Collision
    Detection, 5.1.9): the reference for a capsule pair (minus both radii)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e, f, c, b = d1 @ d1, d2 @ d2, d2 @ r, d1 @ r, d1 @ d2
    den = a * e - b * b
    s = float(np.clip((b * f - c * e) / den, 0.0, 1.0)) if den > 1e-15 else 0.0
    t = (b * s + f) / e
    if t < 0:
        t, s = 0.0, float(np.clip(-c / a, 0.0, 1.0))
    elif t > 1:
        t, s = 1.0, float(np.clip((b - c) / a, 0.0, 1.0))
    return float(np.linalg.norm(p1 + d1 * s - (p2 + d2 * t)))


def _capsule_exact(meter, pair, poses) -> float:
    ends, radii = [], []
    for name in pair:
        _kind, (r, length), _ = meter.items[name]
        X = poses[name]
        ends += [X[:3, 3] - X[:3, 2] * length / 2, X[:3, 3] + X[:3, 2] * length / 2]
        radii.append(r)
    return segment_distance(*ends) - sum(radii)


def _pose_and_distance_checks(world, rw, meter, Q) -> dict:
    """Max pose error of roboplan's kinematics against the suite's, and the signed distances of
    both libraries for every counted pair within NEAR_PAIR_M."""
    max_dp, max_dR, diffs, capsule_err = 0.0, 0.0, [], []
    for q in Q:
        X_suite = world.robot.link_poses(q)
        for i, frame in enumerate(POSE_FRAMES):
            X_rp = np.asarray(rw.scene.forwardKinematics(np.asarray(q, float), frame))
            max_dp = max(max_dp, float(np.max(np.abs(X_rp[:3, 3] - X_suite[i][:3, 3]))))
            max_dR = max(max_dR, float(np.max(np.abs(X_rp[:3, :3] - X_suite[i][:3, :3]))))
        poses = meter.poses(q)
        for pair in meter.pairs:
            m = meter.measure(q, pair, poses)
            if min(m.fcl_distance_m, m.coal_distance_m) < NEAR_PAIR_M:
                diffs.append((m.fcl_distance_m, m.coal_distance_m, m.shapes))
                if m.shapes == "capsule-capsule" and m.fcl_distance_m > 1e-6:
                    exact = _capsule_exact(meter, pair, poses)
                    capsule_err.append((abs(m.fcl_distance_m - exact), abs(m.coal_distance_m - exact)))
    d = np.array([(a, b) for a, b, _ in diffs]) if diffs else np.zeros((0, 2))
    apart = d[:, 0] > 1e-6 if len(d) else np.zeros(0, bool)
    by_shapes: dict[str, float] = collections.defaultdict(float)
    for (a, b, shapes), ok in zip(diffs, apart):
        if ok:
            by_shapes[shapes] = max(by_shapes[shapes], abs(a - b))
    return {
        "pose_max_translation_m": max_dp, "pose_max_rotation_entry": max_dR,
        "near_pairs": int(len(d)),
        "apart_pairs": int(apart.sum()),
        "apart_max_abs_diff_m": float(np.max(np.abs(d[apart, 0] - d[apart, 1]))) if apart.any() else None,
        "penetrating_pairs": int((~apart).sum()),
        "penetrating_max_abs_diff_m": float(np.max(np.abs(d[~apart, 0] - d[~apart, 1]))) if (~apart).any() else None,
        "apart_max_abs_diff_by_shapes_m": dict(by_shapes),
        "capsule_pairs": len(capsule_err),
        "capsule_fcl_max_error_m": max((a for a, _ in capsule_err), default=None),
        "capsule_coal_max_error_m": max((b for _, b in capsule_err), default=None),
    }


def bench_family(ds, family: str, args: argparse.Namespace) -> dict:
    """Agreement, disagreements by kind and checks/s for one family."""
    from planners.roboplan_scene import build_roboplan_world
    from planners.worlds import collision_world
    from suite.bench.agreement_pairs import PairMeter, diagnose

    worlds = _family_worlds(ds, family, args.worlds)
    if not worlds:
        raise SuiteError(f"dataset {ds.name!r} has no family {family!r}")
    rng = np.random.default_rng([CONFIG_SEED, sum(map(ord, family))])
    share = np.full(len(worlds), args.configs // len(worlds))
    share[: args.configs % len(worlds)] += 1
    n_dist = np.full(len(worlds), args.distance_configs // len(worlds))
    n_dist[: args.distance_configs % len(worlds)] += 1
    row = {"family": family, "worlds": len(worlds), "held_worlds": sum(e[0][0].held is not None for e in worlds),
           "configs": 0, "near_configs": 0, "fcl_free": 0, "agree": 0, "disagreements": [],
           "fcl_s": 0.0, "roboplan_s": 0.0, "pose_and_distance": []}
    for entries, n, nd in zip(worlds, share, n_dist):
        if n == 0:
            continue
        problem = entries[0][0]
        world = collision_world(problem)
        rw = build_roboplan_world(world)
        Q = _configurations(world.robot, entries, int(n), args.near_share, rng)
        for q in Q[:20]:  # first-call costs out of the timing
            world.is_free(q)
            rw.is_free(q)
        a, t_a = _time_loop(world.is_free, Q)
        b, t_b = _time_loop(rw.is_free, Q)
        row["configs"] += len(Q)
        row["near_configs"] += int(round(len(Q) * args.near_share))
        row["fcl_free"] += int(a.sum())
        row["agree"] += int((a == b).sum())
        row["fcl_s"] += t_a
        row["roboplan_s"] += t_b
        meter = PairMeter(world, rw)
        for m in np.flatnonzero(a != b):
            d = diagnose(meter, rw, Q[m], fcl_free=bool(a[m]), roboplan_free=bool(b[m]))
            row["disagreements"].append({
                "kind": d.kind, "fcl_free": d.fcl_free, "roboplan_free": d.roboplan_free,
                "held": problem.held is not None, "q": Q[m].round(12).tolist(),
                "roboplan_pairs": [list(p) for p in d.roboplan_pairs],
                "pairs": [dataclasses.asdict(p) for p in d.pairs],
            })
        if nd:
            row["pose_and_distance"].append(_pose_and_distance_checks(world, rw, meter, Q[rng.permutation(len(Q))[:nd]]))
    return row


def self_pair_sweep(ds, n: int) -> dict:
    """Every counted robot self pair (held can included) measured at n uniform configurations:
    per pair, how often it penetrates deeper than SHALLOW_M by python-fcl's signed distance, and
    how often coal's boolean collide (pinocchio's request, roboplan's order), its swapped order
    and python-fcl's collide miss such a penetration."""
    from planners.roboplan_scene import build_roboplan_world
    from planners.worlds import collision_world
    from suite.bench.agreement_pairs import SHALLOW_M, PairMeter

    problem = next(p for p in ds.problems if p.held is not None)
    world = collision_world(problem)
    rw = build_roboplan_world(world)
    meter = PairMeter(world, rw)
    pairs = [pp for pp in meter.pairs if pp[0] in rw.robot_bodies and pp[1] in rw.robot_bodies]
    counts: dict[str, collections.Counter] = {f"{a}-{b}": collections.Counter() for a, b in pairs}
    rng = np.random.default_rng([CONFIG_SEED, 7])
    for q in world.robot.random_configurations(rng, n):
        poses = meter.poses(q)
        for a, b in pairs:
            m = meter.measure(q, (a, b), poses)
            if m.fcl_distance_m < -SHALLOW_M:
                c = counts[f"{a}-{b}"]
                c.update(penetrating=1, coal_misses=int(not m.coal_collide),
                         coal_swapped_misses=int(not m.coal_collide_swapped), fcl_misses=int(not m.fcl_collide))
                c["deepest_m"] = max(c["deepest_m"], -m.fcl_distance_m)
    return {"configs": n, "pairs": {k: dict(v) for k, v in counts.items() if v}}


def _merge_pose(parts: list[dict]) -> dict:
    def mx(key):
        vals = [p[key] for p in parts if p.get(key) is not None]
        return max(vals) if vals else None

    shapes: dict[str, float] = {}
    for p in parts:
        for k, v in p["apart_max_abs_diff_by_shapes_m"].items():
            shapes[k] = max(shapes.get(k, 0.0), v)
    return {"pose_max_translation_m": mx("pose_max_translation_m"), "pose_max_rotation_entry": mx("pose_max_rotation_entry"),
            "near_pairs": sum(p["near_pairs"] for p in parts), "apart_pairs": sum(p["apart_pairs"] for p in parts),
            "apart_max_abs_diff_m": mx("apart_max_abs_diff_m"), "penetrating_pairs": sum(p["penetrating_pairs"] for p in parts),
            "penetrating_max_abs_diff_m": mx("penetrating_max_abs_diff_m"), "apart_max_abs_diff_by_shapes_m": shapes,
            "capsule_pairs": sum(p["capsule_pairs"] for p in parts), "capsule_fcl_max_error_m": mx("capsule_fcl_max_error_m"),
            "capsule_coal_max_error_m": mx("capsule_coal_max_error_m")}


def _fmt_m(v) -> str:
    return "-" if v is None else f"{v:.2g}"


def run(args: argparse.Namespace) -> int:
    from planners.registry import check_available
    from suite.problems.dataset import load_dataset

    check_available("roboplan-rrt")
    if not 0 <= args.near_share <= 1:
        raise SuiteError(f"--near-share must be in [0, 1], got {args.near_share!r}")
    ds = load_dataset(args.dataset)
    present = sorted({m.get("family") for m in ds.meta.values()})
    families = present if args.families is None else [f.strip() for f in args.families.split(",") if f.strip()]
    for f in families:
        if f not in present:
            raise SuiteError(f"dataset {args.dataset!r} has no family {f!r}; allowed: {', '.join(present)}")
    rows = []
    for f in families:
        t = time.perf_counter()
        rows.append(bench_family(ds, f, args))
        rows[-1]["wall_s"] = time.perf_counter() - t
    print(f"model agreement: roboplan {_roboplan_version()} (coal) scene vs the python-fcl world, dataset "
          f"{ds.name}:{ds.tier}; per family up to {args.worlds} worlds, {args.configs} configurations "
          f"({1 - args.near_share:.0%} uniform in the joint limits, {args.near_share:.0%} near starts, goals and "
          f"reference paths, steps {', '.join(map(str, NEAR_STEPS_RAD))} rad), seed {CONFIG_SEED}")
    head = ("family", "worlds (held)", "configs", "fcl free", "agree", "disagree", "fcl checks/s", "roboplan checks/s", "ratio")
    lines = [head]
    tot = collections.Counter()
    for r in rows:
        n_dis = len(r["disagreements"])
        lines.append((r["family"], f"{r['worlds']} ({r['held_worlds']})", r["configs"], r["fcl_free"], r["agree"], n_dis,
                      f"{r['configs'] / r['fcl_s']:,.0f}", f"{r['configs'] / r['roboplan_s']:,.0f}",
                      f"{r['fcl_s'] / r['roboplan_s']:.2f}"))
        tot.update(configs=r["configs"], free=r["fcl_free"], agree=r["agree"], dis=n_dis)
        tot["fcl_s"] += r["fcl_s"]
        tot["rp_s"] += r["roboplan_s"]
    lines.append(("all", "", tot["configs"], tot["free"], tot["agree"], tot["dis"], f"{tot['configs'] / tot['fcl_s']:,.0f}",
                  f"{tot['configs'] / tot['rp_s']:,.0f}", f"{tot['fcl_s'] / tot['rp_s']:.2f}"))
    widths = [max(len(str(line[i])) for line in lines) for i in range(len(head))]
    for line in lines:
        print("  " + "  ".join(str(c).rjust(w) for c, w in zip(line, widths)))
    print("  checks/s: one Python call per state in a loop, the same configurations: CollisionWorld.is_free vs "
          "roboplan Scene.hasCollisions (broadphase tree, stops at the first collision); ratio = roboplan's rate / fcl's")
    print("disagreements by kind (python-fcl depth or gap of the pair, coal's signed distance of the same pair at the same pose):")
    kinds: dict[tuple[str, str], list] = collections.defaultdict(list)
    for r in rows:
        for d in r["disagreements"]:
            kinds[(r["family"], d["kind"])].append(d)
    if not kinds:
        print("  none")
    for (family, kind), ds_ in sorted(kinds.items()):
        who = collections.Counter("fcl collides, roboplan free" if not d["fcl_free"] else "roboplan collides, fcl free" for d in ds_)
        depths = [-p["fcl_distance_m"] for d in ds_ for p in d["pairs"]]
        coal_d = [p["coal_distance_m"] for d in ds_ for p in d["pairs"]]
        print(f"  {family}: {kind}: {len(ds_)} ({', '.join(f'{v} {k}' for k, v in who.items())}); fcl depth "
              f"{_fmt_m(min(depths, default=None))}..{_fmt_m(max(depths, default=None))} m, coal signed distance "
              f"{_fmt_m(min(coal_d, default=None))}..{_fmt_m(max(coal_d, default=None))} m")
    print(f"poses and distances on {args.distance_configs} configurations per family (roboplan's forwardKinematics "
          f"of link_0..link_7 and the gripper body vs the suite's; python-fcl vs coal signed distance of every counted "
          f"pair within {NEAR_PAIR_M} m, same shapes at the same poses):")
    for r in rows:
        m = _merge_pose(r["pose_and_distance"])
        r["pose_and_distance"] = m
        worst = max(m["apart_max_abs_diff_by_shapes_m"].items(), key=lambda kv: kv[1], default=("-", None))
        print(f"  {r['family']}: pose error max {_fmt_m(m['pose_max_translation_m'])} m / {_fmt_m(m['pose_max_rotation_entry'])} "
              f"(rotation entry); {m['apart_pairs']} apart pairs, max |fcl - coal| {_fmt_m(m['apart_max_abs_diff_m'])} m "
              f"(largest for {worst[0]}); {m['penetrating_pairs']} penetrating pairs, max |fcl - coal| "
              f"{_fmt_m(m['penetrating_max_abs_diff_m'])} m; against the exact distance of {m['capsule_pairs']} apart "
              f"capsule pairs: python-fcl off by up to {_fmt_m(m['capsule_fcl_max_error_m'])} m, coal by "
              f"{_fmt_m(m['capsule_coal_max_error_m'])} m")
    sweep = None
    if args.self_sweep > 0:
        sweep = self_pair_sweep(ds, args.self_sweep)
        print(f"robot self pairs, pair by pair, at {args.self_sweep} uniform configurations (held can included): "
              "penetrations deeper than 1e-6 m by python-fcl's signed distance, and the boolean queries that miss them")
        for name, c in sweep["pairs"].items():
            print(f"  {name}: {c['penetrating']} penetrating (deepest {c['deepest_m']:.3f} m); missed by coal in roboplan's "
                  f"order {c['coal_misses']}, in the other order {c['coal_swapped_misses']}, by python-fcl {c['fcl_misses']}")
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"dataset": f"{ds.name}:{ds.tier}", "configs_per_family": args.configs,
                                         "near_share": args.near_share, "seed": CONFIG_SEED, "families": rows,
                                         "self_pair_sweep": sweep}, indent=1))
        print(f"wrote {args.json}")
    return 0


def _roboplan_version() -> str:
    from importlib.metadata import version

    return version("roboplan")
