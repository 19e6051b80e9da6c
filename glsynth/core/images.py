"""Images in: photos as a photographer gives them (read_photo), and resizing maps whose values
must never blend (ids, masks) by one convention everywhere."""

import warnings
from pathlib import Path

import cv2
import numpy as np
from PIL import Image, ImageOps, UnidentifiedImageError

from glsynth.core.errors import UserError, named
from glsynth.core.reading import MAX_IMAGE_BYTES, check_file, read_bytes


def nearest_indices(n_in: int, n_out: int) -> np.ndarray:
    """Source index of each output index under pixel-centre nearest sampling:
    floor((i + 0.5) * n_in / n_out), as Pillow's NEAREST and the 3x label downsampling do."""
    return (np.arange(n_out) * 2 + 1) * n_in // (2 * n_out)


def nearest_resize(values: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """A map brought to (rows, cols) by nearest sampling at pixel centres."""
    if values.shape[:2] == tuple(shape):
        return values
    rows = nearest_indices(values.shape[0], shape[0])
    cols = nearest_indices(values.shape[1], shape[1])
    return np.ascontiguousarray(values[rows[:, None], cols[None, :]])


PHOTO_MODES = ("1", "L", "LA", "P", "PA", "RGB", "RGBA", "I;16", "I;16B", "I;16L", "F")
"""Pillow modes read_photo converts; see its docstring for the rule of each."""


def read_photo(path: str | Path) -> np.ndarray:
    """A photo as uint8 (H, W, 3) RGB, upright: Pillow decodes it and ``ImageOps.exif_transpose``
    applies its EXIF orientation. Conversion by kind: 8-bit RGB as is; grayscale and bilevel
    replicated to three channels; palette images expanded; alpha dropped (PNG stores colour
    unpremultiplied, so the photographed colour is kept as is); 16-bit channels scaled by
    1/257, rounded (65535 -> 255); float images must lie in [0, 1] and are scaled by 255,
    rounded. Other kinds (CMYK, 32-bit integer, float outside [0, 1]) are refused with one
    line, as are files that are missing or damaged, and those over Pillow's decompression-bomb
    limit (MAX_IMAGE_PIXELS, 89 MP), which would take gigabytes to decode."""
    path = Path(path)
    check_file(path, "image", MAX_IMAGE_BYTES, "check the path")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            im = Image.open(path)
        with im:
            if im.mode not in PHOTO_MODES:
                raise UserError(f"{named(path)} is a {im.mode} image; glsynth reads "
                                "grayscale, RGB(A), palette, 16-bit and [0, 1] float "
                                "images: save it as 8- or 16-bit RGB")
            wide = im.mode in ("RGB", "RGBA") and any(";16" in str(t.args) for t in im.tile)
            upright = ImageOps.exif_transpose(_wide_rgb(path, im) if wide else im)
            return _photo_rgb(path, upright)
    except FileNotFoundError:
        raise UserError(f"{named(path)} does not exist; check the path") from None
    except (Image.DecompressionBombError, Image.DecompressionBombWarning):
        raise UserError(f"{named(path)} claims more than Pillow's limit of "
                        f"{Image.MAX_IMAGE_PIXELS:,} pixels for one image (a damaged or "
                        "crafted file, or a panorama): scale it down first") from None
    except (UnidentifiedImageError, OSError, SyntaxError,
            ValueError) as err:
        if isinstance(err, UserError):
            raise
        # OSError: truncated data; SyntaxError: Pillow's word for a malformed header. Its
        # message is kept when short and not a repetition of the path.
        first = (str(err).splitlines() or [""])[0]
        reason = type(err).__name__ + (f": {first}" if first and len(first) < 80
                                       and str(path) not in first else "")
        raise UserError(f"{named(path)} is not a readable image ({reason}); check the file "
                        "or export it again as PNG or JPEG") from err


def _wide_rgb(path: Path, im: Image.Image) -> Image.Image:
    """A 16-bit RGB(A) file, which Pillow cuts to its high bytes, decoded at 16 bits by OpenCV,
    scaled by 1/257 and carrying the file's EXIF for exif_transpose."""
    data = np.frombuffer(read_bytes(path, "image", MAX_IMAGE_BYTES, "check the path"), np.uint8)
    pixels = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    if pixels is None or pixels.dtype != np.uint16 or pixels.ndim != 3:
        raise UserError(f"{named(path)}: its 16-bit colour data cannot be decoded; export it "
                        "again as PNG")
    rgb = cv2.cvtColor(pixels[..., :3], cv2.COLOR_BGR2RGB)
    out = Image.fromarray(_scale16(rgb))
    out.info["exif"] = im.info.get("exif") or im.getexif().tobytes()
    return out


def _scale16(values: np.ndarray) -> np.ndarray:
    return ((values.astype(np.uint32) * 2 + 257) // 514).astype(np.uint8)


def _photo_rgb(path: Path, im: Image.Image) -> np.ndarray:
    """uint8 (H, W, 3) of an upright image of one of PHOTO_MODES (read_photo's rules)."""
    if im.mode.startswith("I;16"):
        gray = _scale16(np.asarray(im).astype(np.uint16))
    elif im.mode == "F":
        values = np.asarray(im)
        if not np.isfinite(values).all() or values.min() < 0 or values.max() > 1:
            raise UserError(f"{named(path)}: a float image must hold values in [0, 1], this "
                            f"one spans [{np.nanmin(values):.4g}, {np.nanmax(values):.4g}]; "
                            "save it as 8- or 16-bit")
        gray = np.round(values * 255).astype(np.uint8)
    else:
        return np.ascontiguousarray(np.asarray(im.convert("RGB")))
    return np.ascontiguousarray(np.repeat(gray[..., None], 3, axis=2))
