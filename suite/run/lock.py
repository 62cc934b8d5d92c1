"""One writer per run directory: an exclusive `fcntl` lock on `DIR/.lock`, held for the whole run.

The lock is taken before anything in the directory is checked or written, so two runs started
into the same new directory at the same moment cannot both proceed. The kernel drops an `fcntl`
lock when its process ends, however it ends, so a lock file left behind by a killed run does not
block the next `--resume`. The file itself stays (removing a lock file races with a process that
has just opened it); it holds the PID of the last holder, for the error message.
"""

from __future__ import annotations

import errno
import fcntl
import os
from pathlib import Path

from scenes.errors import SuiteError

LOCK_FILE = ".lock"


class RunLock:
    """An exclusive, non-blocking lock on a directory (a context manager).

    Args:
        directory: the run (or dataset) directory; created if missing.
        what: how the error message names the holder ("run", "dataset build").
    """

    def __init__(self, directory: str | Path, *, what: str = "run") -> None:
        self.directory = Path(directory)
        self.path = self.directory / LOCK_FILE
        self.what = what
        self._fd: int | None = None

    def acquire(self) -> "RunLock":
        """Take the lock now or fail.

        Raises:
            SuiteError: another process holds it (one line naming the directory and its PID), or
                the directory cannot be created or written.
        """
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        except OSError as exc:
            raise SuiteError(f"--out {str(self.directory)!r} is not writable: {exc.strerror}") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = _read_pid(fd)
            os.close(fd)
            raise SuiteError(f"{str(self.directory)!r} is in use by another {self.what} (PID {holder}); "
                             "wait for it to end, or use another directory") from None
        try:
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        except OSError as exc:  # e.g. a full disk: the lock itself holds, the PID is only for messages
            if exc.errno != errno.ENOSPC:
                os.close(fd)
                raise SuiteError(f"--out {str(self.directory)!r} is not writable: {exc.strerror}") from None
        self._fd = fd
        return self

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)  # closing drops the flock
            self._fd = None

    @property
    def held(self) -> bool:
        return self._fd is not None

    def __enter__(self) -> "RunLock":
        return self.acquire() if self._fd is None else self

    def __exit__(self, *exc) -> None:
        self.release()


def _read_pid(fd: int) -> str:
    try:
        text = os.pread(fd, 32, 0).decode(errors="replace").strip()
    except OSError:
        text = ""
    return text if text.isdigit() else "unknown"
