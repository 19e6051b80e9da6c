"""Validation of config dataclasses: every error names the field, value and range.

A field's bounds are written once, as its metadata (``bounded(default, rule)``), and one
validator, ``validate``, checks every field by its rule, and every Literal-typed field by its
choices. Rules that read other fields or sections stay in the dataclass's ``__post_init__``.
"""

import dataclasses
import functools
import math
import typing
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from glsynth.core.errors import UserError, shown


def fail(section: str, name: str, value: Any, expected: str) -> typing.NoReturn:
    raise UserError(
        f"{section}.{name} = {shown(value)}: must be {expected}. "
        f"Fix it in the [{section}] table of your config file, or use a preset."
    )


def is_nan(value: Any) -> bool:
    """Whether a parsed number is NaN. Only floats can be: an integer (however many digits,
    where math.isnan would overflow) compares with any bound exactly."""
    return isinstance(value, float) and math.isnan(value)


def check_number(section: str, name: str, value: Any, lo: float, hi: float,
                 *, lo_open: bool = False, integer: bool = False) -> None:
    kind = int if integer else (int, float)
    if isinstance(value, bool) or not isinstance(value, kind) or is_nan(value):
        fail(section, name, value, "an integer" if integer else "a number")
    above = value > lo if lo_open else value >= lo
    if not (above and value <= hi):
        fail(section, name, value, f"in {'(' if lo_open else '['}{lo}, {hi}]")


def check_interval(section: str, name: str, value: Any, lo: float, hi: float) -> None:
    ok = (isinstance(value, tuple) and len(value) == 2
          and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value))
    if not ok or is_nan(value[0]) or is_nan(value[1]) or not (
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
    if not ok or not all(lo <= v <= hi for v in value):  # NaN fails every comparison
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


Bound = float | Callable[[Any], float]
"""A number, or a function of the section that reads the bound from another of its fields."""
RULE = "glsynth.rule"
"""The key of a field's rule in its metadata."""


def _at(bound: Bound, section: Any) -> float:
    return bound(section) if callable(bound) else bound


@dataclass(frozen=True)
class Number:
    """A number (an integer if ``integer``) in [lo, hi], or (lo, hi] if ``lo_open``."""

    lo: Bound
    hi: Bound
    lo_open: bool = False
    integer: bool = False

    def check(self, section: str, name: str, value: Any, owner: Any) -> None:
        check_number(section, name, value, _at(self.lo, owner), _at(self.hi, owner),
                     lo_open=self.lo_open, integer=self.integer)


@dataclass(frozen=True)
class Interval:
    """An interval [a, b] with lo <= a <= b <= hi."""

    lo: Bound
    hi: Bound

    def check(self, section: str, name: str, value: Any, owner: Any) -> None:
        check_interval(section, name, value, _at(self.lo, owner), _at(self.hi, owner))


@dataclass(frozen=True)
class PositiveInterval:
    """An interval [a, b] of ``unit`` with 0 < a <= b <= hi."""

    hi: float
    unit: str

    def check(self, section: str, name: str, value: Any, owner: Any) -> None:
        check_positive_interval(section, name, value, self.hi, self.unit)


@dataclass(frozen=True)
class Vector:
    """``size`` numbers, each in [lo, hi]."""

    size: int
    lo: float
    hi: float

    def check(self, section: str, name: str, value: Any, owner: Any) -> None:
        check_vector(section, name, value, self.size, self.lo, self.hi)


@dataclass(frozen=True)
class Flag:
    """true or false (a TOML boolean, not a number)."""

    def check(self, section: str, name: str, value: Any, owner: Any) -> None:
        if not isinstance(value, bool):
            fail(section, name, value, "true or false")


@dataclass(frozen=True)
class Numbers:
    """A non-empty tuple of numbers, each in [lo, hi]; ``expected`` says what it holds."""

    lo: float
    hi: float
    expected: str

    def check(self, section: str, name: str, value: Any, owner: Any) -> None:
        if not isinstance(value, tuple) or not value:
            fail(section, name, value, self.expected)
        for item in value:
            check_number(section, name, item, self.lo, self.hi)


Rule = Number | Interval | PositiveInterval | Vector | Numbers


def bounded(default: Any, rule: Rule) -> Any:
    """A dataclass field with ``default`` and the rule its values must keep."""
    return dataclasses.field(default=default, metadata={RULE: rule})


def _reads_fields(rule: Rule) -> bool:
    return any(callable(getattr(rule, bound, None)) for bound in ("lo", "hi"))


def validate(owner: Any, section: str) -> None:
    """Each field of the dataclass ``owner`` (the config file's ``[section]``) by its rule, in
    field order, and each Literal-typed field by its choices. Rules whose bounds read other
    fields run last, once those fields are known to be valid."""
    fields = dataclasses.fields(owner)
    for f in fields:
        if f.name in _literal_fields(type(owner)):
            check_literal(section, type(owner), f.name, getattr(owner, f.name))
    rules = [(f.name, f.metadata[RULE]) for f in fields if RULE in f.metadata]
    for name, rule in sorted(rules, key=lambda item: _reads_fields(item[1])):
        rule.check(section, name, getattr(owner, name), owner)


@functools.cache
def _literal_fields(cls: type) -> frozenset[str]:
    return frozenset(name for name, hint in typing.get_type_hints(cls).items()
                     if typing.get_origin(hint) is typing.Literal)
