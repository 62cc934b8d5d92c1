"""The worlds the kernel benches draw on (`suite.bench.kernel`'s differential check and
`suite.bench.near_contact`'s boundary check): per family of a dataset, a problem with a held can
and one without, each at its own gripper opening and at the other."""

from __future__ import annotations

import numpy as np

from suite.problems import DEFAULT_DATASET


def draw_worlds(dataset: str = DEFAULT_DATASET, *, pick: int = 0) -> list[tuple]:
    """(family, problem, points) per world: per family of the dataset, the first benchmark problem
    with a held can and the first without (the `pick`-th, counting from 0, where there are that
    many; else the last), each at its own gripper opening and at the other one (open, or closed
    on the can); `points` are its start, goal and witness (or reference) states."""
    from suite.problems.dataset import load_dataset

    ds = load_dataset(dataset)
    chosen: dict[tuple[str, bool], tuple] = {}
    seen: dict[tuple[str, bool], int] = {}
    for pid, p in zip(ds.ids, ds.problems):
        key = (ds.meta[pid]["family"], p.held is not None)
        seen[key] = seen.get(key, 0) + 1
        if seen[key] <= pick + 1:
            path = ds.witnesses.get(pid, ds.references[pid])
            chosen[key] = (p, np.vstack([p.q_start, p.q_goal, path]))
    out = []
    for (family, _), (p, points) in sorted(chosen.items()):
        grasp = p.scene.spec.grasp
        openings = {float(p.gripper_opening_m), float(grasp.open_width_m)}
        if p.held is not None:
            openings.add(float(2 * p.scene.spec.can.radius_m))
        for opening in sorted(openings):
            out.append((family, p.with_(gripper_opening_m=opening), points))
    return out
