"""One reader per kind of file glsynth reads back: JSON documents (progress markers, the run
file, a training run's settings and class weights), label maps, depth maps and training-cache
entries. Each checks its kind's contract (docs/design.md, "Files read back") and refuses
anything else with one UserError line naming the file and the fix; the callers that can make a
file again (progress markers, cache entries) catch that and redo it with a warning.
Manifests are read by glsynth.data.tokaido.read_manifest, TOML by glsynth.core.config.
"""

import io
import json
import math
import warnings
import zipfile
from pathlib import Path

import numpy as np
from PIL import Image, UnidentifiedImageError

from glsynth.core.errors import UserError, shown
from glsynth.core.labels import LABEL_MAPS
from glsynth.data.tokaido import LABEL_STRIDE

MAX_JSON_BYTES = 64 * 2**20
"""A glsynth JSON document is at most a few MB (a marker of 200 views is 0.1 MB)."""


def read_json(path: Path, keys: dict[str, type | tuple[type, ...]], fix: str) -> dict:
    """A JSON object holding at least ``keys`` (name -> type); ``fix`` ends the message."""
    try:
        size = path.stat().st_size
        if size > MAX_JSON_BYTES:
            raise UserError(f"{str(path)!r} is {size:,} bytes, more than any glsynth JSON "
                            f"file; {fix}")
        data = json.loads(path.read_bytes().decode("utf-8"))
    except FileNotFoundError:
        raise UserError(f"{str(path)!r} does not exist; {fix}") from None
    except (UnicodeDecodeError, ValueError, RecursionError) as err:
        if isinstance(err, UserError):
            raise
        reason = str(err).splitlines()[0][:80] if str(err) else type(err).__name__
        raise UserError(f"{str(path)!r} is not valid JSON ({reason}); {fix}") from None
    if not isinstance(data, dict):
        raise UserError(f"{str(path)!r} holds a JSON {type(data).__name__}, not an object; "
                        f"{fix}")
    for key, kind in keys.items():
        if key not in data:
            raise UserError(f"{str(path)!r} has no {key!r}; {fix}")
        if not isinstance(data[key], kind) or isinstance(data[key], bool) and kind in (int,
                                                                                       float):
            raise UserError(f"{str(path)!r}: {key} = {shown(data[key], 40)} is not a "
                            f"{getattr(kind, '__name__', 'value of the right type')}; {fix}")
    return data


def read_class_weights(path: Path, n_classes: int) -> list[float]:
    """A run's class_weights.json: ``weights``, one finite number >= 0 per class."""
    fix = "delete it and run the same command again to count the classes anew"
    weights = read_json(path, {"weights": list}, fix)["weights"]
    ok = len(weights) == n_classes and all(
        isinstance(w, (int, float)) and not isinstance(w, bool) and math.isfinite(w) and w >= 0
        for w in weights)
    if not ok:
        raise UserError(f"{str(path)!r}: weights = {shown(weights, 40)} is not {n_classes} "
                        f"finite numbers >= 0; {fix}")
    return [float(w) for w in weights]


