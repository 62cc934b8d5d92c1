"""The mplib adapter (adapters/mplib/plan.py) reads only an export, builds mplib's model of every
problem, agrees with the suite's validator about which configurations collide, plans with mplib's
RRTConnect in both modes, and its results files import as records judged like the suite's own.

mplib 0.2.1 needs numpy 1.x (with numpy 2 it crashes building a Pose), so it lives in an
environment of its own (`bash adapters/mplib/setup_env.sh`); the test runs with the Python named by
$MPLIB_PYTHON, or with this one if it has mplib and numpy 1.x, and is skipped otherwise."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ADAPTER = Path(__file__).resolve().parents[2] / "adapters" / "mplib" / "plan.py"
DATASET = "recycle-v3:quick"


def mplib_python() -> str | None:
    if importlib.util.find_spec("mplib") is not None and int(np.__version__.split(".")[0]) < 2:
        return sys.executable
    return os.environ.get("MPLIB_PYTHON") or None


pytestmark = pytest.mark.skipif(
    mplib_python() is None,
    reason="mplib not available: bash adapters/mplib/setup_env.sh, then set MPLIB_PYTHON to the Python it prints")


def run_adapter(*args, cwd: Path) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}  # nothing of the suite on its path
    return subprocess.run([mplib_python(), str(ADAPTER), *map(str, args)], check=False, cwd=cwd, env=env,
                          timeout=300, capture_output=True, text=True)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    from suite.exchange.export import write_export
    from suite.problems.dataset import load_dataset

    out = tmp_path_factory.mktemp("export")
    write_export(DATASET, out, time_limit_s=5.0)
    return out, load_dataset(DATASET)


def test_the_model_in_mplib_matches_the_export(exported, tmp_path):
    """Forward kinematics of `body` at q_goal against X_WG_goal, the finger faces against the
    opening, the held can (probe spheres 2 mm inside and outside it), the endpoints free: every problem."""
    export, ds = exported
    done = run_adapter(export, "--self-check", cwd=tmp_path)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    assert len(lines) == len(ds.ids) and all(ln["ok"] for ln in lines)
    assert sum("held_can_probes" in ln for ln in lines) == sum(p.held is not None for p in ds.problems) > 0


def test_mplib_and_the_validator_agree_on_sampled_configurations(exported, tmp_path):
    """Uniform configurations and configurations near the reference paths (where contacts are):
    mplib never calls free what the validator finds colliding, and disagrees on at most 0.5%."""
    from planners.worlds import collision_world

    export, ds = exported
    rng = np.random.default_rng(7)
    lo = np.array([-2.96706, -2.0944, -2.96706, -2.0944, -2.96706, -2.0944, -3.05433])
    picked = [i for i, pid in enumerate(ds.ids) if not ds.meta[pid]["trivial"]][::4]
    truth, states = {}, []
    for i in picked:
        pid, prob = ds.ids[i], ds.problems[i]
        ref = ds.references[pid]
        Q = [rng.uniform(lo, -lo) for _ in range(30)]
        for _ in range(70):
            k = rng.integers(len(ref) - 1)
            q = ref[k] + rng.uniform() * (ref[k + 1] - ref[k])
            Q.append(np.clip(q + rng.normal(0.0, rng.choice([0.01, 0.05, 0.2]), 7), lo, -lo))
        world = collision_world(prob)
        truth[pid] = [not world.is_free(q) for q in Q]
        states.append({"problem_id": pid, "q": [q.tolist() for q in Q]})
    (tmp_path / "states.jsonl").write_text("".join(json.dumps(s) + "\n" for s in states))
    done = run_adapter(export, "--states", tmp_path / "states.jsonl", "--out", tmp_path / "verdicts.jsonl",
                       cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    verdicts = {json.loads(ln)["problem_id"]: json.loads(ln)["colliding"]
                for ln in (tmp_path / "verdicts.jsonl").read_text().splitlines()}
    n = sum(len(v) for v in truth.values())
    missed = sum(t and not m for pid in truth for t, m in zip(truth[pid], verdicts[pid]))
    extra = sum(m and not t for pid in truth for t, m in zip(truth[pid], verdicts[pid]))
    colliding = sum(sum(v) for v in truth.values())
    assert 0.1 * n < colliding < 0.9 * n  # both verdicts are exercised
    assert missed == 0, f"mplib calls free {missed} of {n} configurations the validator finds colliding"
    assert extra <= 0.005 * n, f"mplib finds {extra} of {n} free configurations colliding"


def test_both_modes_plan_from_the_export_alone_and_their_results_import(exported, tmp_path):
    from suite.exchange.results import import_results
    from suite.run.records import read_trials

    export, ds = exported
    trivial = next(pid for pid in ds.ids if ds.meta[pid]["trivial"])
    hard = next(pid for pid, p in zip(ds.ids, ds.problems)
                if not ds.meta[pid]["trivial"] and p.held is not None and ds.meta[pid]["family"] != "window")
    for mode in ("mplib", "mplib-recheck"):
        results = tmp_path / f"{mode}.jsonl"
        done = run_adapter(export, "--mode", mode, "--out", results, "--problems", f"{trivial},{hard}", cwd=tmp_path)
        assert done.returncode == 0, done.stderr[-2000:]
        lines = {json.loads(line)["problem_id"]: json.loads(line) for line in results.read_text().splitlines()}
        assert set(lines) == {trivial, hard}
        run, counts = import_results(dataset=DATASET, results=results, planner=mode, out=tmp_path / f"run-{mode}")
        by_id = {r.problem_id: r for r in read_trials(run)}
        assert by_id[trivial].status == "success" and by_id[trivial].external is True
        assert counts.statuses["no_result"] == len(ds.ids) - 2
        if mode == "mplib":
            assert by_id[hard].status in ("success", "invalid_solution", "timeout")
        else:  # a path that passed mplib's own check at the validator's rule passes the validator
            assert by_id[hard].status in ("success", "timeout")
            assert "OUR wrapper" in lines[hard]["notes"]
