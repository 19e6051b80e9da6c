"""Ctrl-C held while code that would swallow it runs (glsynth.core.interrupts): noted, then
raised where the hold ends; a second one raised at once; a SIGINT the caller ignores or
handles left as it is."""

import signal

import pytest

from glsynth.core.interrupts import held_interrupt


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
