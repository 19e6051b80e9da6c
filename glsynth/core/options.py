"""Command-line options derived from a settings dataclass, so that each setting is written once.

Each field becomes ``--field-name``, with the docstring under the field as its help and the
field's default as the option's default. ``Literal[...]`` types give choices, ``bool`` fields a
switch (``--no-x`` when the default is True), and ``field(metadata=...)`` can add ``parse`` (a
function from the option's text; a ValueError becomes argparse's one-line usage error),
``metavar``, ``repeat`` (the option may be given several times; the field gets a tuple),
``flag`` (another option name), ``show`` (the default as the help shows it) and ``help``
(instead of the docstring).

The command line's other options use the same pieces: ``field_choices`` (a config field's
``Literal`` values), ``parse_size`` ('WxH') and ``argparse_type``.
"""

import argparse
import ast
import dataclasses
import inspect
import textwrap
import types
import typing
from functools import cache
from typing import Any, Literal

from glsynth.core.errors import UserError


@cache
def field_docs(cls: type) -> dict[str, str]:
    """The docstring written under each field of a dataclass, by field name."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(cls)))
    body = tree.body[0].body  # type: ignore[attr-defined]
    docs = {}
    for node, after in zip(body, body[1:]):
        if (isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name)
                and isinstance(after, ast.Expr) and isinstance(after.value, ast.Constant)
                and isinstance(after.value.value, str)):
            docs[node.target.id] = " ".join(after.value.value.split())
    return docs


def argparse_type(parse: typing.Callable[[str], Any], flag: str) -> typing.Callable[[str], Any]:
    """``parse`` as an argparse type: its ValueError (UserError too) becomes argparse's one-line
    usage error with the message kept."""
    def convert(text: str) -> Any:
        try:
            return parse(text)
        except ValueError as err:
            raise argparse.ArgumentTypeError(str(err)) from None
    convert.__name__ = flag  # argparse names the converter in its message
    return convert


MAX_SIDE_PX = 16384
"""The largest image side any glsynth option takes (GL's own limit on the GPUs we know)."""


def parse_size(text: str, minimum: int) -> tuple[int, int]:
    """'WxH' (e.g. '480x270') -> (W, H) in pixels, each side at least ``minimum`` and at
    most MAX_SIDE_PX."""
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise UserError(f"{text!r}: write WIDTHxHEIGHT, e.g. 480x270") from None
    if min(width, height) < minimum:
        raise UserError(f"{text!r}: each side must be at least {minimum} px")
    if max(width, height) > MAX_SIDE_PX:
        raise UserError(f"{text!r}: each side must be at most {MAX_SIDE_PX} px")
    return width, height


def _base_type(hint: Any) -> Any:
    """The type without None (``X | None`` -> X); the option's default is then None."""
    if isinstance(hint, types.UnionType) or typing.get_origin(hint) is typing.Union:
        return next(a for a in typing.get_args(hint) if a is not type(None))
    return hint


def field_choices(cls: type, name: str) -> tuple[Any, ...]:
    """The values field ``name`` of dataclass ``cls`` allows, from its ``Literal`` type."""
    hint = _base_type(typing.get_type_hints(cls)[name])
    if typing.get_origin(hint) is not Literal:
        raise TypeError(f"{cls.__name__}.{name}: {hint} is not a Literal")
    return typing.get_args(hint)


def add_options(parser: argparse.ArgumentParser, cls: type, *, skip: tuple[str, ...] = ()
                ) -> None:
    """Add one option per field of dataclass ``cls`` (fields without default are required)."""
    hints = typing.get_type_hints(cls)
    docs = field_docs(cls)
    for f in dataclasses.fields(cls):
        if f.name in skip:
            continue
        meta = f.metadata
        flag = meta.get("flag", "--" + f.name.replace("_", "-"))
        hint = _base_type(hints[f.name])
        has_default = f.default is not dataclasses.MISSING or \
            f.default_factory is not dataclasses.MISSING
        default = f.default if f.default is not dataclasses.MISSING else (
            f.default_factory() if f.default_factory is not dataclasses.MISSING else None)
        help_text = meta.get("help", docs.get(f.name, ""))
        kwargs: dict[str, Any] = {"dest": f.name, "help": help_text}
        if hint is bool:
            if default:
                kwargs["help"] = f"turn off: {help_text}"
                parser.add_argument("--no-" + f.name.replace("_", "-"), action="store_false",
                                    **kwargs)
            else:
                parser.add_argument(flag, action="store_true", **kwargs)
            continue
        if typing.get_origin(hint) is Literal:
            kwargs["choices"] = typing.get_args(hint)
        elif "parse" in meta:
            kwargs["type"] = argparse_type(meta["parse"], flag)
        elif hint in (int, float, str):
            kwargs["type"] = hint
        else:
            raise TypeError(f"{cls.__name__}.{f.name}: give metadata 'parse' for type {hint}")
        if "metavar" in meta:
            kwargs["metavar"] = meta["metavar"]
        if meta.get("repeat"):
            kwargs.update(action="append", default=[])
        elif has_default:
            kwargs["default"] = default
            if default is not None and help_text:
                kwargs["help"] = f"{help_text} (default: {meta.get('show', default)})"
        else:
            kwargs["required"] = True
        parser.add_argument(flag, **kwargs)


def from_options(cls: type, args: argparse.Namespace, **extra: Any) -> Any:
    """An instance of ``cls`` from the parsed options (repeated options become tuples)."""
    values = {}
    for f in dataclasses.fields(cls):
        if f.name in extra or not hasattr(args, f.name):
            continue
        value = getattr(args, f.name)
        values[f.name] = tuple(value) if f.metadata.get("repeat") else value
    return cls(**values, **extra)
