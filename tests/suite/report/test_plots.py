"""The run's figures: every PNG is written and holds a real image; colours stay with planners."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic_runs import synthetic_records, write_run

from suite.report import plots as plots_module
from suite.report.plots import make_plots, start_plots
from suite.report.plots_common import BUILTIN_COLORS, planner_colors
from suite.report.plots_paths import densify_joint_path

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    records = synthetic_records(seeds=(3,), variants=("open", "wall"), cans=2)
    return write_run(tmp_path_factory.mktemp("run"), records)


def _png_size(path):
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


def test_make_plots_writes_every_figure(run_dir):
    written = make_plots(run_dir)
    names = sorted(p.name for p in written)
    assert names == sorted([
        "metrics_boxplots.png", "outcomes.png", "planning_time_cdf.png", "success_by_family.png",
        "length_ratio_by_family.png", "natural_poses.png", "gripper_paths_seed3_open.png", "gripper_paths_seed3_wall.png", "joint_profiles_transit.png",
    ])
    for p in written:
        assert p.parent == run_dir / "plots"
        w, h = _png_size(p)
        assert w > 400 and h > 300, p.name
        assert p.stat().st_size > 20_000, p.name  # a drawn figure, not an empty canvas


def test_figures_drawn_partly_in_a_second_process_are_the_same_files_in_order(run_dir):
    alone = [p.name for p in make_plots(run_dir)]
    sizes = {p.name: p.stat().st_size for p in (run_dir / "plots").iterdir()}
    drawing = start_plots(run_dir, background=0.6)
    assert drawing.proc is not None  # Linux: forked
    shared = drawing.finish()
    assert [p.name for p in shared] == alone
    assert all(abs(p.stat().st_size - sizes[p.name]) < 0.02 * sizes[p.name] for p in shared)


def test_a_failing_second_process_leaves_its_figures_to_the_first(run_dir, monkeypatch):
    def broken(conn, jobs):
        conn.send(("error", "RuntimeError: no display"))
        conn.close()

    monkeypatch.setattr(plots_module, "_draw_into", broken)
    for p in (run_dir / "plots").iterdir():
        p.unlink()
    written = start_plots(run_dir, background=0.6).finish()
    assert len(written) == 9 and all(p.is_file() for p in written)


def test_make_plots_without_any_success(tmp_path):
    records = synthetic_records(seeds=(0,), variants=("open",), cans=1, planners=("ik", "rrt"))
    for r in records:
        r.status, r.path, r.metrics = "no_solution", None, {}
    written = make_plots(write_run(tmp_path, records, planners=("ik", "rrt"), cans=1))
    # no path to draw a profile of; the statistics figures and the scene are still drawn
    assert sorted(p.name for p in written) == sorted(
        ["metrics_boxplots.png", "outcomes.png", "planning_time_cdf.png", "success_by_family.png",
         "length_ratio_by_family.png", "natural_poses.png", "gripper_paths_seed0_open.png"])


def test_planner_colors_are_fixed_per_planner():
    a = planner_colors(["trajopt", "rrt", "ik"])
    b = planner_colors(["ik", "mine", "rrt", "other"])
    assert a["rrt"] == b["rrt"] == BUILTIN_COLORS["rrt"]
    assert a["ik"] == b["ik"]
    assert b["mine"] != b["other"] and {b["mine"], b["other"]}.isdisjoint(BUILTIN_COLORS.values())


def test_densify_joint_path_keeps_the_polyline():
    path = np.array([np.zeros(7), np.full(7, 0.1), np.r_[0.1, 0.1, 0.1, 0.5, 0.1, 0.1, 0.1]])
    dense = densify_joint_path(path, step_rad=0.01)
    assert np.allclose(dense[0], path[0]) and np.allclose(dense[-1], path[-1])
    assert np.max(np.abs(np.diff(dense, axis=0))) <= 0.01 + 1e-12
    assert len(dense) == 1 + 10 + 40
    assert any(np.allclose(d, path[1]) for d in dense)  # the corner is kept


def test_plot_command_redraws_from_trials_alone(run_dir, tmp_path, capsys):
    from suite.cli import main

    copy = tmp_path / "copy"
    copy.mkdir()
    (copy / "trials.jsonl").write_bytes((run_dir / "trials.jsonl").read_bytes())  # no manifest
    assert main(["plot", str(copy), "--no-plots"]) == 0
    out = capsys.readouterr().out
    assert out.splitlines()[0].split()[:2] == ["planner", "success"]
    assert {"summary.md", "summary.csv", "paired.csv", "arena"} <= {p.name for p in copy.iterdir()}
    assert not (copy / "plots").exists()


def test_plot_command_errors_name_the_directory(tmp_path, capsys):
    from suite.cli import main

    assert main(["plot", str(tmp_path / "missing")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"error: run directory {str(tmp_path / 'missing')!r} does not exist"
    assert main(["plot", str(tmp_path)]) == 2
    assert "holds no trials.jsonl" in capsys.readouterr().err


def test_a_hanging_second_process_is_killed_and_its_figures_drawn_by_the_first(run_dir, monkeypatch):
    import time

    def hangs(conn, jobs):
        time.sleep(60)

    monkeypatch.setattr(plots_module, "_draw_into", hangs)
    monkeypatch.setattr(plots_module, "DRAW_TIMEOUT_S", 0.5)
    drawing = start_plots(run_dir, background=0.6)
    written = drawing.finish()
    assert len(written) == 9 and not drawing.proc.is_alive()
