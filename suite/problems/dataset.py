"""Frozen datasets: planning problems stored as data with reference solutions, hashes and a manifest.

A dataset lives in `scenes/datasets/NAME/`:

- `scenes.jsonl`: one line per scene (its concrete spec, seed, family and cans), stored once;
- `problems.jsonl`: one line per distinct problem (`benchmark: true`) or stored trivial cycle step
  left out of the benchmark (`benchmark: false`, kept so scenes can be executed): its scene, kind, `q_start`, `q_goal`, goal pose,
  task waypoints, held can, gripper opening, removed cans, whether it is trivial, its difficulty,
  its split, its reference solution, its `problem_id` (content hash of world and configurations)
  and `record_hash` (hash of the whole line);
- `manifest.json`: name, format version, dataset hash, identity rule, counts, tiers, versions,
  build command.

How a line is written, read back and hashed is `suite.problems.stored`'s.

A dataset's `problem_id`s were made with one identity rule (`scenes.identity_rule`), named by the
manifest's `identity_rule` (absent: `round9`, the rule of the datasets up to recycle-v3). Its ids
are checked with that rule; a newly built dataset uses the current one.

Loading needs no scene generation and no IK: the same problems on any machine.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import Field

from planners.base import PlanningProblem
from scenes.errors import SuiteError
from scenes.identity_rule import LEGACY_RULE, RULES
from scenes.scene import Scene
from scenes.schema import load
from suite.problems.identity import problem_id
from suite.problems.stored import (
    dataset_hash,
    problem_from_record,
    record_hash,
    scene_from_record,
)

FORMAT_VERSION = 1
DATASETS_DIR = Path(__file__).resolve().parents[2] / "scenes" / "datasets"
SCENES_FILE, PROBLEMS_FILE, MANIFEST_FILE = "scenes.jsonl", "problems.jsonl", "manifest.json"
#: The whole dataset's tier name (every problem).
ALL = "all"


def dataset_dir(name: str) -> Path:
    """Where dataset NAME lives (a path with a slash is taken as the directory itself)."""
    if "/" in name or name.startswith("."):
        return Path(name)
    if not name or any(c in name for c in " :\\"):
        raise SuiteError(f"dataset name {name!r}: use letters, digits, '-' and '_'")
    return DATASETS_DIR / name


#: Fields a dataset selection may filter on (`NAME:TIER:family=wall+window,kind=transit`).
FILTER_FIELDS = ("family", "kind")


def parse_dataset_arg(text: str) -> tuple[str, str]:
    """`NAME[:TIER[:FILTERS]]` -> (name, tier); the tier defaults to the whole dataset."""
    name, _, rest = text.partition(":")
    tier = rest.partition(":")[0]
    return name, tier or ALL


def dataset_filters(text: str) -> dict[str, frozenset[str]]:
    """The filters of `NAME:TIER:FIELD=V1+V2,FIELD=...` as {field: allowed values}; {} without any.

    Raises:
        SuiteError: a filter that is not FIELD=VALUES with FIELD in FILTER_FIELDS.
    """
    spec = text.partition(":")[2].partition(":")[2]
    out: dict[str, frozenset[str]] = {}
    if not spec:
        return out
    for part in spec.split(","):
        field, eq, values = part.partition("=")
        vals = frozenset(v for v in values.split("+") if v)
        if field not in FILTER_FIELDS or not eq or not vals:
            raise SuiteError(f"dataset filter {part!r} in {text!r}: use FIELD=V1+V2 with FIELD one of "
                             f"{', '.join(FILTER_FIELDS)} (e.g. {text.split(':')[0]}:test:family=wall,kind=transit)")
        if field in out:
            raise SuiteError(f"dataset filter {field!r} given twice in {text!r}: list its values as V1+V2")
        out[field] = vals
    return out


def check_tier(name: str, tier: str, manifest: dict[str, Any]) -> None:
    """Raise a one-line SuiteError unless `tier` is ALL, a tier or a split of the dataset."""
    tiers, splits = manifest.get("tiers", {}), manifest.get("splits", {})
    if tier != ALL and tier not in tiers and tier not in splits:
        raise SuiteError(f"dataset {name!r} has no tier or split {tier!r}; allowed: "
                         f"{[ALL, *sorted(tiers), *sorted(s for s in splits if s not in tiers)]}")


def check_selection(text: str) -> None:
    """Check `NAME[:TIER[:FILTERS]]` without loading its problems: the dataset exists, the tier or
    split is one of its own and the filters parse (their values are checked when it is loaded)."""
    name, tier = parse_dataset_arg(text)
    check_tier(name, tier, read_manifest(dataset_dir(name)))
    dataset_filters(text)


@dataclasses.dataclass(frozen=True)
class Dataset:
    """A loaded dataset (or one tier of it).

    Attributes:
        name, hash, tier: what was loaded.
        manifest: the manifest as stored.
        ids: the problems' problem_ids, in stored order.
        problems: the tier's problems, in the same order.
        meta: per problem_id, the stored fields the runs report (family, kind, trivial,
            difficulty, split, reference_length_rad).
        references: per problem_id, the reference path (N, 7).
        cycle_steps: the stored trivial cycle steps that are not benchmark problems, as
            (scene_key, can_id, kind) -> (q_start, q_goal): their straight segment is valid.
        picking_orders: per scene_key, the cans of its cycle in picking order (every stored step
            counts, benchmark or not): a can whose every step is trivial is still picked.
        witnesses: per problem_id, the witness path searched with a margin from the obstacles,
            where the dataset stores one apart from its reference (datasets from recycle-v3 on).
    """

    name: str
    hash: str
    tier: str
    manifest: dict[str, Any]
    ids: tuple[str, ...]
    problems: tuple[PlanningProblem, ...]
    meta: dict[str, dict[str, Any]]
    references: dict[str, np.ndarray]
    cycle_steps: dict[tuple[str, int, str], tuple[list, list]] = dataclasses.field(default_factory=dict)
    picking_orders: dict[str, tuple[int, ...]] = dataclasses.field(default_factory=dict)
    witnesses: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)


META_FIELDS = ("family", "kind", "trivial", "difficulty", "straight_length_rad", "split", "reference_length_rad")


def _read_jsonl(path: Path) -> list[tuple[int, str, dict]]:
    try:
        text = path.read_text()
    except OSError as exc:
        raise SuiteError(f"cannot read {path}: {exc.strerror}") from None
    out = []
    for i, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        try:
            out.append((i, line, json.loads(line)))
        except ValueError:
            raise SuiteError(f"{path}: line {i} is not valid JSON") from None
    return out


def read_manifest(directory: Path) -> dict[str, Any]:
    path = directory / MANIFEST_FILE
    if not path.exists():
        known = sorted(p.name for p in DATASETS_DIR.iterdir() if (p / MANIFEST_FILE).exists()) if DATASETS_DIR.exists() else []
        raise SuiteError(f"no dataset at {str(directory)!r}; known datasets: {known}")
    try:
        manifest = json.loads(path.read_text())
    except (OSError, ValueError):
        raise SuiteError(f"{path} is not a readable dataset manifest") from None
    if not isinstance(manifest, dict):
        raise SuiteError(f"{path} is not a readable dataset manifest (a JSON object)")
    version = manifest.get("format_version", 1)  # datasets written before versions: version 1
    if isinstance(version, int) and not isinstance(version, bool) and version > FORMAT_VERSION:
        raise SuiteError(f"{path}: dataset format version {version} is newer than this suite reads (up to version "
                         f"{FORMAT_VERSION}); update the suite to read it")
    load(ManifestFields, manifest, where=f"{path}: ", ignore_unknown=True)
    return manifest


@dataclasses.dataclass(frozen=True)
class ManifestFields:
    """What this suite reads from a dataset's manifest.json (other fields are kept as they are)."""

    hash: Annotated[str, Field(pattern=r"^[0-9a-f]{20}$")]
    name: Annotated[str, Field(min_length=1)] | None = None
    format_version: Annotated[int, Field(ge=1, le=FORMAT_VERSION)] = 1
    tiers: dict[str, list[str]] = dataclasses.field(default_factory=dict)
    #: the rule its problem_ids were made with (`scenes.identity_rule`); absent in the datasets
    #: built before rules had names, whose rule is `round9`
    identity_rule: Literal[tuple(RULES)] = LEGACY_RULE  # type: ignore[valid-type]


