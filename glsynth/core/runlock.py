"""One writer per output folder, through flock on lock files inside it.

- The driver of a run holds an exclusive lock on ``<folder>/.glsynth.lock`` for the whole run
  and writes its pid there; a second driver gets an error naming that pid.
- Worker processes (a local pool, Ray actors) hold a shared lock on ``.glsynth.workers.lock``.
  A new driver first checks that no worker of an earlier, killed run still holds it, so a resume
  never overlaps that run's last writes.

The kernel drops a flock when its holder exits, however it exits, so no stale lock is left.
"""

import fcntl
import os
from pathlib import Path
from types import TracebackType

from glsynth.core.errors import UserError

DRIVER_LOCK = ".glsynth.lock"
WORKERS_LOCK = ".glsynth.workers.lock"


class RunLock:
    """``with RunLock(folder): ...`` holds the driver's lock; ``RunLock(folder, worker=True)``
    a worker's shared one."""

    def __init__(self, folder: str | Path, *, worker: bool = False) -> None:
        self.folder = Path(folder)
        self.worker = worker
        self._fd: int | None = None

    def _open(self, name: str) -> int:
        if self.folder.exists() and not self.folder.is_dir():
            raise UserError(f"--out {str(self.folder)!r} is a file; give a folder")
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            return os.open(self.folder / name, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as err:
            raise UserError(f"--out {str(self.folder)!r}: cannot create the folder or its lock "
                            f"file ({err.strerror}). Choose a writable --out location.") from err

    def acquire(self) -> "RunLock":
        if self.worker:
            fd = self._open(WORKERS_LOCK)
            fcntl.flock(fd, fcntl.LOCK_SH)  # only a driver's brief check can hold it exclusively
            self._fd = fd
            return self
        fd = self._open(DRIVER_LOCK)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "unknown"
            os.close(fd)
            raise UserError(f"--out {str(self.folder)!r} is in use by another glsynth run "
                            f"(pid {holder}); wait for it to end, or choose another "
                            "folder") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        self._fd = fd
        self._check_no_workers()
        return self

    def _check_no_workers(self) -> None:
        fd = self._open(WORKERS_LOCK)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            self.release()
            raise UserError(f"--out {str(self.folder)!r}: worker processes of an earlier run "
                            "are still writing there; try again once they have ended") from None
        finally:
            os.close(fd)

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)  # closing the descriptor drops the flock
            self._fd = None

    def __enter__(self) -> "RunLock":
        return self.acquire()

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        self.release()
