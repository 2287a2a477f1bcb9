"""One process per run directory: an OS file lock on ``RUN_DIR/lock``.

Two runs writing one directory would log every row twice and collide on their checkpoints, so
the process that opens a run directory (``train``, a server run through the same loop, a resume)
holds an exclusive ``flock`` on its lock file until it closes the run. The kernel drops the lock
when the process ends, however it ends (``kill -9`` too), so a lock is never stale; the file
itself stays (removing it would let a third process lock a new file while a second still holds
the old one), unless the directory was made for a run that was refused before it wrote anything.
The file holds the holder's process id, for the message of the process that is refused.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
from pathlib import Path
from typing import IO

from elevens.runs.errors import RunRefusedError
from elevens.runs.layout import RunLayout


class RunDirectoryLock:
    """A held lock on a run directory; ``release`` (or the process's end) lets it go."""

    def __init__(self, path: Path, file: IO[str], created: bool = False) -> None:
        self.path = path
        self._file: IO[str] | None = file
        self._created = created  # whether locking made the directory

    @property
    def held(self) -> bool:
        return self._file is not None

    def release(self) -> None:
        """Unlock (closing the file unlocks); calling it again does nothing. A directory the
        lock made and the run left empty (refused before it wrote anything) is removed."""
        if self._file is None:
            return
        root = self.path.parent
        empty = self._created and [entry.name for entry in root.iterdir()] == [self.path.name]
        if empty:
            self.path.unlink()  # while still locked: no one else holds it
        self._file.close()
        self._file = None
        if empty:
            with contextlib.suppress(OSError):  # someone made something there meanwhile
                root.rmdir()


def lock_run_directory(
    run_dir: str | os.PathLike[str], flag: str = "--run.run-dir"
) -> RunDirectoryLock:
    """Create ``run_dir`` if needed and lock it for this process. Raises ``RunRefusedError``
    (one line) if another process holds it (naming that process's id), or if ``run_dir`` cannot
    be a run directory (a file, or not writable), naming ``flag``."""
    root = Path(run_dir)
    path = RunLayout.of(root).lock
    created = not root.exists()
    try:
        root.mkdir(parents=True, exist_ok=True)
        file = path.open("a+", encoding="utf-8")
    except FileExistsError as error:
        raise RunRefusedError(
            f"{flag} {str(root)!r} is not a directory ({error.filename} is a file); give a "
            "directory for the run (it is created if missing)"
        ) from error
    except OSError as error:
        raise RunRefusedError(
            f"{flag} {str(root)!r} cannot hold a run: {error.strerror or error} "
            f"({error.filename or path}); give a directory this user can write"
        ) from error
    try:
        fcntl.flock(file.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        file.seek(0)
        holder = file.read().strip() or "unknown"
        file.close()
        raise RunRefusedError(
            f"{root} is in use by another run (process {holder}); wait for it to end, or "
            f"choose another {flag}"
        ) from None
    file.seek(0)
    file.truncate()
    file.write(f"{os.getpid()}\n")
    file.flush()
    return RunDirectoryLock(path, file, created)
