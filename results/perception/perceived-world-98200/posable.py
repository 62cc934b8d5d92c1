# A diagnostic beside the figure (results/perception/perceived-world-98200/README.md): run from a clone with PYTHONPATH set to it.
"""Per scene: cans whose five problems are posed with valid ends, in the truth and perceived worlds."""
import sys, json
import numpy as np
from scenes.spec import load_spec
from scenes.generate import generate_scene
from perception.pipeline import PerceptionSetup
from suite.run.runner import scene_task
from suite.problems.cycle import build_problems
from planners.worlds import collision_world
setup = PerceptionSetup(pipeline="robust", sensor="kinect-v1", correlation_px=4)
spec = load_spec(variant="clutter").with_can_count(5)
out = {}
for seed in range(int(sys.argv[1]), int(sys.argv[2])):
    scene = generate_scene(spec, seed=seed)
    row = {}
    for world in ("truth", "perceived"):
        gp, seen = scene_task(scene, grasps="perceived", perception=setup, world=world)
        ok = 0
        for i in range(len(gp)):  # each can alone, with every other can in place
            probs = build_problems(scene, gp[i:i + 1], time_limit_s=5, seed=0, world=seen,
                                   **({} if len(sys.argv) < 4 else {}))
            good = True
            for p in probs:
                if p.pre_status is not None or p.q_goal is None:
                    good = False; break
                w = collision_world(p.for_planner())
                if not (w.is_free(p.q_start) and w.is_free(p.q_goal)):
                    good = False; break
            ok += good
        row[world] = ok
    out[seed] = row
    print(seed, row, flush=True)
print(json.dumps(out))
