"""The repository's texts where modules are named, for the layout tests of moved packages
(`tests/scenes/collision/test_layout.py`, `tests/planners/gcs/test_gcs_layout.py`)."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Where modules are named: the packages, the tests, the adapters and the readers' pages.
SOURCES = ("suite", "planners", "perception", "scenes", "tests", "adapters")


def repo_texts():
    """(path relative to the repository, text) of every docs page, the README and every Python file
    of `SOURCES`."""
    files = [*ROOT.glob("docs/*.md"), ROOT / "README.md"]
    for top in SOURCES:
        files += (ROOT / top).rglob("*.py")
    for f in files:
        if f.is_file():
            yield f.relative_to(ROOT), f.read_text(encoding="utf-8")
