"""The moving bin's planners compared episode by episode: paired differences in cans in the bin
per can offered, over the episodes (scene, seeded bin path, speed, modes) that both planners met,
with a percentile-bootstrap interval that resamples scenes.

Every figure comes from moving_bin.json alone (`suite.execution.moving_bin_records.MovingBinRecord`);
a record written before bin paths were seeded or modes named reads its fields with a default
(`latency_mode`, `release_mode`, `episode_key`).
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Sequence
from typing import Any

import numpy as np

from suite.execution.moving_bin_records import MovingBinRecord
from suite.report.summary_tables import format_number

#: The fewest paired episodes, and scenes, over which a difference may be called established.
MIN_PAIRED = 10
MIN_SCENES = 4

PAIRED_CAPTION = (
    "Paired differences between planners. The unit is an episode: one scene, one seeded bin path, one "
    "speed (and latency and release mode), which every planner meets. For each episode both planners ran "
    "(ok or crashed; a crash delivers none), d = A's cans in the bin per can offered minus B's; the "
    "table gives the episodes paired, the mean of d in percentage points and its 95% interval from a "
    "percentile bootstrap (10,000 resamples, seed 0) over scenes, each with all its episodes: the bin paths of "
    "one scene share its cans and static plans, so the scene is the independent unit; established: the "
    "interval excludes 0; "
    "A ahead / B ahead: the episodes where each put more in the bin. \"all\" pools every speed above 0. The "
    "pairing is on scenes and bin-path seeds, not on states (each planner reaches the bin at its own moments). Over few "
    "episodes a percentile bootstrap interval is too narrow (over 2 it takes at most 3 values), so a difference "
    f"is called established only over at least {MIN_PAIRED} paired episodes from {MIN_SCENES} scenes. No "
    "correction for the number of comparisons (pairs x speeds) is made: read a single 'yes' among many rows "
    "with that in mind.")

#: Bootstrap of the paired differences.
N_RESAMPLES = 10_000
BOOTSTRAP_SEED = 0


def latency_mode(r: MovingBinRecord) -> str:
    """An episode's latency mode, "measured" for a record written before modes were named."""
    return r.latency_mode or "measured"


def release_mode(r: MovingBinRecord) -> str:
    """An episode's release mode, "rest" for a record written before releases on the move."""
    return r.release_mode or "rest"


def planner_order(records: Sequence[MovingBinRecord], planners: Sequence[str] | None) -> list[str]:
    """The planners of the records: those of `planners` in its order, then the others as they come."""
    present = list(dict.fromkeys(r.planner for r in records))
    order = [p for p in (planners or ()) if p in present]
    return order + [p for p in present if p not in order]  # the records' own planners too


def episode_key(r: MovingBinRecord) -> tuple:
    """What every planner meets in the same way: the scene, the bin path, the speed and the modes."""
    return (r.variant, r.scene_seed, r.bin_seed, int(r.path_index or 0),
            float(r.speed_m_s), latency_mode(r), release_mode(r))


@dataclasses.dataclass(frozen=True)
class PairedDifference:
    """Planner A minus planner B in cans in the bin per can offered, over the episodes both ran.

    speed_m_s, latency_mode, release_mode are None on the row pooling every speed above 0. mean_pp and ci_pp
    (percentage points) are None with fewer than 2 episodes."""

    planner_a: str
    planner_b: str
    speed_m_s: float | None
    latency_mode: str | None
    release_mode: str | None
    n: int
    mean_pp: float | None
    ci_pp: tuple[float, float] | None
    a_ahead: int = 0
    b_ahead: int = 0
    scenes: int = 0

    @property
    def established(self) -> bool | None:
        """The interval excludes 0, over at least MIN_PAIRED episodes from at least MIN_SCENES
        scenes (None: too few to say)."""
        if self.ci_pp is None or self.n < MIN_PAIRED or self.scenes < MIN_SCENES:
            return None
        return self.ci_pp[0] > 0 or self.ci_pp[1] < 0


