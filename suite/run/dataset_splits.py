"""Which scenes of a dataset are for tuning, and which make the quick tier.

Both choices take whole scenes (no scene has problems on both sides; a tier of whole scenes can
be executed in physics) and are deterministic: scenes are visited in the order of their key's
hash, not their seed, so that no seed range is favoured.

- `stratified_tune_scenes`: per family, scenes go to `tune` until it holds `low`-`high` of the
  family's non-trivial problems (aiming at the middle) and every (family, kind) cell with at
  least `min_cell` non-trivial problems has one of them in `tune`.
- `balanced_tier`: test scenes are added, each time from the family whose share of the tier's
  non-trivial problems is furthest below its goal, until the tier holds `target` problems; no
  family may pass `max_share` of the non-trivial problems, and every family with at least
  `min_family` non-trivial test problems gets at least `min_share`.

`split_violations` and `tier_violations` state the rules as checks, read from the stored records.
"""

from __future__ import annotations

import dataclasses
import hashlib
from collections import defaultdict
from collections.abc import Iterable


@dataclasses.dataclass(frozen=True)
class SceneCounts:
    """One scene's benchmark problems: how many, and its non-trivial ones per kind."""

    key: str
    family: str
    problems: int
    nontrivial_by_kind: dict[str, int]

    @property
    def nontrivial(self) -> int:
        return sum(self.nontrivial_by_kind.values())


def _order(key: str) -> str:
    return hashlib.sha256(key.encode()).hexdigest()


def stratified_tune_scenes(scenes: Iterable[SceneCounts], *, low: float = 0.20, high: float = 0.35,
                           min_cell: int = 5) -> set[str]:
    """The keys of the scenes for the `tune` split (see the module docstring)."""
    tune: set[str] = set()
    by_family: dict[str, list[SceneCounts]] = defaultdict(list)
    for s in scenes:
        by_family[s.family].append(s)
    for family, members in by_family.items():
        members = sorted(members, key=lambda s: _order(s.key))
        total = sum(s.nontrivial for s in members)
        cell_total: dict[str, int] = defaultdict(int)
        for s in members:
            for kind, n in s.nontrivial_by_kind.items():
                cell_total[kind] += n
        need = {kind for kind, n in cell_total.items() if n >= min_cell}
        chosen: list[SceneCounts] = []
        held = 0

        def fits(s: SceneCounts) -> bool:
            return total == 0 or (held + s.nontrivial) / total <= high

        # 1. cover every cell that needs a tune problem, smallest scenes first
        while need:
            covering = [s for s in members if s not in chosen and any(s.nontrivial_by_kind.get(k, 0) for k in need)
                        and fits(s)]
            if not covering:
                break
            best = max(covering, key=lambda s: (sum(1 for k in need if s.nontrivial_by_kind.get(k, 0)), -s.nontrivial))
            chosen.append(best)
            held += best.nontrivial
            need -= {k for k in need if best.nontrivial_by_kind.get(k, 0)}
        # 2. fill towards the middle of [low, high]
        goal = 0.5 * (low + high) * total
        for s in members:
            if held >= goal:
                break
            if s not in chosen and s.nontrivial and fits(s) and abs(held + s.nontrivial - goal) <= abs(held - goal):
                chosen.append(s)
                held += s.nontrivial
        # a family whose problems are all trivial still lends one scene to tuning
        if not chosen and members:
            chosen.append(members[0])
        tune |= {s.key for s in chosen}
    return tune


