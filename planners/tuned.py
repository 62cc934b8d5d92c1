"""Tuned planner settings: what `python -m suite tune` chose on a dataset's tuning split, and the
small documented search each planner's settings are chosen from (declared on the planner's class,
next to its config: `search_space`, `tuning_objective`).

`planners/configs/NAME.yaml` holds a planner's chosen `settings` and the `table` of every
candidate's results that justified them. A planner built without explicit settings starts from
its class defaults overlaid with these (see `suite.run.trial.make_config`), so every comparison
runs each planner as tuned, and a record's `planner_config` says exactly what ran.
"""

from __future__ import annotations

import copy
import functools
from pathlib import Path
from typing import Any

from scenes.errors import SuiteError

CONFIGS_DIR = Path(__file__).resolve().parent / "configs"

def search_space(planner: str) -> dict[str, tuple]:
    """The planner's tuning search (its class's `search_space`; {} for a planner without one)."""
    from planners.registry import planner_class

    return dict(getattr(planner_class(planner), "search_space", {}) or {})


def objective(planner: str) -> str:
    """What the planner is tuned for once success is settled: "time" or "length" (its class's
    `tuning_objective`; "time" for a planner that does not say)."""
    from planners.registry import planner_class

    return str(getattr(planner_class(planner), "tuning_objective", "time"))


def config_path(planner: str) -> Path:
    return CONFIGS_DIR / f"{planner}.yaml"


def read_tuned(planner: str) -> dict[str, Any] | None:
    """The planner's tuned-config file as a dict (settings, table, provenance), or None if it has none.

    Parsed once per file version (its path, size and modification time) in a process: every trial
    asks for its planner's settings, and parsing the file with its table cost 29 ms a trial."""
    path = config_path(planner)
    if not path.is_file():
        return None
    st = path.stat()
    data = _parse_tuned(str(path), st.st_size, st.st_mtime_ns)
    return None if data is None else copy.deepcopy(data)


@functools.lru_cache(maxsize=64)
def _parse_tuned(path_s: str, _size: int, _mtime_ns: int) -> dict[str, Any] | None:
    import yaml

    path = Path(path_s)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError) as exc:
        raise SuiteError(f"{path}: cannot read the tuned settings: {exc}") from None
    if not isinstance(data, dict) or not isinstance(data.get("settings"), dict):
        raise SuiteError(f"{path}: a tuned-config file needs a 'settings' mapping; got {type(data).__name__}")
    return data


def tuned_settings(planner: str) -> dict[str, Any]:
    """The settings `tune` chose for the planner ({} when it has no tuned-config file)."""
    data = read_tuned(planner)
    return dict(data["settings"]) if data else {}
