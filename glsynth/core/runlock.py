"""One writer per output folder, through flock on lock files inside it.

- The driver of a run holds an exclusive lock on ``<folder>/.glsynth.lock`` for the whole run
  and writes its pid there; a second driver gets an error naming the processes that hold it.
- Worker processes (a local pool, Ray actors) hold a shared lock on ``.glsynth.workers.lock``,
  and so does every child process a run starts (Blender, through glsynth.core.children: the
  child inherits a descriptor of its own, shared-locked, so the lock lives exactly as long as
  the child). A new driver first checks that no worker or child of an earlier, killed run
  still holds it, so a resume never overlaps that run's last writes.
- Which processes hold a lock is read when a lock is refused, from ``/proc/*/fd`` (Linux; the
  same user's processes): every process with the lock file open, whoever took the lock. Nothing
  is recorded for it, so nothing can go stale; elsewhere the message names the recorded pid.
- A forked child (a data loader's worker) closes its copies of the held locks' descriptors at
  once (never LOCK_UN, which would drop the parent's lock too): only the processes that write
  keep a run's folder, so a resume right after a kill is not refused by readers.

The kernel drops a flock when its holder exits, however it exits, so no stale lock is left.
"""

import fcntl
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import TracebackType

from glsynth.core.errors import UserError, named

DRIVER_LOCK = ".glsynth.lock"
WORKERS_LOCK = ".glsynth.workers.lock"

_HELD: list["RunLock"] = []
"""The locks this process holds, latest last."""


class RunLock:
    """``with RunLock(folder): ...`` holds the driver's lock; ``RunLock(folder, worker=True)``
    a worker's shared one."""

    def __init__(self, folder: str | Path, *, worker: bool = False) -> None:
        self.folder = Path(folder)
        self.worker = worker
        self._fd: int | None = None
        self._created = False
        """Whether this lock made the folder: a run refused inside it leaves none behind."""

    def _open(self, name: str) -> int:
        check_out(self.folder)
        try:
            if not self.worker and not self.folder.exists():
                self.folder.mkdir(parents=True)
                self._created = True
            self.folder.mkdir(parents=True, exist_ok=True)
            return os.open(self.folder / name, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as err:
            raise UserError(f"--out {named(self.folder)}: cannot create the folder or its lock "
                            f"file ({err.strerror}). Choose a writable --out location.") from err

    def acquire(self) -> "RunLock":
        if not self.worker:
            refuse_held(self.folder.parent)
        if self.worker:
            fd = self._open(WORKERS_LOCK)
            fcntl.flock(fd, fcntl.LOCK_SH)  # only a driver's brief check can hold it exclusively
            self._hold(fd)
            return self
        fd = self._open(DRIVER_LOCK)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            recorded = os.pread(fd, 32, 0).decode(errors="replace").strip() or "unknown"
            os.close(fd)
            raise UserError(self._in_use(recorded)) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        self._hold(fd)
        self._check_no_workers()
        return self

    def _hold(self, fd: int) -> None:
        self._fd = fd
        _HELD.append(self)

    def _in_use(self, recorded: str) -> str:
        holders = lock_holders(self.folder / DRIVER_LOCK)
        if not holders or recorded in {str(pid) for pid, _ in holders}:
            who = f"pid {recorded}"
        else:  # the driver is gone; what it started still has the folder
            who = f"pid {recorded}, ended; its processes live on: {describe(holders)}"
        return (f"--out {named(self.folder)} is in use by another glsynth run ({who}); wait "
                "for it to end, or choose another folder")

    def _check_no_workers(self) -> None:
        fd = self._open(WORKERS_LOCK)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            self.release()
            holders = lock_holders(self.folder / WORKERS_LOCK)
            who = f" ({describe(holders)})" if holders else ""
            raise UserError(f"--out {named(self.folder)}: worker processes of an earlier run "
                            f"are still writing there{who}; try again once they have "
                            "ended") from None
        finally:
            os.close(fd)

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)  # closing the descriptor drops the flock
            self._fd = None
            _HELD.remove(self)

    def __enter__(self) -> "RunLock":
        return self.acquire()

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        self.release()
        if kind is not None and self._created:
            self._remove_if_unused()

    def _remove_if_unused(self) -> None:
        """Remove the folder this lock made when a run failed before writing anything but
        the lock files; another process that took the lock meanwhile keeps it."""
        try:
            fd = os.open(self.folder / DRIVER_LOCK, os.O_RDWR)
        except OSError:
            return
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # refused: another run holds it
            if {p.name for p in self.folder.iterdir()} <= {DRIVER_LOCK, WORKERS_LOCK}:
                for name in (DRIVER_LOCK, WORKERS_LOCK):
                    (self.folder / name).unlink(missing_ok=True)
                self.folder.rmdir()
        except OSError:  # another run holds it, or its files arrived: the folder is theirs
            pass
        finally:
            os.close(fd)