def bootstrap_mean_ci(d: np.ndarray, *, clusters: Sequence | None = None, n_resamples: int = N_RESAMPLES,
                      seed: int = BOOTSTRAP_SEED, level: float = 0.95) -> tuple[float, float]:
    """Percentile-bootstrap interval of the mean of d (default_rng(seed)): resampling its entries,
    or, with `clusters` (a label per entry), whole clusters: the episodes of one scene share its
    cans and its static plans, so they are not independent (a cluster bootstrap)."""
    d = np.asarray(d, float)
    rng = np.random.default_rng(seed)
    if clusters is not None:
        labels = sorted(set(clusters), key=repr)
        sums = np.array([sum(x for x, c in zip(d, clusters) if c == g) for g in labels])
        counts = np.array([sum(1 for c in clusters if c == g) for g in labels], float)
        pick = rng.integers(0, len(labels), size=(n_resamples, len(labels)))
        means = sums[pick].sum(axis=1) / counts[pick].sum(axis=1)
    else:
        means = np.empty(n_resamples)
        chunk = max(1, min(n_resamples, 2_000_000 // max(len(d), 1)))
        for start in range(0, n_resamples, chunk):
            stop = min(n_resamples, start + chunk)
            means[start:stop] = d[rng.integers(0, len(d), size=(stop - start, len(d)))].mean(axis=1)
    alpha = (1 - level) / 2
    lo, hi = np.quantile(means, [alpha, 1 - alpha])
    return float(lo), float(hi)


def _episode_rates(records: Sequence[MovingBinRecord], planner: str) -> dict[tuple, float]:
    """Cans in the bin per can offered per episode key (episodes that ran or ended in an error,
    which delivers none of the cans it did not finish; a key met twice takes the mean)."""
    by_key: dict[tuple, list[float]] = {}
    for r in records:
        if r.planner == planner and r.status in ("ok", "error") and r.cans_total \
                and r.speed_m_s is not None:
            delivered = r.cans_in_bin if r.status == "ok" else 0
            by_key.setdefault(episode_key(r), []).append(delivered / r.cans_total)
    return {k: float(np.mean(v)) for k, v in by_key.items()}


def _difference(a: str, b: str, keys: Sequence[tuple], ra: dict, rb: dict, group: tuple) -> PairedDifference:
    d = np.array([ra[k] - rb[k] for k in keys])
    scenes = [(k[0], k[1]) for k in keys]  # the cluster: the scene (variant, seed)
    ahead = (int((d > 0).sum()), int((d < 0).sum()))
    if len(d) < 2:
        return PairedDifference(a, b, *group, len(d), None, None, *ahead, scenes=len(set(scenes)))
    lo, hi = bootstrap_mean_ci(d, clusters=scenes if len(set(scenes)) > 1 else None)
    return PairedDifference(a, b, *group, len(d), 100 * float(d.mean()), (100 * lo, 100 * hi), *ahead,
                            scenes=len(set(scenes)))


def paired_differences(records: Sequence[MovingBinRecord], *, planners: Sequence[str] | None = None
                       ) -> list[PairedDifference]:
    """Every pair of planners (A before B in the given order) at every speed (and modes) where they
    share episodes, then pooled over them all (when there is more than one)."""
    order = planner_order(records, planners)
    rates = {p: _episode_rates(records, p) for p in order}
    out = []
    for a, b in itertools.combinations([p for p in order if rates[p]], 2):
        shared = sorted(set(rates[a]) & set(rates[b]), key=repr)
        if not shared:
            continue
        groups = sorted({(k[4], k[5], k[6]) for k in shared})
        for g in groups:
            out.append(_difference(a, b, [k for k in shared if (k[4], k[5], k[6]) == g], rates[a], rates[b], g))
        moving = [k for k in shared if k[4] > 0]  # a still bin asks for no replanning: not pooled
        if len({(k[4], k[5], k[6]) for k in moving}) > 1:
            out.append(_difference(a, b, moving, rates[a], rates[b], (None, None, None)))
    return out


def _pp(v: float) -> str:
    return f"{v:+.1f}" if abs(v) >= 0.05 else "0.0"


def paired_rows(records: Sequence[MovingBinRecord], planners: Sequence[str] | None = None
                ) -> tuple[list[str], list[list[Any]]]:
    """The paired table: per pair of planners and speed, episodes paired, mean difference (pp), its
    95% bootstrap interval, established. No rows when no two planners share an episode."""
    diffs = paired_differences(records, planners=planners)
    per_group = [d for d in diffs if d.speed_m_s is not None]
    modes_lat = len({d.latency_mode for d in per_group}) > 1
    modes_rel = len({d.release_mode for d in per_group}) > 1
    headers = ["A - B", "speed (m/s)", *(["latency"] if modes_lat else []), *(["release"] if modes_rel else []),
               "episodes paired", "A ahead / B ahead", "mean difference (pp)", "95% interval (pp)", "established"]
    rows = []
    for d in diffs:
        pooled = d.speed_m_s is None
        row = [f"{d.planner_a} - {d.planner_b}", "all" if pooled else format_number(d.speed_m_s)]
        if modes_lat:
            row.append("all" if pooled else d.latency_mode)
        if modes_rel:
            row.append("all" if pooled else d.release_mode)
        row += [f"{d.n} ({d.scenes} scenes)", f"{d.a_ahead} / {d.b_ahead}"]
        if d.ci_pp is None:
            row += ["-", "-", "-"]
        else:
            said = {True: "yes", False: "no", None: f"too few (< {MIN_PAIRED} episodes or {MIN_SCENES} scenes)"}[
                d.established]
            row += [_pp(d.mean_pp), f"[{_pp(d.ci_pp[0])}, {_pp(d.ci_pp[1])}]", said]
        rows.append(row)
    return headers, rows
