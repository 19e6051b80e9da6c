"""Atomic file writes: a file either exists complete or not at all.

Data goes to a temporary file in the destination folder, is flushed to disk, and is then renamed
over the destination (atomic on POSIX within one file system).
"""

import dataclasses
import io
import json
import math
import os
import secrets
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from glsynth.core.errors import UserError


def ensure_parent(path: Path) -> None:
    """Create the parent folder, with an error that says what to do when that fails."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise UserError(f"cannot create output folder {str(path.parent)!r}: {err.strerror}. "
                        "Choose a writable --out location.") from err


def _write_failed(path: Path, err: OSError) -> UserError:
    """The error names the file the user asked for, never the temporary one, and the fix."""
    return UserError(f"cannot write {str(path)!r}: {err.strerror or err}. Check free disk "
                     "space and the permissions of its folder, then run the same command "
                     "again to resume.")


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    path = Path(path)
    ensure_parent(path)
    try:
        # O_CREAT with mode 0o666 lets the process umask decide the final permissions, as for
        # any new file (mkstemp would make it 0600).
        tmp = path.parent / f".{path.name}.{secrets.token_hex(6)}.tmp"
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    except OSError as err:
        raise _write_failed(path, err) from err
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException as err:
        tmp.unlink(missing_ok=True)
        if isinstance(err, OSError):
            raise _write_failed(path, err) from err
        raise


def jsonable(value: Any) -> Any:
    """Plain JSON data: dataclasses become dicts, numpy scalars Python numbers, and non-finite
    floats None (strict JSON has no Infinity or NaN)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return jsonable(dataclasses.asdict(value))
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    return value


def atomic_write_json(path: str | Path, data: Any) -> None:
    text = json.dumps(jsonable(data), indent=2, allow_nan=False) + "\n"
    atomic_write_bytes(path, text.encode("utf-8"))


def image_bytes(array: np.ndarray, format: str = "PNG") -> bytes:
    """Encode uint8 (H, W) or (H, W, 3), or uint16 (H, W) as a 16-bit PNG, to file bytes."""
    buf = io.BytesIO()
    # zlib level 1: a 1920x1080 render encodes 4x faster than at Pillow's default 6 (0.14 s
    # against 0.56 s) for files 17 % larger; PNG stays lossless either way.
    options = {"compress_level": 1} if format == "PNG" else {}
    Image.fromarray(array).save(buf, format=format, **options)
    return buf.getvalue()


def png_bytes(array: np.ndarray) -> bytes:
    return image_bytes(array, "PNG")


def npy_bytes(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, array)
    return buf.getvalue()
