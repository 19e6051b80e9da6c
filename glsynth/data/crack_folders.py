"""Crack images and their crack masks for the sim-to-real benchmark (glsynth bench sim2real):
a folder of real photographs (``images/`` and ``masks/``, one mask per image by file stem)
a glsynth dataset in the Tokaido layout (crack pixels: crack-width map > 0, with its image
brought down to the map's size), and groups of a real folder's images that the benchmark also
scores alone (--groups: by surface, light or camera)."""

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from glsynth.core.errors import UserError, named
from glsynth.core.reading import MAX_JSON_BYTES, parse_json, read_bytes
from glsynth.data.readers import read_crack_width_map
from glsynth.data.tokaido import crack_width_path, read_manifest

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff")
MASK_SUFFIXES = (".png", ".bmp", ".tif", ".tiff", ".jpg", ".jpeg")
JPEG_SUFFIXES = (".jpg", ".jpeg")
"""Masks that JPEG compressed (many public crack datasets ship them so): their ringing beside a
crack's edge stays far from mid-grey, so a 0/255 mask binarised at 128 keeps its cracks; a 0/1
mask's cracks drown in it (at quality 75 they decode to 0), and such a mask is refused where
its 1s survive, a folder of them where none do."""


@dataclass(frozen=True)
class CrackImage:
    name: str
    rgb: np.ndarray
    """(H, W, 3) uint8."""
    crack: np.ndarray
    """(H, W) bool."""


def _read_rgb(path: Path) -> np.ndarray:
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        raise UserError(f"image {str(path)!r} is not a readable image; replace or remove it")
    return np.ascontiguousarray(bgr[..., ::-1])


def _read_mask(path: Path, shape: tuple[int, int]) -> np.ndarray:
    """A crack mask: 0 is background; a 0/1 mask's 1 and a 0/255 mask's values over 127
    are crack (a JPEG mask's always the latter: JPEG_SUFFIXES)."""
    mask = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if mask is None:
        raise UserError(f"mask {str(path)!r} is not a readable image; replace or remove it")
    if mask.shape != shape:
        raise UserError(f"mask {str(path)!r} is {mask.shape[1]}x{mask.shape[0]} but its image "
                        f"is {shape[1]}x{shape[0]}; give each image a mask of its own size")
    if path.suffix.lower() in JPEG_SUFFIXES:
        if 0 < mask.max() <= 127:
            raise UserError(f"mask {str(path)!r} is a JPEG whose values reach only "
                            f"{mask.max()}: a 0/1 mask's cracks cannot be told from JPEG's "
                            "noise; save it as PNG, or with cracks at 255")
        return mask > 127
    return mask > (0 if mask.max() <= 1 else 127)


def _listed(folder: Path, suffixes: tuple[str, ...]) -> dict[str, Path]:
    """The files of ``folder`` with one of ``suffixes`` (any case), by stem; two files of one
    stem (a.png and a.jpg) are refused rather than one picked."""
    listed: dict[str, Path] = {}
    for path in sorted(folder.iterdir()):
        if path.is_file() and path.suffix.lower() in suffixes:
            if path.stem in listed:
                raise UserError(f"{str(listed[path.stem])!r} and {str(path)!r} share a name; "
                                "keep one of them")
            listed[path.stem] = path
    return listed


def read_real_folder(root: str | Path) -> list[CrackImage]:
    """Every image of ``root``/images with its mask ``root``/masks/<stem>.<MASK_SUFFIXES>,
    sorted by name; an image without a mask, a mask without an image, a mask of another
    size, and a folder whose masks mark no crack at all are refused."""
    root = Path(root)
    if not root.is_dir():
        raise UserError(f"real folder {str(root)!r} does not exist or is not a folder; give a "
                        "folder holding images/ and masks/")
    for sub in ("images", "masks"):
        if not (root / sub).is_dir():
            raise UserError(f"real folder {str(root)!r} has no {sub}/ sub-folder; put the "
                            f"photographs in images/ and their crack masks in masks/")
    images, masks = _listed(root / "images", IMAGE_SUFFIXES), _listed(root / "masks",
                                                                      MASK_SUFFIXES)
    if not images:
        raise UserError(f"{str(root / 'images')!r} holds no images "
                        f"({', '.join(IMAGE_SUFFIXES)})")
    for stems, have, lacks in ((images, "image", "masks"), (masks, "mask", "images")):
        other = masks if lacks == "masks" else images
        missing = sorted(set(stems) - set(other))
        if missing:
            raise UserError(f"{have} {str(stems[missing[0]])!r} has no counterpart in "
                            f"{lacks}/ (same name; "
                            f"{len(missing)} such); add it or remove the {have}")
    out = []
    for stem, path in images.items():
        rgb = _read_rgb(path)
        out.append(CrackImage(stem, rgb, _read_mask(masks[stem], rgb.shape[:2])))
    if not any(image.crack.any() for image in out):
        # Also what a JPEG of 0/1 masks decodes to: its 1s lost in compression.
        raise UserError(f"no mask in {str(root / 'masks')!r} marks a crack pixel; mark cracks "
                        "at 1 or 255 (at 255 in a JPEG mask)")
    return out


