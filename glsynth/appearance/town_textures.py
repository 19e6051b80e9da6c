"""Procedural textures of the town around the viaducts ([environment] world = "town").

The texture repository's categories are the paper's (Section 3.2) and a user's own photo
folders must hold just those, so the town's surfaces are made here instead: facades (one bay
of one storey, 3 x 3 m, tiling: cladding, a window and, on some, a door), asphalt and foliage.
Image k of a category comes from its own generator (Stream.WORLD, env 0, the repository seed),
made once per process at the repository's size.
"""

import functools
from collections.abc import Callable

import numpy as np

from glsynth.appearance.noise import spectral
from glsynth.core.seeding import Stream, make_rng

FACADE_BAY_M = 3.0
"""A facade image spans one bay of one storey: it repeats every 3 m both ways."""
IMAGES_PER_CATEGORY = 8


def _shade(base: np.ndarray, shade: np.ndarray) -> np.ndarray:
    return np.clip(base[None, None, :] * shade[..., None], 0.0, 1.0)


def facade(size: int, rng: np.random.Generator) -> np.ndarray:
    """One bay: rendered, sided or corrugated cladding, a framed window with glazing bars
    and, in one of three, a door instead of the window's lower half."""
    y, x = np.mgrid[0:size, 0:size] / size  # y = 0 at the top of the image
    wall = np.array([rng.uniform(0.45, 0.9)] * 3) * [1.0, rng.uniform(0.9, 1.0),
                                                     rng.uniform(0.78, 1.0)]
    style = int(rng.integers(3))
    shade = 0.9 + 0.12 * spectral((size, size), 2.0, rng)
    if style == 1:  # horizontal siding boards
        shade *= 0.92 + 0.08 * ((y * 12) % 1.0 > 0.08)
    elif style == 2:  # vertical corrugation
        shade *= 0.85 + 0.15 * np.sin(2 * np.pi * 30 * x) ** 2
    img = _shade(wall, shade)
    w0, w1 = rng.uniform(0.15, 0.3), rng.uniform(0.7, 0.85)
    top, bottom = rng.uniform(0.15, 0.3), rng.uniform(0.6, 0.75)
    frame = (x > w0 - 0.02) & (x < w1 + 0.02) & (y > top - 0.02) & (y < bottom + 0.02)
    img[frame] = [0.85, 0.85, 0.83]
    glass = (x > w0) & (x < w1) & (y > top) & (y < bottom)
    sky = 0.12 + 0.25 * (1.0 - (y - top) / (bottom - top))  # reflections, lighter at the top
    img[glass] = np.stack([sky * 0.8, sky * 0.9, sky], axis=-1)[glass]
    bars = glass & ((np.abs(x - (w0 + w1) / 2) < 0.008) | (np.abs(y - (top + bottom) / 2) < 0.008))
    img[bars] = [0.8, 0.8, 0.78]
    if rng.random() < 1 / 3:
        door = (x > 0.4) & (x < 0.6) & (y > 0.3)
        img[door] = np.array([0.35, 0.22, 0.12]) * rng.uniform(0.6, 1.3)
    return (img * 255).astype(np.uint8)


def asphalt(size: int, rng: np.random.Generator) -> np.ndarray:
    """Dark grey asphalt with aggregate speckle and patches."""
    grey = rng.uniform(0.18, 0.32)
    patches = spectral((size, size), 3.0, rng)
    grain = spectral((size, size), 0.5, rng)
    shade = 0.85 + 0.2 * patches + 0.25 * (grain - 0.5)
    return (_shade(np.array([grey, grey, grey * 1.03]), shade) * 255).astype(np.uint8)


def foliage(size: int, rng: np.random.Generator) -> np.ndarray:
    """Leaves: clumps of green, darker in their gaps."""
    green = np.array([0.16, 0.30, 0.10]) * rng.uniform(0.7, 1.3)
    clumps = spectral((size, size), 2.0, rng)
    leaves = spectral((size, size), 0.8, rng)
    return (_shade(green, 0.6 + 0.5 * clumps + 0.4 * (leaves - 0.5)) * 255).astype(np.uint8)


CATEGORIES: dict[str, Callable[[int, np.random.Generator], np.ndarray]] = {
    "facade": facade, "asphalt": asphalt, "foliage": foliage}


@functools.lru_cache(maxsize=64)
def image(category: str, index: int, size: int, seed: int) -> np.ndarray:
    """Image ``index`` (wrapping) of a town category at ``size`` px, read-only."""
    c = list(CATEGORIES).index(category)
    rng = make_rng(seed, 0, Stream.WORLD, 10**6 * (c + 1) + index % IMAGES_PER_CATEGORY)
    out = CATEGORIES[category](size, rng)
    out.setflags(write=False)
    return out
