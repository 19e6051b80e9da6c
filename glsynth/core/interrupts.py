"""Stopping work on request: the exception work raises when its ``interrupt()`` says stop,
and a Ctrl-C held back while code that would swallow it runs.

Libraries glsynth imports catch every exception around their own optional imports: trimesh
wraps each in ``except BaseException`` (to raise it when the feature is used), pyglet and
networkx have bare ``except:``. A KeyboardInterrupt raised inside one of those is lost: the
command goes on as if Ctrl-C had not been pressed, with a half-imported module left behind
(docs/design.md, "A Ctrl-C is never lost", tells what it did to ``glsynth view``). While
held, SIGINT is noted instead of raised, and raised as KeyboardInterrupt where the hold ends,
a point where it propagates."""

import contextlib
import signal
import threading
from collections.abc import Iterator


class RenderInterrupted(Exception):
    """Work that takes an ``interrupt()`` (a render, a load, an opening) stopped because it
    said so."""


@contextlib.contextmanager
def held_interrupt() -> Iterator[list[int]]:
    """Inside the block SIGINT is noted, not raised; leaving it with one noted raises
    KeyboardInterrupt. Yields the list of noted signals, for a server that takes the signals
    over inside the block to act on (glsynth.view.server) and clear. A second Ctrl-C raises at
    once: the user insists. Nothing is held outside the main thread (no handler can be set
    there) or where SIGINT is not Python's default (ignored, as in a background job, or
    handled by the caller): that choice stands."""
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler):
        yield []
        return
    noted: list[int] = []

    def note(signum: int, _frame: object) -> None:
        noted.append(signum)
        if len(noted) > 1:
            raise KeyboardInterrupt

    previous = signal.signal(signal.SIGINT, note)
    try:
        yield noted
    finally:
        signal.signal(signal.SIGINT, previous)
    if noted:
        raise KeyboardInterrupt
