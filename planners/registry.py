"""Planner registry: an explicit table of built-in planners plus entry points.

Built-ins are imported lazily (OMPL is not loaded to run `ik`). Third-party packages add planners
with an entry point in the group `suite.planners`, e.g. in their pyproject.toml:

    [project.entry-points."suite.planners"]
    myplanner = "mypackage.module:MyPlanner"
"""

from __future__ import annotations

import importlib
from importlib.metadata import entry_points

from scenes.errors import SuiteError

BUILTIN = {
    "ik": "planners.nominal_ik:NominalIkPlanner",
    "rrt": "planners.ompl_rrt:RRTConnectPlanner",
    "rrtstar": "planners.ompl_rrt:RRTstarPlanner",
    "bitstar": "planners.ompl_rrt:BITstarPlanner",
    "aorrtc": "planners.ompl_rrt:AORRTCPlanner",
    "prm": "planners.ompl_rrt:PRMPlanner",
    "trajopt": "planners.trajopt:TrajoptPlanner",
    "gcs": "planners.gcs:GcsPlanner",
}
ENTRY_POINT_GROUP = "suite.planners"


def known_planners() -> dict[str, str]:
    """Name -> "module:Class" for built-ins and installed entry points (built-ins win)."""
    table = {ep.name: ep.value for ep in entry_points(group=ENTRY_POINT_GROUP)}
    table.update(BUILTIN)
    return table


def planner_class(name: str) -> type:
    """The planner class registered under `name`.

    Raises:
        SuiteError: for an unknown name, listing the known ones.
    """
    table = known_planners()
    if name not in table:
        raise SuiteError(f"unknown planner {name!r}; known planners: {', '.join(sorted(table))}")
    module, _, attr = table[name].partition(":")
    return getattr(importlib.import_module(module), attr)


def parse_planner_list(text: str) -> list[str]:
    """Split and check a comma-separated planner list (e.g. "ik,rrt,trajopt")."""
    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names:
        raise SuiteError(f"--planners must name at least one planner, got {text!r}")
    table = known_planners()
    for n in names:
        if n not in table:
            raise SuiteError(f"unknown planner {n!r}; known planners: {', '.join(sorted(table))}")
    if len(set(names)) != len(names):
        raise SuiteError(f"--planners names a planner twice: {text!r}")
    return names


def make_planner(name: str, config=None):
    """An instance of the named planner with its default (or the given) config."""
    return planner_class(name)(config)