def _open_map(path: Path, what: str) -> Image.Image:
    """A map image opened lazily, with a crafted or damaged header refused."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            return Image.open(path)
    except FileNotFoundError:
        raise UserError(f"{what} {str(path)!r} does not exist; check the dataset's manifest "
                        "and its files") from None
    except (Image.DecompressionBombError, Image.DecompressionBombWarning):
        raise UserError(f"{what} {str(path)!r} claims more than {Image.MAX_IMAGE_PIXELS:,} "
                        "pixels; the file is damaged: write it again") from None
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as err:
        raise UserError(f"{what} {str(path)!r} is not a readable image "
                        f"({type(err).__name__}); write it again") from None


def _pixels(im: Image.Image, path: Path, what: str, size: tuple[int, int] | None) -> np.ndarray:
    if size is not None and im.size != tuple(size):
        raise UserError(f"{what} {str(path)!r} is {im.width}x{im.height}; it must be "
                        f"{size[0]}x{size[1]}, a third of its image: write it again")
    try:
        with im:
            return np.asarray(im)
    except (OSError, SyntaxError, ValueError) as err:  # truncated or corrupt pixel data
        raise UserError(f"{what} {str(path)!r} is damaged ({type(err).__name__}); write it "
                        "again") from None


def map_size(image: Path) -> tuple[int, int]:
    """(width, height) of the label and depth maps of an image: a third of its size, the
    Tokaido layout's stride (from the image's header alone)."""
    im = _open_map(image, "image")
    with im:
        return im.width // LABEL_STRIDE, im.height // LABEL_STRIDE


def read_label_map(path: Path, kind: str, size: tuple[int, int] | None = None) -> np.ndarray:
    """uint8 ids of a ``kind`` ("component" or "damage") label map: one 8-bit channel (mode L
    or P, as the released .bmp files), ids within the kind's range, ``size`` = (width,
    height) when given."""
    im = _open_map(path, f"{kind} label map")
    if im.mode not in ("L", "P"):
        im.close()
        raise UserError(f"{kind} label map {str(path)!r} is a {im.mode} image; label maps hold "
                        "one 8-bit channel of ids (mode L or P): write it again as such")
    ids = _pixels(im, path, f"{kind} label map", size)
    top = max(LABEL_MAPS[kind])
    if ids.size and int(ids.max()) > top:
        raise UserError(f"{kind} label map {str(path)!r} holds id {int(ids.max())}; "
                        f"{kind} ids are 0 to {int(top)}: fix the map")
    return ids


def _read_16bit_map(path: Path, what: str, encoding: str, size: tuple[int, int] | None
                    ) -> np.ndarray:
    """uint16 codes of a 16-bit one-channel PNG map, ``size`` = (width, height) when given;
    ``encoding`` says what its codes mean, for the message."""
    im = _open_map(path, what)
    if not im.mode.startswith("I;16"):
        im.close()
        raise UserError(f"{what} {str(path)!r} is a {im.mode} image; {what}s are 16-bit "
                        f"one-channel PNG ({encoding}): write it again as such")
    return _pixels(im, path, what, size).astype(np.uint16)


def read_depth_map(path: Path, size: tuple[int, int] | None = None) -> np.ndarray:
    """uint16 depth code of a depth map (glsynth.data.tokaido.encode_depth)."""
    return _read_16bit_map(path, "depth map", "0.5 m -> 0, 30 m -> 65535", size)


def read_crack_width_map(path: Path, size: tuple[int, int] | None = None) -> np.ndarray:
    """uint16 code of a crack-width map (glsynth.data.tokaido.encode_crack_width)."""
    return _read_16bit_map(path, "crack-width map", "0.01 mm steps", size)


def read_float_map(path: Path, what: str, size: tuple[int, int]) -> np.ndarray:
    """A float32 (height, width) ``.npy`` map of ``size`` = (width, height): ``glsynth
    render``'s depth.npy and crack_width.npy."""
    fix = "write it again with glsynth render"
    try:
        data = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise UserError(f"{what} {str(path)!r} does not exist; {fix}") from None
    except (OSError, ValueError) as err:
        raise UserError(f"{what} {str(path)!r} is not a .npy array "
                        f"({str(err).splitlines()[0][:80]}); {fix}") from None
    if data.dtype != np.float32 or data.shape != (size[1], size[0]):
        raise UserError(f"{what} {str(path)!r} is {data.dtype} of shape {data.shape}; it must "
                        f"be float32 of shape {(size[1], size[0])}, the image's: {fix}")
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
        with np.load(path, allow_pickle=False) as data:
            if not {"rgb", "key"} <= set(data.files):
                raise ValueError("not a glsynth cache entry")
            stored, rgb = str(data["key"]), data["rgb"]
        if stored != key:
            raise ValueError("made for another image or size")
        if rgb.dtype != np.uint8 or rgb.shape != tuple(shape):
            raise ValueError(f"{rgb.dtype} {rgb.shape}, not uint8 {tuple(shape)}")
        return rgb
    except FileNotFoundError:
        return None
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile) as err:
        warnings.warn(f"training cache: remaking {str(path)!r} ({err})", stacklevel=2)
        path.unlink(missing_ok=True)
        return None
