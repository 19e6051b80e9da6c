"""The one error type for bad input, and how the command line tells it from a programming error.

A ``UserError`` is something the user can fix: a bad option, config value, file or folder, or a
machine without what glsynth needs. Its message is one line that names the field, the value and
the fix. It subclasses ValueError so that callers of the library can catch it as one.
"""

import os

MAX_MESSAGE = 300
"""The longest error line the command line prints (docs/design.md, "Errors")."""


class UserError(ValueError):
    """Bad input or environment: printed as one line by the command line, without traceback."""


def shown(value: object, limit: int = 60) -> str:
    """``repr(value)`` cut to about ``limit`` characters, so that a message quoting a value a
    file or an option supplied stays one short line whatever its size."""
    text = repr(value)
    if len(text) <= limit:
        return text
    return f"{text[:limit - 20]}... ({len(text):,} characters)"


def named(path: str | os.PathLike, limit: int = 120) -> str:
    """A path quoted for a message, its middle cut where it is longer than ``limit``: the
    start says where it lies and the end which file it is, so both are kept."""
    text = repr(os.fspath(path))
    if len(text) <= limit:
        return text
    keep = (limit - 3) // 2
    return f"{text[:keep]}...{text[-keep:]}"


def clipped(message: str, limit: int = MAX_MESSAGE) -> str:
    """A message of at most ``limit`` characters; a longer one loses its middle, so that the
    culprit at its start and the fix at its end both remain."""
    if len(message) <= limit:
        return message
    head = limit * 2 // 3
    return f"{message[:head]} ... {message[-(limit - head - 5):]}"
