"""Validation helpers for config dataclasses: every error names the field, value and range."""

import math
import typing
from typing import Any

from glsynth.core.errors import UserError


def fail(section: str, name: str, value: Any, expected: str) -> typing.NoReturn:
    raise UserError(
        f"{section}.{name} = {value!r}: must be {expected}. "
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


def check_vector(section: str, name: str, value: Any, size: int, lo: float, hi: float) -> None:
    ok = (isinstance(value, tuple) and len(value) == size
          and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value))
    if not ok or not all(lo <= v <= hi for v in value):
        fail(section, name, value, f"{size} numbers in [{lo}, {hi}]")


def check_choice(section: str, name: str, value: Any, choices: tuple[str, ...]) -> None:
    if value not in choices:
        fail(section, name, value, "one of " + ", ".join(f'"{c}"' for c in choices))