def identity_rule(manifest: dict[str, Any]) -> str:
    """The identity rule of the problem_ids of a dataset or a run, from its manifest (absent: `round9`)."""
    return manifest.get("identity_rule", LEGACY_RULE)


def load_dataset(text: str, *, time_limit_s: float = 5.0) -> Dataset:
    """Load `NAME[:TIER]` (no IK, no scene generation); TIER may also name a split (`tune`, `test`).

    Raises:
        SuiteError: an unknown dataset or tier, or a file that does not parse.
    """
    name, tier = parse_dataset_arg(text)
    filters = dataset_filters(text)
    directory = dataset_dir(name)
    manifest = read_manifest(directory)
    check_tier(name, tier, manifest)
    tiers = manifest.get("tiers", {})
    splits = manifest.get("splits", {})
    wanted = None if tier == ALL or tier not in tiers else set(tiers[tier])
    split = tier if tier not in tiers and tier in splits else None  # a split is a tier too
    scenes = {rec["scene_key"]: rec for _, _, rec in _read_jsonl(directory / SCENES_FILE)}
    built: dict[str, Scene] = {}
    ids, problems, meta, refs, steps, wits = [], [], {}, {}, {}, {}
    seen: dict[str, set[str]] = {field: set() for field in filters}  # every value of a filtered field
    removed_before: dict[str, dict[int, int]] = {}  # scene -> can -> how many cans were picked before it
    for lineno, _, rec in _read_jsonl(directory / PROBLEMS_FILE):
        pid = rec.get("problem_id")
        before = removed_before.setdefault(rec["scene_key"], {})
        n_removed = len(rec.get("removed_can_ids") or ())  # the return after a drop counts its own can
        if rec.get("can_id") is not None:  # a cycle's motion (a free transit picks no can)
            before[int(rec["can_id"])] = min(before.get(int(rec["can_id"]), n_removed), n_removed)
        if not rec.get("benchmark", True):
            steps[(rec["scene_key"], int(rec["can_id"]), rec["kind"])] = (rec["q_start"], rec["q_goal"])
            continue
        for field in filters:
            seen[field].add(str(rec.get(field)))
        if (wanted is not None and pid not in wanted) or (split is not None and rec.get("split") != split):
            continue
        if any(str(rec.get(field)) not in allowed for field, allowed in filters.items()):
            continue
        key = rec.get("scene_key")
        if key not in scenes:
            raise SuiteError(f"{directory / PROBLEMS_FILE}: line {lineno} (problem {pid}) names unknown scene {key!r}")
        try:
            if key not in built:
                built[key] = scene_from_record(scenes[key])
            problem = problem_from_record(rec, built[key], time_limit_s=time_limit_s,
                                          where=f"{directory / PROBLEMS_FILE}: line {lineno} (problem {pid}) is not a "
                                                "stored problem: ")
            ref = np.asarray(rec["reference"]["path"], float)
        except (KeyError, TypeError, ValueError, StopIteration) as exc:
            what = f"field {exc.args[0]!r} missing" if isinstance(exc, KeyError) else f"{type(exc).__name__}: {exc}"
            raise SuiteError(f"{directory / PROBLEMS_FILE}: line {lineno} (problem {pid}) is not a stored problem: "
                             f"{what}".splitlines()[0]) from None
        ids.append(pid)
        problems.append(problem)
        meta[pid] = {"problem_id": pid, **{k: rec.get(k) for k in META_FIELDS}}
        refs[pid] = ref
        if rec.get("witness"):
            wits[pid] = np.asarray(rec["witness"]["path"], float)
    for field, allowed in filters.items():
        unknown = sorted(allowed - seen[field])
        if unknown:
            raise SuiteError(f"dataset {name!r} has no {field} {unknown[0]!r}; allowed: {sorted(seen[field])}")
    if filters and not ids:
        raise SuiteError(f"{text!r} selects no problem of dataset {name!r} (tier or split {tier!r})")
    orders = {key: tuple(sorted(cans, key=lambda c: (cans[c], c))) for key, cans in removed_before.items()}
    return Dataset(name, manifest["hash"], tier, manifest, tuple(ids), tuple(problems), meta, refs, steps, orders, wits)


