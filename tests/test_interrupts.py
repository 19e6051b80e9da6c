"""Ctrl-C held while code that would swallow it runs (glsynth.core.interrupts): noted, then
raised where the hold ends; a second one raised at once; a SIGINT the caller ignores or
handles left as it is; and held through a swallowing package's import wherever it is made."""

import signal
import sys
import textwrap

import pytest

from glsynth.core import interrupts
from glsynth.core.interrupts import held_interrupt, hold_while_importing


@pytest.fixture(autouse=True)
def python_ctrl_c():
    """SIGINT at Python's default, as in a terminal (a test run started in the background
    ignores it)."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


def _swallowing_import() -> None:
    """What trimesh does around its optional imports: every exception kept for later."""
    try:
        signal.raise_signal(signal.SIGINT)  # Ctrl-C while the import runs
    except BaseException:  # noqa: BLE001 - the library's own pattern, under test
        pass


def test_a_ctrl_c_that_code_inside_would_swallow_is_raised_where_the_hold_ends():
    _swallowing_import()  # unheld, the Ctrl-C is lost
    reached = False
    with pytest.raises(KeyboardInterrupt):
        with held_interrupt() as noted:
            _swallowing_import()
            assert noted == [signal.SIGINT]
            reached = True  # the block runs on to its end
    assert reached
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_second_ctrl_c_is_raised_at_once():
    with pytest.raises(KeyboardInterrupt), held_interrupt():
        signal.raise_signal(signal.SIGINT)
        with pytest.raises(KeyboardInterrupt):
            signal.raise_signal(signal.SIGINT)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


@pytest.mark.parametrize("handler", [signal.SIG_IGN, lambda signum, frame: None])
def test_a_sigint_the_caller_ignores_or_handles_is_left_alone(handler):
    previous = signal.signal(signal.SIGINT, handler)
    try:
        with held_interrupt() as noted:
            assert signal.getsignal(signal.SIGINT) is handler
            signal.raise_signal(signal.SIGINT)
        assert noted == []
    finally:
        signal.signal(signal.SIGINT, previous)


def test_a_swallowing_packages_import_is_held_wherever_it_is_made(tmp_path, monkeypatch):
    """A package that swallows a Ctrl-C in its own import, as trimesh does, imported after
    hold_while_importing: the import runs to its end and the Ctrl-C is raised there; the
    same package imported without the hold loses it."""
    for name in ("swallower", "swallower_unheld"):
        package = tmp_path / name
        package.mkdir()
        (package / "__init__.py").write_text(textwrap.dedent("""
            import signal
            try:
                signal.raise_signal(signal.SIGINT)
            except BaseException:  # what trimesh does round an optional import
                pass
            from . import part  # the package's own imports run under the same hold
            from pathlib import Path
            (Path(__file__).parent / "ran_to_its_end").touch()
            """))
        (package / "part.py").write_text("")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(interrupts, "SWALLOWING", frozenset({"swallower"}))
    monkeypatch.setattr(sys, "meta_path", list(sys.meta_path))
    hold_while_importing()
    hold_while_importing()  # installed once however often it is asked
    assert sum(isinstance(f, interrupts._HoldingFinder) for f in sys.meta_path) == 1
    try:
        import swallower_unheld  # noqa: F401 - not named in SWALLOWING: the Ctrl-C is lost
        with pytest.raises(KeyboardInterrupt):
            import swallower  # noqa: F401
    finally:
        for name in ("swallower", "swallower.part", "swallower_unheld", "swallower_unheld.part"):
            sys.modules.pop(name, None)
    assert (tmp_path / "swallower" / "ran_to_its_end").exists()
    assert (tmp_path / "swallower_unheld" / "ran_to_its_end").exists()
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
