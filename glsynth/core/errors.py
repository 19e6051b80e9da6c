"""The one error type for bad input, and how the command line tells it from a programming error.

A ``UserError`` is something the user can fix: a bad option, config value, file or folder, or a
machine without what glsynth needs. Its message is one line that names the field, the value and
the fix. It subclasses ValueError so that callers of the library can catch it as one.
"""


class UserError(ValueError):
    """Bad input or environment: printed as one line by the command line, without traceback."""


def shown(value: object, limit: int = 60) -> str:
    """``repr(value)`` cut to about ``limit`` characters, so that a message quoting a value a
    file or an option supplied stays one short line whatever its size."""
    text = repr(value)
    if len(text) <= limit:
        return text
    return f"{text[:limit - 20]}... ({len(text):,} characters)"