def tuning_problems(dataset: str, *, per_family: int | None, time_limit_s: float
                    ) -> tuple[Dataset, list[tuple[PlanningProblem, dict[str, Any]]]]:
    """The tuning sample of dataset NAME (`tune`, `regions --tune-sample`): the non-trivial problems
    of its tune split, up to per_family of each family (None: all), lowest problem id first.
    Returns (the tune split, [(problem, meta)])."""
    name, tier = parse_dataset_arg(dataset)
    if tier != ALL:
        raise SuiteError(f"--dataset takes a dataset name (its tune split is used), got {dataset!r}")
    ds = load_dataset(f"{name}:tune", time_limit_s=time_limit_s)
    by_family: dict[str, list] = {}
    for pid, problem in sorted(zip(ds.ids, ds.problems), key=lambda x: x[0]):
        meta = ds.meta[pid]
        if not meta.get("trivial"):
            by_family.setdefault(str(meta["family"]), []).append((problem, meta))
    chosen = [x for fam in sorted(by_family) for x in by_family[fam][:per_family]]
    if not chosen:
        raise SuiteError(f"dataset {name!r} has no non-trivial problem in its tune split")
    return ds, chosen


def dataset_scene(name: str, scene_key: str) -> Scene:
    """One stored scene of a dataset, by its key."""
    for _, _, rec in _read_jsonl(dataset_dir(name) / SCENES_FILE):
        if rec["scene_key"] == scene_key:
            return scene_from_record(rec)
    raise SuiteError(f"dataset {name!r} holds no scene {scene_key!r}")


