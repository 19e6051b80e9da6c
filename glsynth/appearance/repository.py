"""The texture repository: image folders by category, as in the paper (Section 2.3).

A repository is a folder with one sub-folder per category (concrete, steel, painted, wood,
ground, scene) holding images (.png, .jpg, .jpeg, .bmp, .tif). Users point glsynth at their own
photos in this layout; by default glsynth generates a procedural one
(glsynth.appearance.texgen) once, deterministically from a seed, and caches it under
$GLSYNTH_CACHE (default ~/.cache/glsynth).

Decoding and resizing is slow next to reading an array (docs/results.md, "Decoded repository
images"), so each image is kept, decoded at the size asked for, as a .npy under
$GLSYNTH_CACHE/decoded, keyed by the SHA-256 of the file's bytes and the size, so an edited
image is decoded again.

An image that cannot be read is skipped with a warning naming it, and the next readable image
of its category is used instead, so a bad file never stops a long run; a category with no
readable image is an error that says what to fix.
"""

import fcntl
import hashlib
import io
import os
import warnings
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
from PIL import Image, UnidentifiedImageError

from glsynth.appearance.texgen import CATEGORIES
from glsynth.core.errors import UserError, named, shown
from glsynth.core.fileio import atomic_write_bytes, npy_bytes, png_bytes
from glsynth.core.interrupts import RenderInterrupted
from glsynth.core.paths import cache_error, cache_folder, cache_root
from glsynth.core.reading import MAX_IMAGE_BYTES, read_bytes, read_npy, remove_entry
from glsynth.core.seeding import Stream, make_rng

EXTENSIONS = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff"}
GENERATOR_VERSION = 1


class TextureRepository:
    """Images of each category, loaded lazily, resized to size x size RGB, kept in memory."""

    def __init__(self, root: str | Path, size: int) -> None:
        self.root = Path(root)
        self.size = size
        self.files: dict[str, list[Path]] = {}
        if not self.root.is_dir():
            raise UserError(f"texture repository {named(self.root)} is not a folder. Point "
                            "[materials] repository at a folder with sub-folders "
                            f"{sorted(CATEGORIES)}, or leave it empty for the built-in one.")
        for category in CATEGORIES:
            folder = self.root / category
            files = sorted(p for p in folder.glob("*") if p.suffix.lower() in EXTENSIONS) \
                if folder.is_dir() else []
            if not files:
                raise UserError(f"texture repository {named(self.root)}: category folder "
                                f"{category!r} is missing or has no images "
                                f"({', '.join(sorted(EXTENSIONS))}). Add images, or run "
                                f"`glsynth textures --out {self.root}` to generate them.")
            self.files[category] = files
        self._cache: dict[tuple[str, int], np.ndarray] = {}
        self._bad: set[Path] = set()

    def count(self, category: str) -> int:
        return len(self.files[category])

    def _load(self, path: Path) -> np.ndarray | None:
        """The image at ``path`` as size x size RGB: from the decoded cache, or decoded (and
        then cached); None, with a warning, where it cannot be read."""
        try:
            data = read_bytes(path, "repository image", MAX_IMAGE_BYTES, "replace it")
        except UserError as err:
            return _unreadable(path, err)
        key = hashlib.sha256(data)
        key.update(self.size.to_bytes(4, "little"))
        cached = cache_folder(cache_root() / "decoded") / f"{key.hexdigest()}.npy"
        if os.path.lexists(cached):
            try:
                array = read_npy(cached, "decoded-image cache entry", "it is decoded again")
                if array.shape == (self.size, self.size, 3) and array.dtype == np.uint8:
                    return array
            except UserError:
                pass
            warnings.warn(f"texture repository: decoding {named(path)} again (its cache entry "
                          f"{cached.name!r} is damaged)", stacklevel=3)
            remove_entry(cached)
        try:
            with Image.open(io.BytesIO(data)) as im:
                im = im.convert("RGB")
                if im.size != (self.size, self.size):
                    im = im.resize((self.size, self.size), Image.Resampling.LANCZOS)
                array = np.asarray(im, dtype=np.uint8)
        except (OSError, UnidentifiedImageError, ValueError, Image.DecompressionBombError) as err:
            return _unreadable(path, err)
        atomic_write_bytes(cached, npy_bytes(array))
        return array

    def image(self, category: str, index: int) -> np.ndarray:
        """Image ``index`` of a category (wrapping), or the next readable one after it."""
        files = self.files[category]
        for step in range(len(files)):
            i = (index + step) % len(files)
            key = (category, i)
            if key in self._cache:
                return self._cache[key]
            if files[i] in self._bad:
                continue
            array = self._load(files[i])
            if array is None:
                self._bad.add(files[i])
                continue
            array.setflags(write=False)
            self._cache[key] = array
            return array
        raise UserError(f"texture repository {named(self.root)}: no readable image in "
                        f"category {category!r}; replace the files named in the warnings")


