"""Format versions of what a run writes (trial records, run manifests).

A reader accepts its own version and every older one (a file without a version is version 1); a
file written by a newer format is one error line naming both versions. Datasets carry their own
`format_version` (`suite.problems.dataset.FORMAT_VERSION`).
"""

from __future__ import annotations

from typing import Any

from scenes.errors import SuiteError

#: The newest version of the trial records in trials.jsonl this suite writes and reads.
#: 2: a record's budget may be CPU time (`budget_clock`: "cpu"), and then its TIMEOUT (a late
#: success included) was judged on its `planning_cpu_time_s`, not its wall time.
RECORD_FORMAT_VERSION = 2
#: The newest version of a run's manifest.json this suite writes and reads.
#: 2: the run's `config.budget_clock` may be "cpu" (a suite that does not know it would resume the
#: run on the wall clock).
MANIFEST_FORMAT_VERSION = 2


def record_format_version(*, budget_clock: str) -> int:
    """The version a new record is written with: the oldest that reads it correctly. A wall-clock
    record is version 1 (its `planning_cpu_time_s`, `budget_clock` and `contention` are additions a
    version-1 reader may ignore); a CPU-clock one is version 2."""
    return 1 if budget_clock == "wall" else 2


def manifest_format_version(*, budget_clock: str) -> int:
    """The version a new run manifest is written with (as `record_format_version`)."""
    return 1 if budget_clock == "wall" else 2


def format_version(data: dict[str, Any]) -> int:
    """The `format_version` of a record, manifest or dataset manifest (missing: 1)."""
    v = data.get("format_version", 1)
    return v if isinstance(v, int) and not isinstance(v, bool) else -1


def check_version(data: dict[str, Any], *, supported: int, what: str, where: str) -> int:
    """The data's format version, if this suite reads it.

    Raises:
        SuiteError: one line naming the file (`where`), the data's version and the newest one read.
    """
    v = format_version(data)
    if v < 1:
        raise SuiteError(f"{where}: {what} format_version = {data.get('format_version')!r}: allowed: an integer "
                         f"from 1 to {supported}")
    if v > supported:
        raise SuiteError(f"{where}: {what} format version {v} is newer than this suite reads (up to version "
                         f"{supported}); update the suite to read it")
    return v
