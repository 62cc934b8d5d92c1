"""Appending trial records to a run's trials.jsonl, one whole line at a time.

Each record is one `write` of one line, then flushed to disk (`fsync`), by the parent only. If an
append fails (a full disk, an I/O error) the file is cut back to where the line began, so what
is on disk stays a sequence of whole records and `--resume` continues from it; the failure is one
`RecordWriteError` naming the file and the error. A file removed while the run writes to it
is noticed at the next append (its link count drops to zero) and reported the same way.
"""

from __future__ import annotations

import errno
import json
import os
from pathlib import Path
from typing import TYPE_CHECKING

from scenes.errors import SuiteError

if TYPE_CHECKING:
    from suite.run.records import TrialRecord


class RecordWriteError(SuiteError):
    """An append to trials.jsonl failed: the run stops (what is on disk is kept)."""

    def __init__(self, path: Path, exc: OSError) -> None:
        name = errno.errorcode.get(exc.errno or 0, "")
        detail = f"{exc.strerror or exc} ({name})" if name else str(exc.strerror or exc)
        super().__init__(f"cannot append to {path}: {detail}")
        self.path = path
        self.errno = exc.errno


def _write(fd: int, data: bytes) -> int:
    """One `os.write` (a seam where tests inject a full disk)."""
    return os.write(fd, data)


class TrialsJournal:
    """Append-only writer of trial records (a context manager).

    Args:
        path: the trials.jsonl file; created if missing.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        try:
            self._fd: int | None = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_CLOEXEC, 0o644)
        except OSError as exc:
            raise RecordWriteError(self.path, exc) from None
        self.appended = 0

    def append(self, record: TrialRecord) -> None:
        """Write one record (its JSON, `TrialRecord.to_json`) as one line and sync it to disk.

        Raises:
            RecordWriteError: the line could not be written whole (the file is cut back to the
                last whole record where possible), or the file was removed under the run.
        """
        assert self._fd is not None, "journal closed"
        data = (json.dumps(record.to_json()) + "\n").encode()
        fd = self._fd
        try:
            st = os.fstat(fd)
            start = st.st_size
            if st.st_nlink == 0:
                raise OSError(errno.ENOENT, "the file was removed during the run")
        except OSError as exc:
            raise RecordWriteError(self.path, exc) from None
        try:
            done = 0
            while done < len(data):
                n = _write(fd, data[done:])
                if n <= 0:
                    raise OSError(errno.EIO, "short write")
                done += n
            os.fsync(fd)
        except OSError as exc:
            try:
                os.ftruncate(fd, start)  # no torn line left behind
            except OSError:
                pass  # a torn last line is still skipped by every reader and cut by --resume
            raise RecordWriteError(self.path, exc) from None
        self.appended += 1

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> "TrialsJournal":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
