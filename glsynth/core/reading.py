"""Reading a file within limits, whatever stands at its path: check_file opens it without
blocking and checks it with fstat before a byte is read (no FIFO, device, folder or symlink
loop; at most its kind's size), and parse_json and read_npy bound what a file may hold. Every
reader of glsynth (glsynth.data.readers and the TOML, manifest, photo, cache and checkpoint
readers) starts here; docs/design.md, "Files read back", lists what each checks."""

import io
import json
import math
import os
import shutil
import stat
from pathlib import Path

import numpy as np

from glsynth.core.errors import UserError, named

MAX_JSON_BYTES = 64 * 2**20
"""A glsynth JSON document is at most a few MB (a marker of 200 views is 0.1 MB)."""
MAX_JSON_DEPTH = 32
"""The deepest nesting of arrays and objects any glsynth JSON file has is 4 (a pose)."""
MAX_JSON_DIGITS = 30
"""The longest number any glsynth JSON file holds (a float's repr is at most 24 characters)."""
MAX_TOML_BYTES = 1 << 20
"""A config file sets a few dozen keys (the paper preset's in full is 6 kB)."""
MAX_MANIFEST_BYTES = 1 << 28
"""A manifest line is at most 7 fields of 1024 characters; 256 MB is 30,000 such lines."""
MAX_ARRAY_BYTES = 1 << 30
"""A .npy map of the largest render (8192 x 8192 float32 is 256 MB) with room to spare."""
MAX_IMAGE_BYTES = 1 << 30
"""An image file: Pillow's pixel limit (89 MP) at 8 bytes a pixel, with room to spare."""


def check_file(path: Path, what: str, limit: int, fix: str) -> int:
    """The size of a regular file of at most ``limit`` bytes; one UserError line for a
    missing, unopenable, special (FIFO, device, folder) or oversize one. It is opened without
    blocking and never read, so a FIFO never hangs the caller. ``what`` names its kind."""
    what = f"{what} {named(path)}".strip()
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except FileNotFoundError:
        raise UserError(f"{what} does not exist; {fix}") from None
    except OSError as err:
        raise UserError(f"{what} cannot be opened ({err.strerror}); {fix}") from None
    try:
        info = os.fstat(fd)
    finally:
        os.close(fd)
    if not stat.S_ISREG(info.st_mode):
        raise UserError(f"{what} is not a regular file (a folder, FIFO or device); {fix}")
    if info.st_size > limit:
        raise UserError(f"{what} is {info.st_size:,} bytes, more than the {limit:,} such a "
                        f"file may hold; {fix}")
    return info.st_size


def read_bytes(path: Path, what: str, limit: int, fix: str) -> bytes:
    """The bytes of a file that passes check_file: a regular file of at most ``limit``."""
    check_file(path, what, limit, fix)
    try:
        with open(path, "rb") as f:
            data = f.read(limit + 1)
    except OSError as err:
        raise UserError(f"{what} {named(path)} cannot be read ({err.strerror}); "
                        f"{fix}") from None
    if len(data) > limit:  # grown since it was checked
        raise UserError(f"{what} {named(path)} is more than {limit:,} bytes; {fix}")
    return data


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):  # 1e999
        raise ValueError(f"number {text[:20]} is out of range")
    return value


def _short_int(text: str) -> int:
    if len(text) > MAX_JSON_DIGITS:
        raise ValueError(f"an integer of {len(text)} digits")
    return int(text)


def _no_constant(text: str) -> float:
    raise ValueError(f"{text} is not a finite number")


def _depth(data: object) -> int:
    """How deep arrays and objects nest in parsed JSON (iteratively: no recursion limit)."""
    deepest, todo = 0, [(data, 1)]
    while todo:
        value, level = todo.pop()
        if isinstance(value, (list, dict)):
            deepest = max(deepest, level)
            todo.extend((v, level + 1) for v in (value.values() if isinstance(value, dict)
                                                 else value))
    return deepest


def parse_json(data: bytes, what: str, fix: str) -> object:
    """Strict JSON of at most MAX_JSON_DEPTH levels: UTF-8, finite numbers of at most
    MAX_JSON_DIGITS characters (no NaN, Infinity or 1e999), else one UserError line."""
    try:
        value = json.loads(data.decode("utf-8"), parse_float=_finite_float,
                           parse_int=_short_int, parse_constant=_no_constant)
    except (UnicodeDecodeError, ValueError, RecursionError) as err:
        reason = ("nested too deeply" if isinstance(err, RecursionError) else
                  str(err).splitlines()[0][:80] if str(err) else type(err).__name__)
        raise UserError(f"{what} is not valid JSON ({reason}); {fix}") from None
    if _depth(value) > MAX_JSON_DEPTH:
        raise UserError(f"{what} nests more than {MAX_JSON_DEPTH} levels deep; {fix}")
    return value


def read_npy(path: Path, what: str, fix: str) -> np.ndarray:
    """A numeric array from a ``.npy`` file that passes check_file (at most MAX_ARRAY_BYTES,
    no pickled objects); one UserError line for anything else."""
    data = read_bytes(path, what, MAX_ARRAY_BYTES, fix)
    try:
        array = np.load(io.BytesIO(data), allow_pickle=False)
    except (OSError, ValueError, EOFError) as err:
        reason = (str(err).splitlines() or [type(err).__name__])[0][:80]
        raise UserError(f"{what} {named(path)} is not a .npy array ({reason}); {fix}") from None
    if not isinstance(array, np.ndarray) or array.dtype.kind not in "biuf":
        raise UserError(f"{what} {named(path)} holds no numeric array; {fix}")
    return array


def remove_entry(path: Path) -> None:
    """Remove a cache entry about to be made again, whatever it is (a file, a FIFO, a
    folder: an entry glsynth made is a file, so a folder there holds nothing of its)."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        path.unlink(missing_ok=True)
