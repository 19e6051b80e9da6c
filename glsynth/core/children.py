"""Processes a run starts (pool workers, Blender, data-loader workers) end with the process
that started them, and those that write hold the run folder's worker lock while they live
(glsynth/core/runlock.py): a killed driver leaves nothing running, and a new run cannot start
while anything of the old one still writes.

Death with the parent is Linux's PR_SET_PDEATHSIG: the kernel sends SIGKILL when the *thread*
that started the child ends, so children are started from a thread that lives as long as the
run (the main thread, everywhere in glsynth). The setting survives exec but not fork: a child
that starts processes of its own must arm them too (Blender starts none). Elsewhere than Linux
the worker lock alone guards the folder.
"""

import ctypes
import functools
import os
import signal
import subprocess
from collections.abc import Callable, Sequence

from glsynth.core.runlock import child_lock

_PR_SET_PDEATHSIG = 1


def _load_prctl() -> Callable[[int, int], int] | None:
    try:
        return ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):  # not Linux
        return None


# Looked up once here: a child forked from a process with threads must not dlopen before exec.
_PRCTL = _load_prctl()


def die_with_parent(parent: int, *_: object) -> None:
    """Arm SIGKILL for this process when its parent ``parent`` (a pid) ends; if the parent
    ended before that, exit now, since the signal only follows the current parent. The extra
    arguments let it serve as a data loader's ``worker_init_fn`` (bound with
    functools.partial)."""
    if _PRCTL is not None:
        _PRCTL(_PR_SET_PDEATHSIG, signal.SIGKILL)
    if os.getppid() != parent:
        os._exit(1)


def run_child(argv: Sequence[str], timeout_s: float) -> subprocess.CompletedProcess:
    """``argv`` to its end, its output captured as text, as a child that dies with this process
    and holds the worker lock of the run folder this process holds (if any). A child still
    running after ``timeout_s`` is killed and TimeoutExpired raised."""
    with child_lock() as fds:
        return subprocess.run(list(argv), capture_output=True, text=True, timeout=timeout_s,
                              pass_fds=fds,
                              preexec_fn=functools.partial(die_with_parent, os.getpid()))