def _close_in_forked_child() -> None:
    """A forked child shares the parent's lock (one open file description); closing its own
    descriptor leaves the parent's lock as it is, whereas LOCK_UN would drop it."""
    for lock in _HELD:
        if lock._fd is not None:
            os.close(lock._fd)
            lock._fd = None
    _HELD.clear()


os.register_at_fork(after_in_child=_close_in_forked_child)


@contextmanager
def child_lock() -> Iterator[tuple[int, ...]]:
    """Descriptors for a child process to inherit (``pass_fds``): a new shared lock on the
    worker lock of the run folder this process holds, none if it holds none. The child's copy
    keeps the lock while the child lives; this process's copy is closed on leaving."""
    if not _HELD:
        yield ()
        return
    fd = _HELD[-1]._open(WORKERS_LOCK)
    try:
        fcntl.flock(fd, fcntl.LOCK_SH)
        yield (fd,)
    finally:
        os.close(fd)


def lock_holders(path: Path) -> list[tuple[int, str]]:
    """Other processes (pid, command line) that have ``path`` open, read from /proc (Linux,
    processes of this user); empty where /proc cannot tell."""
    try:
        target = os.stat(path)
        entries = [e for e in os.scandir("/proc") if e.name.isdigit()]
    except OSError:
        return []
    found = []
    for entry in entries:
        pid = int(entry.name)
        if pid != os.getpid() and _has_open(pid, (target.st_dev, target.st_ino)):
            found.append((pid, _command(pid)))
    return found


def _has_open(pid: int, file_id: tuple[int, int]) -> bool:
    try:
        descriptors = list(os.scandir(f"/proc/{pid}/fd"))
    except OSError:  # gone, or not ours to read
        return False
    for fd in descriptors:
        try:
            info = os.stat(fd.path)
        except OSError:  # closed meanwhile
            continue
        if (info.st_dev, info.st_ino) == file_id:
            return True
    return False


def _command(pid: int) -> str:
    try:
        raw = Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return "?"
    return " ".join(raw.decode(errors="replace").replace("\0", " ").split()) or "?"


def describe(holders: list[tuple[int, str]], shown: int = 2, width: int = 40) -> str:
    """'pid 12 (blender -b ...), pid 34 (...)': a bounded part of one message line."""
    parts = [f"pid {pid} ({command[:width] + '...' if len(command) > width else command})"
             for pid, command in holders[:shown]]
    more = f" and {len(holders) - shown} more" if len(holders) > shown else ""
    return ", ".join(parts) + more


def resolved(path: Path) -> Path:
    """``path`` made absolute with its links followed; a link loop is a UserError (Python
    raises RuntimeError or OSError for it, depending on the version)."""
    try:
        return Path(path).resolve()
    except (RuntimeError, OSError):
        raise UserError(f"--out {named(path)} is a loop of symbolic links; give a folder") \
            from None


def held_by_another(path: Path) -> Path | None:
    """The nearest folder at or above ``path`` whose driver lock another process holds (a
    run writing there), or None. A lock this process holds does not count."""
    mine = {resolved(lock.folder) for lock in _HELD}
    for folder in (resolved(path), *resolved(path).parents):
        lock = folder / DRIVER_LOCK
        if folder in mine or not lock.is_file():
            continue
        try:
            fd = os.open(lock, os.O_RDONLY | os.O_NONBLOCK)
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return folder
        finally:
            os.close(fd)  # and with it the shared lock just taken
    return None


def check_out(folder: str | Path) -> None:
    """Refuse, writing nothing, an --out that is a file or lies in the kernel's file systems:
    what RunLock refuses before it makes anything, for a command whose own checks come before
    the lock and take time (a flight builds its environment to check its plan), so that a
    wrong --out is told at once. (A folder another run holds is refused for every command by
    the command line before the command runs: refuse_held.)"""
    folder = Path(folder)
    where = resolved(folder)  # a symbolic-link loop is one line, before any other test
    if folder.exists() and not folder.is_dir():
        raise UserError(f"--out {named(folder)} is a file; give a folder")
    if where.parts[1:2] in (("proc",), ("sys",), ("dev",)):
        raise UserError(f"--out {named(folder)} is in the kernel's /proc, /sys or /dev; give "
                        "a folder on a disk")


def refuse_held(path: Path) -> None:
    """Refuse, before anything is written, an output at or inside a folder another glsynth run
    holds (every command's --out passes here, with or without a run lock of its own)."""
    held = held_by_another(path)
    if held is None:
        return
    if held == resolved(path):  # the folder itself: the run lock's own words, with the pid
        recorded = (held / DRIVER_LOCK).read_text(errors="replace").strip()[:32] or "unknown"
        raise UserError(RunLock(held)._in_use(recorded))
    raise UserError(f"--out {named(path)} is inside {named(held)}, which another glsynth "
                    "run is writing; wait for it to end, or choose a folder outside it")
