"""Command-line options derived from settings dataclasses (glsynth.core.options)."""

import argparse
from dataclasses import dataclass, field
from typing import Literal

import pytest

from glsynth.core.errors import UserError
from glsynth.core.options import (
    add_options,
    field_choices,
    field_docs,
    from_options,
    parse_size,
)


def _pair(text: str) -> tuple[int, int]:
    a, b = text.split(",")
    return int(a), int(b)


@dataclass(frozen=True)
class Example:
    name: str
    """Required: no default."""
    mode: Literal["a", "b"] = "a"
    """A choice."""
    size: tuple[int, int] = field(default=(2, 3), metadata={"parse": _pair, "metavar": "A,B"})
    """Parsed from text."""
    folders: tuple[str, ...] = field(default=(), metadata={"parse": str, "repeat": True})
    """Repeatable."""
    fast: bool = True
    """On by default."""
    verbose: bool = False
    """Off by default."""
    limit: float | None = None
    """Optional number."""


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser()
    add_options(p, Example)
    return p


def test_docstrings_become_help_and_defaults_carry_over():
    assert field_docs(Example)["size"] == "Parsed from text."
    text = parser().format_help()
    assert "--no-fast" in text and "--verbose" in text and "A,B" in text
    assert "turn off: On by default." in text and "(default: a)" in text
    settings = from_options(Example, parser().parse_args(["--name", "x"]))
    assert settings == Example("x")


def test_every_kind_of_field_parses():
    args = parser().parse_args(["--name", "x", "--mode", "b", "--size", "4,5", "--folders",
                                "p", "--folders", "q", "--no-fast", "--verbose",
                                "--limit", "2.5"])
    assert from_options(Example, args) == Example("x", "b", (4, 5), ("p", "q"), False, True, 2.5)


@pytest.mark.parametrize("argv, message", [
    (["--name", "x", "--mode", "c"], "invalid choice"),
    (["--name", "x", "--size", "four"], "--size"),
    ([], "--name"),  # required: the field has no default
])
def test_bad_options_are_argparse_errors(argv, message, capsys):
    with pytest.raises(SystemExit):
        parser().parse_args(argv)
    assert message in capsys.readouterr().err


def test_the_train_command_is_built_from_train_settings():
    from glsynth.model.settings import TrainSettings

    from glsynth.cli import build_parser

    args = build_parser().parse_args(["train", "--task", "depth", "--data", "d", "--out", "r",
                                      "--image-size", "480x270", "--schedule", "1e-3:2"])
    settings = from_options(TrainSettings, args)
    assert settings.task == "depth" and settings.image_size == (480, 270)
    assert settings.schedule == ((1e-3, 2),) and settings.batch_size == 8
    assert settings.data.endswith("/d")  # resolved to an absolute folder


def test_train_settings_take_their_names_from_the_labels_and_check_every_choice():
    from glsynth.model.settings import CLASS_NAMES, N_OUTPUTS, TrainSettings

    from glsynth.core.errors import UserError
    from glsynth.core.labels import Component, Damage

    assert CLASS_NAMES["component"][Component.SLEEPER - 1] == "sleeper"
    assert CLASS_NAMES["damage"][Damage.REBAR - 1] == "rebar"
    assert N_OUTPUTS == {"component": 8, "damage": 3, "depth": 1}  # the paper's FCN58 heads
    for name, value in (("task", "segment"), ("precision", "fp16"), ("views", "aerial")):
        with pytest.raises(UserError, match=f"--{name} '{value}': choose one of"):
            TrainSettings(**{"task": "depth", "data": "d", name: value})


@pytest.mark.parametrize("text, minimum, size", [
    ("480x270", 16, (480, 270)),
    ("1920X1080", 96, (1920, 1080)),  # either case of x
    ("16x16", 16, (16, 16)),  # the minimum itself is allowed
])
def test_sizes_parse_from_wxh(text, minimum, size):
    assert parse_size(text, minimum) == size


@pytest.mark.parametrize("text, minimum, message", [
    ("480", 16, "write WIDTHxHEIGHT"),
    ("480x", 16, "write WIDTHxHEIGHT"),
    ("1x2x3", 1, "write WIDTHxHEIGHT"),
    ("wide x tall", 1, "write WIDTHxHEIGHT"),
    ("15x270", 16, "each side must be at least 16 px"),
    ("480x95", 96, "each side must be at least 96 px"),
    ("-5x10", 1, "at least 1 px"),
])
def test_bad_sizes_are_one_clear_line(text, minimum, message):
    with pytest.raises(UserError, match=message):
        parse_size(text, minimum)


@pytest.mark.parametrize("argv, message", [
    (["train", "--task", "depth", "--data", "d", "--out", "r", "--image-size", "192x95"],
     "argument --image-size: '192x95': each side must be at least 96 px"),
    (["bench", "quality", "--out", "q", "--size", "15x15"],
     "argument --size: '15x15': each side must be at least 16 px"),
    (["bench", "quality", "--out", "q", "--size", "big"], "'big': write WIDTHxHEIGHT"),
])
def test_the_commands_take_sizes_with_their_own_minimum(argv, message, capsys):
    from glsynth.cli import build_parser

    with pytest.raises(SystemExit):
        build_parser().parse_args(argv)
    assert message in capsys.readouterr().err


def test_choices_come_from_a_fields_literal_type():
    from glsynth.core.config import RenderConfig

    assert field_choices(Example, "mode") == ("a", "b")
    assert field_choices(RenderConfig, "renderer") == ("gl", "cycles")
    with pytest.raises(TypeError, match="not a Literal"):
        field_choices(Example, "name")
