"""One reader per kind of file glsynth reads back: JSON documents (progress markers, run
files, a training run's settings and class weights), label maps, depth and crack-width maps,
render and flight images and training-cache entries. Each reads through glsynth.core.reading
(a regular file within its size; bounded JSON) and checks its kind's contract (docs/design.md,
"Files read back"), refusing anything else with one UserError line naming the file and the
fix; the callers that can make a file again (progress markers, flight frames, cache entries)
catch that and redo it with a warning. Manifests are read by glsynth.data.tokaido.read_manifest,
TOML by glsynth.core.config, both through glsynth.core.reading.
"""

import io
import math
import os
import stat
import warnings
import zipfile
from pathlib import Path

import numpy as np
from PIL import Image, UnidentifiedImageError

from glsynth.core.errors import UserError, named, shown
from glsynth.core.labels import LABEL_MAPS
from glsynth.core.reading import (
    MAX_ARRAY_BYTES,
    MAX_IMAGE_BYTES,
    MAX_JSON_BYTES,
    check_file,
    parse_json,
    read_bytes,
    read_npy,
    remove_entry,
)
from glsynth.data.tokaido import LABEL_STRIDE


def read_json(path: Path, keys: dict[str, type | tuple[type, ...]], fix: str,
              what: str = "") -> dict:
    """A JSON object holding at least ``keys`` (name -> type) from a regular file of at most
    MAX_JSON_BYTES (read_bytes, parse_json); ``what`` starts the message, ``fix`` ends it."""
    where = f"{what} {named(path)}".strip()
    data = parse_json(read_bytes(path, what, MAX_JSON_BYTES, fix), where, fix)
    if not isinstance(data, dict):
        raise UserError(f"{where} holds a JSON {type(data).__name__}, not an object; {fix}")
    for key, kind in keys.items():
        if key not in data:
            raise UserError(f"{where} has no {key!r}; {fix}")
        if not isinstance(data[key], kind) or isinstance(data[key], bool) and kind in (int,
                                                                                       float):
            raise UserError(f"{where}: {key} = {shown(data[key], 40)} is not a "
                            f"{getattr(kind, '__name__', 'value of the right type')}; {fix}")
    return data


def is_marker(path: Path) -> bool:
    """Whether a progress marker (an empty file, or a JSON one its reader checks) is there: a
    regular file. Anything else in its place (a folder, a FIFO) is removed with a warning
    where it can be, so that its unit is done again, and refused with one line where not."""
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return False
    if stat.S_ISREG(mode):
        return True
    warnings.warn(f"progress marker {named(path)} is not a file; its unit is done again",
                  stacklevel=2)
    try:
        path.rmdir() if stat.S_ISDIR(mode) else path.unlink()
    except OSError as err:
        raise UserError(f"progress marker {named(path)} is not a file and cannot be removed "
                        f"({err.strerror}); remove it and run the same command again") from None
    return False


def read_class_weights(path: Path, n_classes: int) -> list[float]:
    """A run's class_weights.json: ``weights``, one finite number >= 0 per class."""
    fix = "delete it and run the same command again to count the classes anew"
    weights = read_json(path, {"weights": list}, fix)["weights"]
    ok = len(weights) == n_classes and all(
        isinstance(w, (int, float)) and not isinstance(w, bool) and math.isfinite(w) and w >= 0
        for w in weights)
    if not ok:
        raise UserError(f"{named(path)}: weights = {shown(weights, 40)} is not {n_classes} "
                        f"finite numbers >= 0; {fix}")
    return [float(w) for w in weights]


def _open_map(path: Path, what: str) -> Image.Image:
    """A map image opened lazily (check_file first), with a crafted or damaged header
    refused."""
    check_file(path, what, MAX_IMAGE_BYTES, "check the dataset's manifest and its files")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            return Image.open(path)
    except (Image.DecompressionBombError, Image.DecompressionBombWarning):
        raise UserError(f"{what} {named(path)} claims more than {Image.MAX_IMAGE_PIXELS:,} "
                        "pixels; the file is damaged: write it again") from None
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as err:
        raise UserError(f"{what} {named(path)} is not a readable image "
                        f"({type(err).__name__}); write it again") from None


def _pixels(im: Image.Image, path: Path, what: str, size: tuple[int, int] | None) -> np.ndarray:
    if size is not None and im.size != tuple(size):
        raise UserError(f"{what} {named(path)} is {im.width}x{im.height}; it must be "
                        f"{size[0]}x{size[1]}, the size its image gives: write it again")
    try:
        with im:
            return np.asarray(im)
    except (OSError, SyntaxError, ValueError) as err:  # truncated or corrupt pixel data
        raise UserError(f"{what} {named(path)} is damaged ({type(err).__name__}); write it "
                        "again") from None


def map_size(image: Path) -> tuple[int, int]:
    """(width, height) of the label and depth maps of an image: a third of its size, the
    Tokaido layout's stride (from the image's header alone)."""
    im = _open_map(image, "image")
    with im:
        return im.width // LABEL_STRIDE, im.height // LABEL_STRIDE


