"""Execute planned pick-and-place cycles in a Drake physics simulation: are the cans recycled?

`execute_cycles` chains each can's timed trajectories and gripper actions into one command stream
(`suite.execution.commands`), drives the scene's plant with it (`suite.execution.plant`: the
controllers and contact settings) and measures the outcome (`suite.execution.monitor`).

What is measured (`ExecutionOutcome`): where every can ends (in the bin, back on the plate,
elsewhere), contacts of the robot with the static scene or with cans it is not picking (and of the
carried can with the scene), the peak joint tracking error, and wall and simulated time.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from scenes.scene import Scene
from suite.execution.commands import CommandStream, CycleProvider, WorldState
from suite.execution.monitor import CanResult, ContactEvent, Monitor
from suite.execution.config import ExecutionConfig
from suite.execution.plant import build_simulation

log = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True)
class ExecutionOutcome:
    """What happened when one planner's plans for one scene were executed.

    Attributes:
        cans_total: cans on the plate at the start.
        cans_attempted: cans whose whole cycle was planned and executed.
        cans_in_bin, cans_on_plate, cans_elsewhere: where the cans ended.
        collisions: unintended contact episodes (robot vs static scene, robot vs a can it was not
            picking, the carried can vs the scene or other cans).
        contact_events: the first few of them.
        peak_tracking_error_rad: largest |q - q_desired| of any arm joint.
        peak_slip_m: largest displacement of a carried can in the gripper frame since its lift
            began.
        sim_time_s: simulated time of the whole stream (settling included).
        clear_time_s: simulated time at which the last can entered the bin (None unless all did).
        clear_wall_time_s: wall time the simulation took to get there (None unless all did).
        wall_time_s: wall time of the simulation (the provider's planning between cycles is
            left out and recorded as between_cycles_wall_s).
        real_time_factor: sim_time_s / wall_time_s.
        stopped: why execution stopped before the last can ("" if it did not).
    """

    planner: str
    scene_seed: int
    variant: str
    cans_total: int
    cans_attempted: int
    cans_in_bin: int
    cans_on_plate: int
    cans_elsewhere: int
    collisions: int
    contact_events: tuple[ContactEvent, ...]
    peak_tracking_error_rad: float
    peak_slip_m: float
    sim_time_s: float
    clear_time_s: float | None
    clear_wall_time_s: float | None
    wall_time_s: float
    real_time_factor: float
    cans: tuple[CanResult, ...]
    stopped: str = ""
    extra: dict[str, Any] = dataclasses.field(default_factory=dict)

    def to_json(self) -> dict:
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
               if f.name not in ("contact_events", "cans", "extra")}
        out["contact_events"] = [e.to_json() for e in self.contact_events]
        out["cans"] = [c.to_json() for c in self.cans]
        out.update(self.extra)
        for k in ("peak_tracking_error_rad", "peak_slip_m", "sim_time_s", "wall_time_s", "real_time_factor"):
            out[k] = round(float(out[k]), 6)
        return out


def execute_cycles(
    scene: Scene,
    provider: CycleProvider,
    *,
    q_home: np.ndarray,
    planner: str,
    config: ExecutionConfig = ExecutionConfig(),  # noqa: B008 (frozen)
    meshcat=None,
    cameras: bool = False,
    on_progress: Callable[[float, float], None] | None = None,
) -> ExecutionOutcome:
    """Simulate the cans' cycles one after the other and measure the outcome.

    Args:
        scene: the scene as the cans really stand at the start.
        provider: gives each next can's timed motions (`planned_ahead` for plans made before
            execution; a closed-loop provider perceives and plans between cycles).
        q_home: the arm's configuration at the start (the first approach's start).
        planner: its name (recorded).
        config: control, contact and timing settings.
        meshcat: a pydrake Meshcat to record the execution into, or None.
        cameras: add the spec's cameras and render them after each release (closed loop).
        on_progress: called with (simulated time, planned total) every simulated second.
    """
    spec = scene.spec
    stream = CommandStream(q_home=q_home, open_width_m=spec.grasp.open_width_m, config=config)
    sim = build_simulation(scene, stream, q_home=q_home, config=config, meshcat=meshcat, cameras=cameras)
    plant, iiwa, pc, root, simulator = sim.plant, sim.iiwa, sim.pc, sim.root, sim.simulator
    monitor = Monitor(sim, scene, stream, lambda: time.perf_counter() - wall0 - provider_wall)
    snapshot: dict = {}

    def world_state() -> WorldState:
        return WorldState(
            t_s=root.get_time(), q_arm=plant.GetPositions(pc, iiwa).copy(), q_command=stream.q_end,
            X_WCans={i: plant.EvalBodyPoseInWorld(pc, b).GetAsMatrix4() for i, b in monitor.can_bodies.items()},
            images=snapshot.get("images"), q_images=snapshot.get("q"),
        )

    wall0 = time.perf_counter()
    provider_wall = 0.0
    simulator.Initialize()
    if meshcat is not None:
        meshcat.StartRecording(frames_per_second=config.publish_hz)
    every = max(1, round(0.01 / config.time_step_s))  # the full check every 10 ms
    steps = 0
    t = 0.0
    next_progress = 1.0
    attempted: list[int] = []
    stopped = ""
    finished = False
    while True:
        if not finished and t >= stream.duration_s - 1e-9:
            p0 = time.perf_counter()
            cycle, stopped = provider(world_state())
            provider_wall += time.perf_counter() - p0
            if cycle is None:
                stream.finish()
                finished = True
            else:
                stream.append_cycle(cycle)
                attempted.append(cycle.can_id)
        if finished and t >= stream.duration_s - 1e-9:
            break
        steps += 1
        t = min(steps * config.time_step_s, stream.duration_s)
        simulator.AdvanceTo(t)
        monitor.check(root, full=steps % every == 0 or t >= stream.duration_s)
        segment = stream.at(t)
        if cameras and segment.phase == "return" and snapshot.get("cycle") != len(attempted):
            from scenes.render import render_context

            p0 = time.perf_counter()
            snapshot.update(cycle=len(attempted), images=render_context(sim.ds, root),
                            q=plant.GetPositions(pc, iiwa).copy())
            provider_wall += time.perf_counter() - p0
        if on_progress is not None and t >= next_progress:
            on_progress(t, stream.duration_s)
            next_progress += 1.0
    wall = time.perf_counter() - wall0 - provider_wall
    if meshcat is not None:
        meshcat.StopRecording()
        meshcat.PublishRecording()

    cans = monitor.fates(attempted)
    counts = {w: sum(c.where == w for c in cans) for w in ("bin", "plate", "elsewhere")}
    cleared = counts["bin"] == len(cans) and bool(cans)
    clear = max(c.in_bin_at_s for c in cans) if cleared else None
    clear_wall = max(monitor.in_bin_wall[c.can_id] for c in cans) if cleared else None
    return ExecutionOutcome(
        planner=planner, scene_seed=scene.seed, variant=scene.variant, cans_total=len(scene.cans),
        cans_attempted=len(attempted), cans_in_bin=counts["bin"], cans_on_plate=counts["plate"],
        cans_elsewhere=counts["elsewhere"], collisions=monitor.n_episodes, contact_events=tuple(monitor.events),
        peak_tracking_error_rad=monitor.peak_err, peak_slip_m=monitor.peak_slip, sim_time_s=stream.duration_s,
        clear_time_s=clear, clear_wall_time_s=clear_wall,
        wall_time_s=wall, real_time_factor=stream.duration_s / wall if wall > 0 else float("inf"),
        cans=tuple(cans), stopped=stopped, extra={"between_cycles_wall_s": round(provider_wall, 3)},
    )
