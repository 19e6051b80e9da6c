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
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from types import TracebackType
from typing import Any

import cv2
import numpy as np
from PIL import Image

from glsynth.core.errors import UserError, named


def ensure_parent(path: Path) -> None:
    """Create the parent folder, with an error that says what to do when that fails."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise UserError(f"cannot create output folder {named(path.parent)}: {err.strerror}. "
                        "Choose a writable --out location.") from err


def _write_failed(path: Path, err: OSError) -> UserError:
    """The error names the file the user asked for, never the temporary one, and the fix."""
    return UserError(f"cannot write {named(path)}: {err.strerror or err}. Check free disk "
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
    """Encode uint8 (H, W) or (H, W, 3) RGB, or uint16 (H, W) as a 16-bit PNG, to file bytes."""
    if format == "PNG":
        # OpenCV's encoder at zlib level 1: faster than Pillow's and than level 6 for the same
        # file size; every row through PNG's Up filter, not the best of five tried row by row:
        # half the CPU, the file within a few per cent (docs/results.md). Lossless either way.
        pixels = cv2.cvtColor(array, cv2.COLOR_RGB2BGR) if array.ndim == 3 else array
        ok, encoded = cv2.imencode(".png", pixels, [cv2.IMWRITE_PNG_COMPRESSION, 1,
                                                    cv2.IMWRITE_PNG_FILTER,
                                                    cv2.IMWRITE_PNG_FILTER_UP])
        if not ok:  # cv2 refuses only what the types above exclude
            raise ValueError(f"PNG encoding failed for {array.dtype} {array.shape}")
        return encoded.tobytes()
    buf = io.BytesIO()
    Image.fromarray(array).save(buf, format=format)
    return buf.getvalue()


def png_bytes(array: np.ndarray) -> bytes:
    return image_bytes(array, "PNG")


def npy_bytes(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, array)
    return buf.getvalue()


def write_files(out: Path, images: dict[str, tuple[np.ndarray, str]],
                documents: dict[str, Any]) -> None:
    """Encode and atomically write ``images`` (relative path -> (array, "PNG" or "BMP")), then
    ``documents`` (relative path -> JSON data), under ``out``."""
    for relative, (array, format) in images.items():
        atomic_write_bytes(out / relative, image_bytes(array, format))
    for relative, data in documents.items():
        atomic_write_json(out / relative, data)


class BackgroundWriter:
    """Runs file jobs (encode, then atomic writes) in one background thread, in order, so that
    a worker renders its next view meanwhile: OpenCV's encoder, zlib and the writes release
    the GIL. At most ``pending`` jobs wait, which bounds the memory their arrays hold.

    A job that failed is raised by the next ``submit`` or by leaving the ``with`` block, so a
    run stops at its first failed write and never reports as done a unit with a file missing.
    Leaving the block waits for every job, also when the block raises, so no job outlives it
    (its files are written whole or not at all, as every write here is atomic)."""

    def __init__(self, pending: int = 2) -> None:
        if pending < 1:
            raise ValueError(f"pending = {pending}: must be at least 1")
        self._pending = pending
        self._jobs: deque[Future[None]] = deque()
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="writer")

    def submit(self, job: Callable[..., None], *args: Any) -> None:
        self._raise_failed()
        self._jobs.append(self._pool.submit(job, *args))
        while len(self._jobs) > self._pending:
            self._jobs.popleft().result()

    def _raise_failed(self) -> None:
        """Raise the error of the oldest finished job that failed (the jobs ahead of it are
        done or still running)."""
        while self._jobs and self._jobs[0].done():
            self._jobs.popleft().result()

    def wait(self) -> None:
        """Wait for every job; raise the first failure."""
        while self._jobs:
            self._jobs.popleft().result()

    def __enter__(self) -> "BackgroundWriter":
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        try:
            if kind is None:
                self.wait()
        finally:
            # On an error in the block the jobs still finish (or fail) before it propagates.
            self._pool.shutdown(wait=True)


def distinct_stems(paths: list[str] | list[Path]) -> list[str]:
    """Output stems for a batch of input files, unique within it: a file's stem, or for stems
    that occur more than once (a/ok.png, b/ok.png) the stem and the file's position (ok_0,
    ok_1), so that no output overwrites another."""
    names = [Path(p).stem for p in paths]
    taken = {n for n in names if names.count(n) == 1}
    stems = []
    for i, name in enumerate(names):
        stem = name
        if names.count(name) > 1:
            stem, k = f"{name}_{i}", i
            while stem in taken:  # "ok_1" was itself an input's stem
                k += len(names)
                stem = f"{name}_{k}"
        taken.add(stem)
        stems.append(stem)
    return stems