def balanced_tier(scenes: Iterable[SceneCounts], *, target: int, max_share: float = 0.25, min_share: float = 0.08,
                  min_family: int = 20) -> list[str]:
    """The keys of the test scenes that make a tier of about `target` problems, in the order chosen."""
    by_family: dict[str, list[SceneCounts]] = defaultdict(list)
    for s in scenes:
        by_family[s.family].append(s)
    for members in by_family.values():
        members.sort(key=lambda s: _order(s.key))
    available = {f: sum(s.nontrivial for s in m) for f, m in by_family.items()}
    chosen: list[SceneCounts] = []
    counts: dict[str, int] = defaultdict(int)

    def share_after(f: str, add: int) -> float:
        total = sum(counts.values()) + add
        return (counts[f] + add) / total if total else 0.0

    # every family once (its smallest scene with non-trivial problems), then by deficit
    for f in sorted(by_family):
        cands = [s for s in by_family[f] if s.nontrivial]
        if cands:
            s = min(cands, key=lambda s: (s.nontrivial, s.problems))
            chosen.append(s)
            by_family[f].remove(s)
            counts[f] += s.nontrivial
    while sum(s.problems for s in chosen) < target:
        fams = [f for f in by_family if by_family[f]]
        if not fams:
            break
        # the family furthest below an equal share, among those that stay within max_share
        total = sum(counts.values())
        equal = 1.0 / max(1, sum(1 for f in available if available[f]))
        fitting = {f: [s for s in by_family[f] if share_after(f, s.nontrivial) <= max_share] for f in fams}
        ok = [f for f in fams if fitting[f]]
        if ok:
            f = min(ok, key=lambda f: (counts[f] / total if total else 0.0) - equal)
            s = min(fitting[f], key=lambda s: abs(sum(x.problems for x in chosen) + s.problems - target))
        else:  # while the tier is small every scene tips a family over: the one that tips it least
            f, s = min(((f, s) for f in fams for s in by_family[f]), key=lambda fs: (share_after(fs[0], fs[1].nontrivial),
                                                                                   fs[1].problems))
        chosen.append(s)
        by_family[f].remove(s)
        counts[f] += s.nontrivial
    return [s.key for s in chosen]


def split_violations(scenes: Iterable[SceneCounts], tune: set[str], *, low: float = 0.20, high: float = 0.35,
                     min_family: int = 20, min_cell: int = 5) -> list[str]:
    """What breaks the split rules: a family with at least `min_family` non-trivial problems whose
    tune share is outside [low, high], or a (family, kind) cell of at least `min_cell` with none in tune."""
    fam_total, fam_tune = defaultdict(int), defaultdict(int)
    cell_total, cell_tune = defaultdict(int), defaultdict(int)
    for s in scenes:
        fam_total[s.family] += s.nontrivial
        for kind, n in s.nontrivial_by_kind.items():
            cell_total[(s.family, kind)] += n
            if s.key in tune:
                cell_tune[(s.family, kind)] += n
        if s.key in tune:
            fam_tune[s.family] += s.nontrivial
    out = [f"{f}: tune holds {fam_tune[f]} of {n} non-trivial problems ({fam_tune[f] / n:.0%}), outside "
           f"[{low:.0%}, {high:.0%}]" for f, n in sorted(fam_total.items())
           if n >= min_family and not low <= fam_tune[f] / n <= high]
    out += [f"{f} {k}: none of its {n} non-trivial problems is in tune" for (f, k), n in sorted(cell_total.items())
            if n >= min_cell and not cell_tune[(f, k)]]
    return out


def tier_violations(tier: Iterable[SceneCounts], test: Iterable[SceneCounts], *, max_share: float = 0.25,
                    min_share: float = 0.08, min_family: int = 20, min_nontrivial: float = 0.70) -> list[str]:
    """What breaks the tier rules (its scenes `tier`, all test-split scenes `test`)."""
    tier = list(tier)
    n = sum(s.problems for s in tier)
    nt = sum(s.nontrivial for s in tier)
    out = []
    if n and nt / n < min_nontrivial:
        out.append(f"{nt} of {n} problems are non-trivial ({nt / n:.0%}), below {min_nontrivial:.0%}")
    fam = defaultdict(int)
    for s in tier:
        fam[s.family] += s.nontrivial
    test_fam = defaultdict(int)
    for s in test:
        test_fam[s.family] += s.nontrivial
    for f, k in sorted(fam.items()):
        if nt and k / nt > max_share:
            out.append(f"{f} holds {k} of {nt} non-trivial problems ({k / nt:.0%}), above {max_share:.0%}")
    for f, k in sorted(test_fam.items()):
        if k >= min_family and nt and fam[f] / nt < min_share:
            out.append(f"{f} holds {fam[f]} of {nt} non-trivial problems ({fam[f] / nt:.0%}), below {min_share:.0%}")
    return out