def _unreadable(path: Path, err: Exception) -> None:
    warnings.warn(f"texture repository: skipping unreadable image {named(path)} "
                  f"({type(err).__name__}: {shown(str(err), 120)})", stacklevel=4)


BUILD_THREADS = 2
"""Images made at once: numpy's FFTs and zlib release the GIL, so two threads make the
built-in repository in about half the time of one, with the same bytes (docs/results.md,
"Making the built-in repository"; bench/bench_repository.py)."""


def _image_path(root: Path, category: str, k: int) -> Path:
    return root / category / f"{category}_{k:04d}.png"


def _complete(root: Path, per_category: int) -> bool:
    return all(_image_path(root, category, k).exists() for category in CATEGORIES
               for k in range(per_category))


def generate_repository(root: str | Path, seed: int, per_category: int, size: int,
                        interrupt: Callable[[], bool] | None = None) -> Path:
    """Fill ``root`` with ``per_category`` procedural images per category (PNG, atomic).
    ``interrupt()``, asked before each image: True raises RenderInterrupted once the images
    begun are written (a viewer stopping while it makes a fresh cache's repository).

    Image k of a category comes from its own generator, so it is the same whatever the count
    and whichever thread makes it; existing files are kept (a run that was stopped carries on
    where it was).
    """
    root = Path(root)
    jobs = [(_image_path(root, category, k), make,
             make_rng(seed, 0, Stream.MATERIALS, 10**6 * (c_index + 1) + k))
            for c_index, (category, make) in enumerate(CATEGORIES.items())
            for k in range(per_category)]

    def write(job: tuple[Path, Callable, np.random.Generator]) -> None:
        path, make, rng = job
        if interrupt is not None and interrupt():
            raise RenderInterrupted("making the texture repository was interrupted")
        atomic_write_bytes(path, png_bytes(make(size, rng)))

    pool = ThreadPoolExecutor(BUILD_THREADS, thread_name_prefix="repository")
    try:
        list(pool.map(write, [job for job in jobs if not job[0].exists()]))  # raises a failure
    finally:  # on a failure or Ctrl-C, the images not begun are not made
        pool.shutdown(cancel_futures=True)
    return root


def builtin_root(seed: int, per_category: int, size: int) -> Path:
    """Where the procedural repository for these settings is cached."""
    return cache_root() / f"textures-v{GENERATOR_VERSION}-seed{seed}-n{per_category}-{size}px"


def builtin_repository(seed: int, per_category: int, size: int,
                       interrupt: Callable[[], bool] | None = None) -> Path:
    """The procedural repository for these settings, generated on first use and cached. One
    process makes it at a time (a flock beside it): the dataset's workers and the processes of
    a test run that start together wait for the first one's images instead of making them
    again. ``interrupt``: generate_repository's."""
    root = cache_folder(builtin_root(seed, per_category, size))
    if _complete(root, per_category):  # no lock needed to read it (a read-only cache works)
        return root
    lock_path = root.with_name(root.name + ".lock")
    try:
        lock = open(lock_path, "a")
    except OSError as err:
        raise cache_error(lock_path, err) from None
    with lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # dropped when closed, or by the kernel at any exit
        return generate_repository(root, seed, per_category, size, interrupt)
