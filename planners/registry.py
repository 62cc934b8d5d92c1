"""Planner registry: an explicit table of built-in planners plus entry points.

Built-ins are imported lazily (OMPL is not loaded to run `ik`). A built-in that needs an optional
extra (`OPTIONAL`) is named like any other; without its extra, naming it is a one-line SuiteError
that names the extra, and nothing falls back to another planner. Third-party packages add planners
with an entry point in the group `suite.planners`, e.g. in their pyproject.toml:

    [project.entry-points."suite.planners"]
    myplanner = "mypackage.module:MyPlanner"
"""

from __future__ import annotations

import importlib
import importlib.util
from importlib.metadata import entry_points

from planners.base import PLANNER_METHODS
from scenes.errors import SuiteError

BUILTIN = {
    "ik": "planners.nominal_ik:NominalIkPlanner",
    "rrt": "planners.ompl_rrt:RRTConnectPlanner",
    "rrtstar": "planners.ompl_rrt:RRTstarPlanner",
    "bitstar": "planners.ompl_rrt:BITstarPlanner",
    "aorrtc": "planners.ompl_rrt:AORRTCPlanner",
    "prm": "planners.ompl_rrt:PRMPlanner",
    "prm-roadmap": "planners.ompl_roadmap:PRMRoadmapPlanner",
    "prm-roadmap-shortcut": "planners.ompl_roadmap:ShortcutPRMRoadmapPlanner",
    "trajopt": "planners.trajopt:TrajoptPlanner",
    "gcs": "planners.gcs.planner:GcsPlanner",
    "roboplan-rrt": "planners.roboplan_rrt:RoboplanRRTPlanner",
}
#: Built-ins that need an optional extra: name -> (the module it needs, the extra that installs it).
OPTIONAL = {
    "roboplan-rrt": ("roboplan", "peers"),
}
ENTRY_POINT_GROUP = "suite.planners"


def known_planners() -> dict[str, str]:
    """Name -> "module:Class" for built-ins and installed entry points (built-ins win)."""
    table = {ep.name: ep.value for ep in entry_points(group=ENTRY_POINT_GROUP)}
    table.update(BUILTIN)
    return table


def _missing_extra(name: str) -> SuiteError:
    extra = OPTIONAL[name][1]
    return SuiteError(f"planner {name!r} needs the optional extra: pip install -e .[{extra}]")


def check_available(name: str) -> None:
    """Raise the one-line SuiteError naming the extra if `name` needs one that is not installed."""
    if name in OPTIONAL and importlib.util.find_spec(OPTIONAL[name][0]) is None:
        raise _missing_extra(name)


def planner_class(name: str) -> type:
    """The planner class registered under `name`.

    Raises:
        SuiteError: for an unknown name, listing the known ones, or a built-in whose optional
            extra is not installed, naming the extra.
    """
    table = known_planners()
    if name not in table:
        raise SuiteError(f"unknown planner {name!r}; known planners: {', '.join(sorted(table))}")
    check_available(name)
    module, _, attr = table[name].partition(":")
    try:
        mod = importlib.import_module(module)
    except ModuleNotFoundError as exc:
        needed = OPTIONAL.get(name, (None,))[0]
        if needed is not None and (exc.name or "").split(".")[0] == needed:
            raise _missing_extra(name) from None
        raise
    cls = getattr(mod, attr)
    missing = [m for m in PLANNER_METHODS if not callable(getattr(cls, m, None))]
    if missing:
        raise SuiteError(f"planner {name!r} ({table[name]}) has no {missing[0]}() method; a planner implements "
                         f"{', '.join(PLANNER_METHODS)} (planners.base.Planner; PlannerBase gives a prepare that does nothing)")
    return cls


def parse_planner_list(text: str) -> list[str]:
    """Split and check a comma-separated planner list (e.g. "ik,rrt,trajopt")."""
    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names:
        raise SuiteError(f"--planners must name at least one planner, got {text!r}")
    table = known_planners()
    for n in names:
        if n not in table:
            raise SuiteError(f"unknown planner {n!r}; known planners: {', '.join(sorted(table))}")
        check_available(n)
    if len(set(names)) != len(names):
        raise SuiteError(f"--planners names a planner twice: {text!r}")
    return names


def make_planner(name: str, config=None):
    """An instance of the named planner with its default (or the given) config."""
    return planner_class(name)(config)