def verify_dataset(name: str, *, progress=None) -> dict[str, int]:
    """Re-derive every problem's content hash and record hash, re-validate every reference with
    the validator, give every benchmark reference its exact verdict (`certify_path`), and check
    the dataset hash. A dataset whose manifest says `references_certified` must have every
    benchmark reference certified; older ones get the counts. Raises SuiteError naming the first
    problem that fails."""
    from planners.worlds import collision_world
    from suite.scoring.validate import certify_path, validate_path

    directory = dataset_dir(name)
    manifest = read_manifest(directory)
    scene_rows = _read_jsonl(directory / SCENES_FILE)
    scenes = {rec["scene_key"]: scene_from_record(rec) for _, _, rec in scene_rows}
    for _, _, rec in scene_rows:
        if scenes[rec["scene_key"]].key() != rec["scene_key"]:
            raise SuiteError(f"dataset {name!r}: scene {rec['scene_key']} does not hash to its key (edited?)")
    records = _read_jsonl(directory / PROBLEMS_FILE)
    rule = identity_rule(manifest)
    must_certify = bool(manifest.get("references_certified"))
    verdicts = {"certified": 0, "unproved": 0, "collision": 0}
    for i, (lineno, _, rec) in enumerate(records):
        pid = rec.get("problem_id")
        if record_hash(rec) != rec.get("record_hash"):
            raise SuiteError(f"dataset {name!r}: problem {pid} (line {lineno}): record hash mismatch (edited?)")
        problem = problem_from_record(rec, scenes[rec["scene_key"]], time_limit_s=1.0)
        if problem_id(problem, rule=rule) != pid:
            raise SuiteError(f"dataset {name!r}: problem {pid} (line {lineno}): content does not hash to its problem_id "
                             f"(identity rule {rule})")
        world = collision_world(problem)
        path = np.asarray(rec["reference"]["path"], float)
        reason = validate_path(problem, path, world)
        if reason is not None:
            raise SuiteError(f"dataset {name!r}: problem {pid} (line {lineno}): reference rejected: {reason}")
        if rec.get("witness"):
            wpath = np.asarray(rec["witness"]["path"], float)
            reason = validate_path(problem, wpath, world)
            if reason is None and certify_path(wpath, world)["verdict"] != "certified":
                reason = "not certified"
            if reason is not None:
                raise SuiteError(f"dataset {name!r}: problem {pid} (line {lineno}): witness rejected: {reason}")
        if rec.get("benchmark", True):
            cert = certify_path(path, world)
            verdicts[cert["verdict"]] += 1
            if must_certify and cert["verdict"] != "certified":
                raise SuiteError(f"dataset {name!r}: problem {pid} (line {lineno}): reference not certified: "
                                 f"{cert['verdict']} on segment {cert.get('segment')} ({' vs '.join(cert.get('pair', []))})")
        length = float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)))
        if abs(length - rec["reference_length_rad"]) > 1e-6:
            raise SuiteError(f"dataset {name!r}: problem {pid} (line {lineno}): reference length {length:.6f} "
                             f"!= stored {rec['reference_length_rad']:.6f}")
        if progress is not None:
            progress(i + 1, len(records))
    h = dataset_hash([line for _, line, _ in scene_rows], [rec for _, _, rec in records])
    if h != manifest.get("hash"):
        raise SuiteError(f"dataset {name!r}: dataset hash {h} != manifest's {manifest.get('hash')}")
    bench = sum(1 for _, _, rec in records if rec.get("benchmark", True))
    return {"scenes": len(scene_rows), "problems": bench, "cycle_steps": len(records) - bench,
            "identity_rule": rule, "references": verdicts, "references_must_be_certified": must_certify}


