"""A 3-D replay of one problem: every planner's timed path in the problem's world, as Meshcat static HTML.

The report does not inline these: a Meshcat static page carries its three.js viewer (about 3.5 MB),
so a hundred problems would make a page of hundreds of MB. `python -m suite replay RUN PROBLEM`
writes one on demand from the run's saved files: the problem's world (its dataset's scene without
the recycled cans, the held can welded in the gripper at the recorded opening) is built in Drake's
"plan" mode, each planner's saved path is timed again with TOPP-RA as its trial was, and the robot
plays the planners one after another; each planner's gripper path stays drawn as a coloured line,
the reference path's in grey (`/paths/NAME` in Meshcat's scene tree, where each can be hidden).
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from scenes.errors import SuiteError
from suite.report.html.problems import Problem, group_problems, load_world
from suite.run.records import joint_path, planners_in, read_manifest, read_trials

log = logging.getLogger(__name__)

#: Frames per second of the recorded animation, and the pause after each planner's motion.
FPS = 30
PAUSE_S = 0.75


@dataclasses.dataclass(frozen=True)
class Replay:
    """What was written: the file, and when each planner plays in it (s), or why it does not."""

    path: Path
    schedule: dict[str, tuple[float, float] | str]
    note: str


def find_problem(problems: Sequence[Problem], text: str) -> Problem:
    """The problem whose id is `text`, or starts with it (a unique prefix of at least 6 characters)."""
    exact = [p for p in problems if p.pid == text]
    if exact:
        return exact[0]
    found = [p for p in problems if len(text) >= 6 and p.pid.startswith(text)]
    if len(found) == 1:
        return found[0]
    example = ", ".join(p.pid for p in problems[:3])
    if found:
        raise SuiteError(f"problem {text!r} is the prefix of {len(found)} problems; give more of it")
    raise SuiteError(f"no problem {text!r} in this run (its ids are in report.html and trials.jsonl, e.g. {example})")


def write_replay(run_dir: str | Path, problem: str, *, out: str | Path | None = None) -> Replay:
    """Write the replay of one problem of a run.

    Args:
        run_dir: the run directory (trials.jsonl, manifest.json).
        problem: the problem's id (its problem_id, or a unique prefix of 6+ characters).
        out: the HTML file to write (default RUN/replays/ID.html, where the report links it).

    Raises:
        SuiteError: no such run or problem, or its scene cannot be rebuilt from the run's files.
    """
    from pydrake.geometry import MeshcatVisualizer, Rgba
    from pydrake.systems.framework import DiagramBuilder

    from scenes.drake_scene import build_drake_scene
    from scenes.robot_model import load_robot
    from suite.execution.jobs import meshcat_for
    from suite.report.html.drilldown import replay_path
    from suite.report.plots_common import planner_colors
    from suite.report.plots_paths import densify_joint_path
    from suite.scoring.timing import time_parameterize

    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise SuiteError(f"run directory {str(run_dir)!r} does not exist")
    records = read_trials(run_dir)
    manifest = read_manifest(run_dir)
    planners = planners_in(records, manifest)
    p = find_problem(group_problems(records), problem)
    world = load_world([p], manifest)
    stored = world.stored.get(p.pid)
    if stored is not None:
        scene = stored.scene.without_cans(stored.removed_can_ids)
        held, opening, note = stored.held, stored.gripper_opening_m, world.note
    elif p.first.scene_key in world.scenes:
        scene, held, opening = world.scenes[p.first.scene_key], None, None
        note = world.note + " The held can is not drawn (the run does not record it)."
    else:
        raise SuiteError(f"cannot rebuild the scene of problem {p.pid}: {world.note}")
    builder = DiagramBuilder()
    ds = build_drake_scene(scene, mode="plan", cameras=False, gripper_opening_m=opening, held=held,
                           builder=builder, build=False)
    meshcat = meshcat_for(scene)
    visualizer = MeshcatVisualizer.AddToBuilder(builder, ds.scene_graph, meshcat)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = ds.plant.GetMyContextFromRoot(context)
    robot = load_robot(scene.spec.robot)
    colors = planner_colors(planners)
    schedule: dict[str, tuple[float, float] | str] = {}
    visualizer.StartRecording(set_transforms_while_recording=False)
    t0 = 0.0
    for planner in planners:
        q = next((joint_path(r) for r in p.trials.get(planner, ()) if joint_path(r) is not None), None)
        if q is None:
            schedule[planner] = "no path (" + ", ".join(str(r.status) for r in p.trials.get(planner, ())) + ")"
            continue
        traj = time_parameterize(q, robot=robot)
        if not traj.ok:
            schedule[planner] = f"timing failed ({traj.reason})"
            continue
        times = np.arange(0.0, traj.duration_s, 1.0 / FPS).tolist() + [traj.duration_s]
        for t in times:
            context.SetTime(t0 + t)
            ds.plant.SetPositions(plant_context, _sample(traj, t))  # "plan" mode: the 7 arm joints alone
            diagram.ForcedPublish(context)
        schedule[planner] = (t0, t0 + traj.duration_s)
        t0 += traj.duration_s + PAUSE_S
        p_WG = robot.gripper_pose(densify_joint_path(q))[:, :3, 3]
        rgb = [int(colors[planner][i:i + 2], 16) / 255 for i in (1, 3, 5)]
        meshcat.SetLine(f"/paths/{planner}", p_WG.T.copy(), 3.0, Rgba(*rgb, 1.0))
    if p.pid in world.references:
        p_WG = robot.gripper_pose(densify_joint_path(world.references[p.pid]))[:, :3, 3]
        meshcat.SetLine("/paths/reference", p_WG.T.copy(), 2.0, Rgba(0.35, 0.35, 0.35, 1.0))
    visualizer.StopRecording()
    visualizer.PublishRecording()
    path = Path(out) if out else replay_path(run_dir, p.pid)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(meshcat.StaticHtml(), encoding="utf-8")
    log.info("wrote %s", path)
    return Replay(path, schedule, note)


def _sample(traj, t: float) -> np.ndarray:
    """The timed trajectory's joint positions (7,) at time t (linear between its samples)."""
    return np.array([np.interp(t, traj.t_s, traj.q[:, j]) for j in range(traj.q.shape[1])])
