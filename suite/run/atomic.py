"""Replacing a file whole: the suite's one way to rewrite a result file (a manifest, execution.json,
moving_bin.json, a rescored trials.jsonl, a tuned-settings file) so that a reader, or a run killed
half way, never sees half of it."""

from __future__ import annotations

import os
from pathlib import Path


def write_text_atomically(path: Path, text: str) -> None:
    """Write `text` to a temporary file beside `path`, sync it to disk, then rename it over `path`
    (one rename: the old file or the new one, never a torn one). The temporary file is removed if
    anything fails."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