def summary(ds: Dataset) -> dict[str, Any]:
    """The composition of a loaded dataset (tier): counts per family, trivial, difficulty."""
    fams: dict[str, dict[str, Any]] = {}
    for pid, p in zip(ds.ids, ds.problems):
        m = ds.meta[pid]
        f = fams.setdefault(m["family"], {"scenes": set(), "problems": 0, "trivial": 0, "kinds": {}})
        f["scenes"].add(p.scene.key())
        f["problems"] += 1
        f["trivial"] += bool(m["trivial"])
        f["kinds"][m["kind"]] = f["kinds"].get(m["kind"], 0) + 1
    diff = np.array([ds.meta[k]["difficulty"] for k in ds.meta], float)
    ratio = np.array([ds.meta[k]["reference_length_rad"] / max(ds.meta[k]["straight_length_rad"], 1e-9)
                      for k in ds.meta], float)
    qs = (0.0, 0.25, 0.5, 0.75, 1.0)
    return {
        "name": ds.name, "tier": ds.tier, "hash": ds.hash, "identity_rule": identity_rule(ds.manifest),
        "problems": len(ds.problems), "distinct": len(ds.meta),
        "trivial": int(sum(bool(m["trivial"]) for m in ds.meta.values())),
        "families": {k: {"scenes": len(v["scenes"]), "problems": v["problems"], "trivial": v["trivial"],
                         "kinds": dict(sorted(v["kinds"].items()))} for k, v in sorted(fams.items())},
        "splits": {s: sum(1 for m in ds.meta.values() if m["split"] == s) for s in sorted({m["split"] for m in ds.meta.values()})},
        "difficulty_quantiles": dict(zip(("min", "q1", "median", "q3", "max"),
                                         [round(float(v), 4) for v in np.quantile(diff, qs)] if len(diff) else [])),
        "reference_over_straight_quantiles": dict(zip(("min", "q1", "median", "q3", "max"),
                                                      [round(float(v), 4) for v in np.quantile(ratio, qs)] if len(ratio) else [])),
        "tiers": {k: len(v) for k, v in ds.manifest.get("tiers", {}).items()},
        "build": ds.manifest.get("build", {}),
    }