GROUPS_FIX = ('give a JSON file holding an object of group names, each a list of image names '
              'of the --real folder: {"asphalt": ["0011", "0012.jpg"], "concrete": [...]}')


def read_groups(path: str | Path) -> dict[str, list[str]]:
    """The groups of a --groups file, read before the real folder: a JSON object of group
    names, each a non-empty list of image names (file names of images/, with or without
    their suffix; no folders)."""
    what = f"--groups file {named(path)}"
    groups = parse_json(read_bytes(Path(path), "--groups file", MAX_JSON_BYTES, GROUPS_FIX),
                        what, GROUPS_FIX)
    if not isinstance(groups, dict) or not groups:
        raise UserError(f"{what} is not a non-empty JSON object; {GROUPS_FIX}")
    for group, names in groups.items():
        if not isinstance(names, list) or not names or \
                not all(isinstance(n, str) and n for n in names):
            raise UserError(f"{what}: group {group!r} is not a non-empty list of image names; "
                            f"{GROUPS_FIX}")
        paths = [n for n in names if "/" in n or "\\" in n]
        if paths:
            raise UserError(f"{what}: group {group!r} names {paths[0]!r}, a path; give the "
                            "image's file name in images/, without folders")
    return groups


def _stem_of(name: str, stems: dict[str, int]) -> str | None:
    """The stem of the real folder's image that ``name`` names: the name itself, or the name
    less an image suffix (so a stem that ends like a suffix, 'scan.png' of scan.png.jpg,
    is found as given)."""
    if name in stems:
        return name
    suffix = Path(name).suffix
    if suffix.lower() in IMAGE_SUFFIXES and name[:-len(suffix)] in stems:
        return name[:-len(suffix)]
    return None


def group_members(groups: dict[str, list[str]], images: list[CrackImage]
                  ) -> dict[str, list[int]]:
    """Each group as indices into ``images``. A name the folder lacks is refused, not
    skipped: a misspelt name would otherwise shrink its group silently."""
    index = {image.name: k for k, image in enumerate(images)}
    out = {}
    for group, names in groups.items():
        stems = [_stem_of(n, index) for n in names]
        unknown = [n for n, stem in zip(names, stems) if stem is None]
        if unknown:
            raise UserError(f"--groups: group {group!r} names {unknown[0]!r}, not an image of "
                            f"the --real folder ({len(unknown)} such); fix or remove the name")
        out[group] = sorted({index[stem] for stem in stems})
    return out


def read_synthetic(root: str | Path) -> list[CrackImage]:
    """Every frame of a glsynth dataset (train and test manifests), its image brought down
    to its crack-width map's size (area averaging), crack = width > 0."""
    root = Path(root)
    frames = [*read_manifest(root, "files_train.csv"), *read_manifest(root, "files_test.csv")]
    if not frames:
        raise UserError(f"dataset {str(root)!r} lists no frames; generate one with glsynth "
                        "generate --preset inspection")
    out = []
    for record in frames:
        widths = read_crack_width_map(root / crack_width_path(record.damage))
        rgb = _read_rgb(root / record.image)
        size = (widths.shape[1], widths.shape[0])
        small = cv2.resize(rgb, size, interpolation=cv2.INTER_AREA)
        out.append(CrackImage(Path(record.image).stem, small, widths > 0))
    if not any(image.crack.any() for image in out):
        raise UserError(f"dataset {str(root)!r} has no crack pixels; generate it with cracks "
                        "(--preset inspection)")
    return out
