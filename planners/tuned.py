"""Tuned planner settings: what `python -m suite tune` chose on a dataset's tuning split, and the
small documented search each planner's settings are chosen from.

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

#: What each planner is tuned for once success is settled: "time" (a feasibility planner:
#: median time to solve, failures at the budget) or "length" (an optimizing planner: median length
#: over the best known path, on the problems every candidate solved).
OBJECTIVE: dict[str, str] = {
    "ik": "time", "rrt": "time", "roboplan-rrt": "time",
    "rrtstar": "length", "bitstar": "length", "aorrtc": "length", "prm": "length",
    "trajopt": "length", "gcs": "length",
}

#: The search: each setting's candidate values (the grid is their product). Small on purpose: a
#: tuning run must fit a session on 2 cores; the first value of each is the class default.
SEARCH_SPACES: dict[str, dict[str, tuple]] = {
    # None: OMPL's own range (a fifth of the space's extent, about 2.8 rad here), and steps around it
    "rrt": {"range_rad": (None, 2.0, 1.0, 0.5), "simplifier": ("rope", "rope+full")},
    # roboplan's own max connection distance (3.0) first, steps around it, and rrt's 1.0; always
    # shortcut, as rrt always simplifies (unshortcut paths return sooner but are 1.4 to 5.6 times
    # the reference length on the tune split, and the time objective alone would choose them)
    "roboplan-rrt": {"range_rad": (3.0, 2.0, 1.0, 0.5)},
    "rrtstar": {"range_rad": (None, 1.0, 0.5, 0.25), "goal_bias": (0.05, 0.2)},
    "bitstar": {"samples_per_batch": (100, 400), "range_rad": (None, 1.0)},
    "aorrtc": {"range_rad": (None, 1.0, 0.5)},
    "prm": {"max_nearest_neighbors": (10, 20), "range_rad": (None, 1.0)},
    "trajopt": {"num_control_points": (10, 16), "num_collision_samples": (15, 30),
                "initial_guess": ("straight", "via_waypoints")},
    "ik": {"knot_dt_tu": (0.5, 0.25), "position_tolerance_transit_m": (0.05, 0.1),
           "orientation_tolerance_transit_rad": (0.3, 0.6)},
    "gcs": {"order": (1, 3), "max_rounded_paths": (5, 10)},
}


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
