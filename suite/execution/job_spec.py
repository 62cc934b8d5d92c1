"""What one physics execution job is: one planner on one scene, where its plans come from, the
world it plans in, and what a can that cannot be planned does to the rest (`ExecutionJob`)."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

from scenes.scene import Scene
from suite.execution.config import ExecutionConfig

if TYPE_CHECKING:
    from perception.pipeline import PerceptionSetup

#: What a can that cannot be fully planned does to the rest of the run (`ExecutionJob.on_failure`).
ON_FAILURE = ("skip", "stop")


@dataclasses.dataclass(frozen=True)
class ExecutionJob:
    """One planner's execution of one scene (picklable plain values).

    Attributes:
        planner, planner_config: the planner and its settings.
        scene: the scene at the start.
        grasps: "truth" or "perceived".
        time_limit_s: planning budget per problem (when this job plans).
        seed: the run seed (trial seeds derive from it as in `compare`).
        cans: pre-planned cycles in picking order, (can id, five paths or None where a problem
            failed, first failed status); None to plan in this job.
        q_home: where the pre-planned cycles start (the first approach's start); with `cans`.
        reperceive: plan each next can from a fresh rendering of the simulated cameras.
        replay_path: where to write the Meshcat replay HTML, or None.
        config: the simulation settings.
        perception: with `grasps="perceived"`, how they are perceived (pipeline, segmentation,
            sensor model; `perception.pipeline.PerceptionSetup`); None: the paper's pipeline on
            the spec's cameras.
        world: the world the planners plan in, `truth` or `perceived` (None: the perceived one with
            perceived grasps; `suite.run.runner.plan_world_for`). Judge and physics use the truth.
        on_failure: what a can not fully planned does to the cans after it (`ON_FAILURE`): `skip`
            (it stays on the plate; the cans after it are planned again around it, and the loop
            goes on) or `stop` (the run ends there). Pre-planned `cans` always stop: their later
            plans assumed the can gone.
    """

    planner: str
    planner_config: dict[str, Any]
    scene: Scene
    grasps: str
    time_limit_s: float
    seed: int
    cans: tuple[tuple[int, tuple[Any, ...], str], ...] | None = None
    q_home: tuple[float, ...] | None = None
    reperceive: bool = False
    replay_path: str | None = None
    config: ExecutionConfig = ExecutionConfig()
    perception: PerceptionSetup | None = None
    world: str | None = None
    on_failure: str = "skip"

    def __post_init__(self):
        if self.on_failure not in ON_FAILURE:
            from scenes.errors import SuiteError

            raise SuiteError(f"unknown on-failure policy {self.on_failure!r}; allowed: {', '.join(ON_FAILURE)}")
        self.scene.spec.require("cans", needed_by="execution in physics (the pick-and-place cycle)")
