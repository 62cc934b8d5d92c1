"""A run's manifest.json: what ran (the command, the settings, the dataset and the identity rule of
its problem_ids), with which code (the package versions, the git commit) on which machine, and how
it ended (status, counts, contention), updated as the run goes.

The manifest is written beside itself and renamed over the old one, so a reader never sees half of
it; a manifest of a newer format than this suite reads is one error line.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import json
import logging
import platform
import subprocess
from pathlib import Path
from typing import TYPE_CHECKING, Any

from scenes.errors import SuiteError
from suite.run.atomic import write_text_atomically

if TYPE_CHECKING:
    from suite.run.runner import CompareConfig

log = logging.getLogger(__name__)

MANIFEST_FILE = "manifest.json"


def git_commit() -> str | None:
    """The checkout's commit, with "+dirty" when tracked files differ from it (the code that ran is
    then not that commit's)."""
    here = Path(__file__).parent
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=here, capture_output=True, text=True, timeout=5)
        commit = out.stdout.strip()
        if not commit:
            return None
        changed = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=here,
                                 capture_output=True, text=True, timeout=10)
        return commit + "+dirty" if changed.returncode == 0 and changed.stdout.strip() else commit
    except (OSError, subprocess.SubprocessError):
        return None


def versions() -> dict[str, str | None]:
    from importlib.metadata import PackageNotFoundError, version

    out = {"python": platform.python_version()}
    for dist in ("drake", "ompl", "python-fcl", "toppra", "numpy", "opencv-python-headless", "scipy"):
        try:
            out[dist] = version(dist)
        except PackageNotFoundError:
            out[dist] = None
    return out


def write_manifest(out: Path, config: CompareConfig, *, argv: list[str]) -> None:
    from scenes.identity_rule import CURRENT_RULE
    from suite.run.executors import cpu_description

    dataset, rule = None, CURRENT_RULE  # the rule of the run's problem_ids
    if config.dataset:
        from suite.problems.dataset import dataset_dir, dataset_filters, identity_rule, parse_dataset_arg, read_manifest

        name, tier = parse_dataset_arg(config.dataset)
        ds_manifest = read_manifest(dataset_dir(name))
        dataset, rule = {"name": name, "tier": tier, "hash": ds_manifest["hash"]}, identity_rule(ds_manifest)
        filters = dataset_filters(config.dataset)
        if filters:
            dataset["filters"] = {field: sorted(values) for field, values in filters.items()}
    from suite.run.formats import manifest_format_version

    manifest = {
        "format_version": manifest_format_version(budget_clock=config.budget_clock),
        "status": "running",
        "command": " ".join(["python -m suite"] + argv),
        "config": dataclasses.asdict(config),
        "dataset": dataset,
        "identity_rule": rule,
        "versions": versions(),
        "git_commit": git_commit(),
        "machine": {**cpu_description(), "platform": platform.platform()},
        "started_utc": _now(),
    }
    _write_json_atomically(out / MANIFEST_FILE, manifest)


def _now() -> str:
    return dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds")


def _write_json_atomically(path: Path, data: dict[str, Any]) -> None:
    write_text_atomically(path, json.dumps(data, indent=2) + "\n")


def read_run_manifest(out: Path) -> dict[str, Any] | None:
    """A run's manifest.json (None if it has none).

    Raises:
        SuiteError: it does not parse, or was written by a newer manifest format.
    """
    from suite.run.formats import MANIFEST_FORMAT_VERSION, check_version

    path = out / MANIFEST_FILE
    try:
        manifest = json.loads(path.read_text())
    except FileNotFoundError:
        return None
    except (OSError, ValueError):
        raise SuiteError(f"{path} is not a readable run manifest") from None
    if not isinstance(manifest, dict):
        raise SuiteError(f"{path} is not a readable run manifest")
    check_version(manifest, supported=MANIFEST_FORMAT_VERSION, what="run manifest", where=str(path))
    return manifest


def update_manifest(out: Path, **fields: Any) -> bool:
    """Set fields of a run's manifest (status, counts); best effort, False if it could not.

    A run stopped by a full disk may not be able to say so in its manifest: the error line it
    prints is what counts, and the records on disk are the truth.
    """
    try:
        manifest = read_run_manifest(out)
        if manifest is None:
            return False
        manifest.update(fields)
        manifest.setdefault("format_version", 1)
        _write_json_atomically(out / MANIFEST_FILE, manifest)
        return True
    except (OSError, SuiteError) as exc:
        log.warning("could not update %s: %s", out / MANIFEST_FILE, exc)
        return False
