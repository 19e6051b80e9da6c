"""Validation helpers for config dataclasses: every error names the field, value and range."""

import functools
import math
import typing
from typing import Any

from glsynth.core.errors import UserError, shown


def fail(section: str, name: str, value: Any, expected: str) -> typing.NoReturn:
    raise UserError(
        f"{section}.{name} = {shown(value)}: must be {expected}. "
        f"Fix it in the [{section}] table of your config file, or use a preset."
    )


def check_number(section: str, name: str, value: Any, lo: float, hi: float,
                 *, lo_open: bool = False, integer: bool = False) -> None:
    kind = int if integer else (int, float)
    if isinstance(value, bool) or not isinstance(value, kind) or math.isnan(value):
        fail(section, name, value, "an integer" if integer else "a number")
    above = value > lo if lo_open else value >= lo
    if not (above and value <= hi):
        fail(section, name, value, f"in {'(' if lo_open else '['}{lo}, {hi}]")


def check_interval(section: str, name: str, value: Any, lo: float, hi: float) -> None:
    ok = (isinstance(value, tuple) and len(value) == 2
          and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value))
    if not ok or math.isnan(value[0]) or math.isnan(value[1]) or not (
            lo <= value[0] <= value[1] <= hi):
        fail(section, name, value, f"an interval [a, b] with {lo} <= a <= b <= {hi}")


def check_positive_interval(section: str, name: str, value: Any, hi: float, unit: str) -> None:
    """An interval [a, b] of ``unit`` with 0 < a <= b <= hi, one message for every way out."""
    try:
        check_interval(section, name, value, 0.0, hi)
        positive = value[0] > 0
    except UserError:
        positive = False
    if not positive:
        fail(section, name, value, f"an interval [a, b] of {unit} with 0 < a <= b <= {hi:g}")


def check_vector(section: str, name: str, value: Any, size: int, lo: float, hi: float) -> None:
    ok = (isinstance(value, tuple) and len(value) == size
          and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value))
    if not ok or not all(lo <= v <= hi for v in value):
        fail(section, name, value, f"{size} numbers in [{lo}, {hi}]")


@functools.cache
def literal_choices(cls: type, name: str) -> tuple[Any, ...]:
    """The allowed values of a ``Literal[...]``-typed field of a config dataclass: the one place
    each set of choices is written."""
    hint = typing.get_type_hints(cls)[name]
    if typing.get_origin(hint) is not typing.Literal:
        raise TypeError(f"{cls.__name__}.{name} is not Literal-typed")
    return typing.get_args(hint)


def check_literal(section: str, cls: type, name: str, value: Any) -> None:
    """``value`` is one of the choices of field ``name``'s Literal type, of the same type
    (so True is not 1, nor 2.0 the integer 2)."""
    choices = literal_choices(cls, name)
    if not any(type(value) is type(c) and value == c for c in choices):
        fail(section, name, value, "one of " + ", ".join(
            f'"{c}"' if isinstance(c, str) else str(c) for c in choices))
