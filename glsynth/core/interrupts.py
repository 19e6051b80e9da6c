"""Stopping work on request: the exception work raises when its ``interrupt()`` says stop,
and a Ctrl-C held back while code that would swallow it runs.

Libraries glsynth imports catch every exception around their own optional imports: trimesh
wraps each in ``except BaseException`` (to raise it when the feature is used), pyglet and
networkx have bare ``except:``. A KeyboardInterrupt raised inside one of those is lost: the
command goes on as if Ctrl-C had not been pressed, with a half-imported module left behind
(docs/design.md, "A Ctrl-C is never lost", tells what it did to ``glsynth view``). While
held, SIGINT is noted instead of raised, and raised as KeyboardInterrupt where the hold ends,
a point where it propagates. A process started through the command line (glsynth.__main__)
holds it through the first import of those packages, wherever a command makes it
(``hold_while_importing``)."""

import contextlib
import importlib.abc
import importlib.machinery
import signal
import sys
import threading
import types
from collections.abc import Iterator, Sequence


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


SWALLOWING = frozenset({"trimesh", "pyglet", "networkx"})
"""The packages whose imports catch every exception round their optional imports."""


class _HeldLoader(importlib.abc.Loader):
    """A package's own loader, run with Ctrl-C held; everything else (its resources, its
    source) is the loader's."""

    def __init__(self, loader: importlib.abc.Loader) -> None:
        self._loader = loader

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> types.ModuleType | None:
        return self._loader.create_module(spec)

    def exec_module(self, module: types.ModuleType) -> None:
        with held_interrupt():  # the package's own imports run inside: all held, once
            self._loader.exec_module(module)

    def __getattr__(self, name: str) -> object:
        if name == "_loader":  # not set yet (a copy being made): no loader to ask
            raise AttributeError(name)
        return getattr(self._loader, name)


class _HoldingFinder(importlib.abc.MetaPathFinder):
    """Finds SWALLOWING packages as the finders after it do, with a _HeldLoader."""

    def find_spec(self, name: str, path: Sequence[str] | None,
                  target: types.ModuleType | None = None
                  ) -> importlib.machinery.ModuleSpec | None:
        if name not in SWALLOWING:
            return None
        for finder in sys.meta_path:
            if finder is self or not hasattr(finder, "find_spec"):
                continue
            spec = finder.find_spec(name, path, target)
            if spec is not None:
                if hasattr(spec.loader, "exec_module"):  # not a namespace package
                    spec.loader = _HeldLoader(spec.loader)
                return spec
        return None


def hold_while_importing() -> None:
    """From now on, SWALLOWING packages are imported with Ctrl-C held (in the main thread,
    where SIGINT is Python's default), whichever module imports them first and when: the
    command line imports what a command needs as it runs (its own start stays light), so a
    hold round its own import alone would miss them. Once the noted Ctrl-C is raised the
    import has failed and the process is meant to end (every command exits with 130): the
    package's submodules stay loaded, and importing it again would give a package without
    them. Worker processes a run spawns start without it; a package's own lazy import inside
    its own ``except BaseException`` later on (trimesh's viewer importing pyglet, which
    glsynth never uses) is not held either."""
    if not any(isinstance(f, _HoldingFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, _HoldingFinder())