def read_rgb_image(path: Path, what: str, size: tuple[int, int]) -> np.ndarray:
    """uint8 (height, width, 3) pixels of an 8-bit RGB image glsynth wrote (a render's or a
    flight frame's image.png) of ``size`` = (width, height)."""
    im = _open_map(path, what)
    if im.mode != "RGB":
        im.close()
        raise UserError(f"{what} {named(path)} is a {im.mode} image, not 8-bit RGB: write it "
                        "again")
    return _pixels(im, path, what, size)


def read_label_map(path: Path, kind: str, size: tuple[int, int] | None = None) -> np.ndarray:
    """uint8 ids of a ``kind`` ("component" or "damage") label map: one 8-bit channel (mode L
    or P, as the released .bmp files), ids within the kind's range, ``size`` = (width,
    height) when given."""
    im = _open_map(path, f"{kind} label map")
    if im.mode not in ("L", "P"):
        im.close()
        raise UserError(f"{kind} label map {named(path)} is a {im.mode} image; label maps hold "
                        "one 8-bit channel of ids (mode L or P): write it again as such")
    ids = _pixels(im, path, f"{kind} label map", size)
    top = max(LABEL_MAPS[kind])
    if ids.size and int(ids.max()) > top:
        raise UserError(f"{kind} label map {named(path)} holds id {int(ids.max())}; "
                        f"{kind} ids are 0 to {int(top)}: fix the map")
    return ids


def _read_16bit_map(path: Path, what: str, encoding: str, size: tuple[int, int] | None
                    ) -> np.ndarray:
    """uint16 codes of a 16-bit one-channel PNG map, ``size`` = (width, height) when given;
    ``encoding`` says what its codes mean, for the message."""
    im = _open_map(path, what)
    if not im.mode.startswith("I;16"):
        im.close()
        raise UserError(f"{what} {named(path)} is a {im.mode} image; {what}s are 16-bit "
                        f"one-channel PNG ({encoding}): write it again as such")
    return _pixels(im, path, what, size).astype(np.uint16)


def read_depth_map(path: Path, size: tuple[int, int] | None = None) -> np.ndarray:
    """uint16 depth code of a depth map (glsynth.data.tokaido.encode_depth)."""
    return _read_16bit_map(path, "depth map", "0.5 m -> 0, 30 m -> 65535", size)


def read_crack_width_map(path: Path, size: tuple[int, int] | None = None) -> np.ndarray:
    """uint16 code of a crack-width map (glsynth.data.tokaido.encode_crack_width)."""
    return _read_16bit_map(path, "crack-width map", "0.01 mm steps", size)


def read_float_map(path: Path, what: str, size: tuple[int, int],
                   fix: str = "write it again with glsynth render",
                   high: float = math.inf) -> np.ndarray:
    """A float32 (height, width) ``.npy`` map of ``size`` = (width, height), finite and in
    [0, ``high``] everywhere: ``glsynth render``'s and ``glsynth fly``'s depth.npy (metres,
    zfar where nothing is) and crack_width.npy (millimetres, 0 where no crack is)."""
    data = read_npy(path, what, fix)
    if data.dtype != np.float32 or data.shape != (size[1], size[0]):
        raise UserError(f"{what} {named(path)} is {data.dtype} of shape {shown(data.shape, 30)}; "
                        f"it must be float32 of shape {(size[1], size[0])}, the image's: {fix}")
    bad = ~(np.isfinite(data) & (data >= 0) & (data <= high))
    if bad.any():
        allowed = "finite and >= 0" if high == math.inf else f"finite and in [0, {high:g}]"
        raise UserError(f"{what} {named(path)} holds {int(bad.sum()):,} values that are not "
                        f"{allowed} (NaN, infinite, negative or too large); {fix}")
    return data


def cache_entry_bytes(rgb: np.ndarray, key: str) -> bytes:
    """A training-cache entry: the resized image and the key of what it was made from."""
    buffer = io.BytesIO()
    np.savez(buffer, rgb=np.ascontiguousarray(rgb), key=np.array(key))
    return buffer.getvalue()


def read_cache_entry(path: Path, key: str, shape: tuple[int, ...]) -> np.ndarray | None:
    """The image of a cache entry made for ``key`` with uint8 pixels of ``shape``; None if
    there is none. An entry that is unreadable, foreign (another key), or of another dtype
    or shape is removed with a warning naming it, so that the caller makes it again."""
    try:
        check_file(path, "training-cache entry", MAX_ARRAY_BYTES, "it is made again")
        with np.load(path, allow_pickle=False) as data:
            if not {"rgb", "key"} <= set(data.files):
                raise ValueError("not a glsynth cache entry")
            stored, rgb = str(data["key"]), data["rgb"]
        if stored != key:
            raise ValueError("made for another image or size")
        if rgb.dtype != np.uint8 or rgb.shape != tuple(shape):
            raise ValueError(f"{rgb.dtype} {rgb.shape}, not uint8 {tuple(shape)}")
        return rgb
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile) as err:
        if not os.path.lexists(path):
            return None
        warnings.warn(f"training cache: remaking {named(path)} ({shown(str(err), 100)})",
                      stacklevel=2)
        remove_entry(path)
        return None
