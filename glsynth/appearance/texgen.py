"""Procedural texture images per repository category, deterministic from a generator.

glsynth cannot download the paper's photo repository at run time, so it makes plausible,
varied stand-ins: tileable (periodic) surface textures built from spectral noise, and scene
panoramas (urban skyline, rural fields). Each function returns an (S, S, 3) uint8 sRGB image.
"""

from collections.abc import Callable

import numpy as np

from glsynth.appearance.noise import spectral

Image = np.ndarray


def _rgb(base: np.ndarray, shade: np.ndarray) -> Image:
    """Base colour (3,) in [0, 1] modulated by a shade map (S, S) around 1."""
    return np.clip(base[None, None, :] * shade[..., None] * 255.0, 0, 255).astype(np.uint8)


def _dots(size: int, density: float, rng: np.random.Generator, beta: float = 0.5) -> np.ndarray:
    """Sparse speckles: the top ``density`` fraction of a fine noise."""
    fine = spectral((size, size), beta, rng)
    return (fine > np.quantile(fine, 1.0 - density)).astype(np.float32)


def concrete(size: int, rng: np.random.Generator) -> Image:
    """Grey concrete: aggregate speckle, pores, low-frequency stains and formwork joints."""
    grey = rng.uniform(0.45, 0.72)
    tint = np.array([1.0, rng.uniform(0.97, 1.01), rng.uniform(0.92, 1.0)]) * grey
    stains = spectral((size, size), 3.2, rng)
    grain = spectral((size, size), 1.0, rng)
    shade = 0.85 + 0.25 * stains + 0.12 * (grain - 0.5)
    shade -= 0.25 * _dots(size, rng.uniform(0.002, 0.01), rng)      # pores
    shade += 0.10 * _dots(size, rng.uniform(0.02, 0.06), rng)       # aggregate
    joints = max(1, int(rng.integers(1, 4)))
    rows = np.arange(size) % (size // joints)
    shade[rows < max(1, size // 400), :] *= 0.8                     # formwork joints
    streaks = spectral((size, size), 2.0, rng, anisotropy=6.0).T    # vertical rain streaks
    shade *= 1.0 - rng.uniform(0.0, 0.2) * np.clip(streaks - 0.5, 0, 1)
    return _rgb(tint, shade)


def steel(size: int, rng: np.random.Generator) -> Image:
    """Bare brushed steel, or rusted steel with orange-brown patches."""
    brushed = spectral((size, size), 1.5, rng, anisotropy=12.0)
    if rng.random() < 0.5:
        base = np.array([0.55, 0.56, 0.58]) * rng.uniform(0.8, 1.1)
        return _rgb(base, 0.85 + 0.3 * brushed)
    rust = spectral((size, size), 2.8, rng)
    level = rng.uniform(0.3, 0.7)
    patches = np.clip((rust - level) * 6.0, 0.0, 1.0)[..., None]
    metal = np.array([0.45, 0.45, 0.47])[None, None] * (0.8 + 0.3 * brushed[..., None])
    rusty = np.array([0.45, 0.22, 0.10])[None, None] * (0.7 + 0.5 * rust[..., None])
    return np.clip((metal * (1 - patches) + rusty * patches) * 255, 0, 255).astype(np.uint8)


def painted(size: int, rng: np.random.Generator) -> Image:
    """A painted surface of one random colour, with brush noise and some peeling."""
    hue = rng.uniform(0, 1)
    base = np.clip(np.abs((hue * 6 + np.array([0, 4, 2])) % 6 - 3) - 1, 0, 1)
    base = 0.25 + 0.6 * (base * rng.uniform(0.4, 0.9) + (1 - rng.uniform(0.4, 0.9)) * 0.5)
    shade = 0.9 + 0.15 * spectral((size, size), 1.2, rng)
    peel = spectral((size, size), 2.5, rng) > rng.uniform(0.8, 0.95)
    img = _rgb(base, shade)
    img[peel] = (img[peel] * 0.55).astype(np.uint8)
    return img


def wood(size: int, rng: np.random.Generator) -> Image:
    """Wood grain: warped stripes along x in brown tones."""
    warp = spectral((size, size), 3.0, rng)
    y = np.arange(size)[:, None] / size
    rings = rng.integers(8, 30)
    grain = 0.5 + 0.5 * np.sin(2 * np.pi * (rings * y + 1.5 * warp))
    fibre = spectral((size, size), 1.0, rng, anisotropy=10.0)
    base = np.array([0.55, 0.38, 0.22]) * rng.uniform(0.6, 1.1)
    return _rgb(base, 0.7 + 0.35 * grain + 0.15 * (fibre - 0.5))


def ground(size: int, rng: np.random.Generator) -> Image:
    """Gravel (grey-brown speckle) or grass (green noise with blades)."""
    coarse = spectral((size, size), 2.5, rng)
    fine = spectral((size, size), 0.6, rng)
    if rng.random() < 0.5:
        base = np.array([0.48, 0.44, 0.38]) * rng.uniform(0.8, 1.1)
        return _rgb(base, 0.7 + 0.3 * coarse + 0.35 * (fine - 0.5))
    base = np.array([0.28, 0.42, 0.16]) * rng.uniform(0.8, 1.2)
    blades = spectral((size, size), 1.0, rng, anisotropy=0.15)
    return _rgb(base, 0.65 + 0.4 * coarse + 0.3 * (blades - 0.5))


def scene(size: int, rng: np.random.Generator) -> Image:
    """A panorama for the panels at 30 m: an urban skyline or rural fields under a sky."""
    h = w = size
    y = np.linspace(0.0, 1.0, h)[:, None, None]
    sky = (np.array([0.55, 0.68, 0.86]) * (1 - y) + np.array([0.85, 0.88, 0.9]) * y)
    img = np.broadcast_to(sky, (h, w, 3)).copy()
    horizon = int(h * rng.uniform(0.45, 0.65))
    if rng.random() < 0.5:  # urban: buildings with window grids
        x = 0
        while x < w:
            # At least one pixel wide: below 16 px w // 16 is 0, and a 0-wide building never
            # moved x on (sizes 5-9 hung, 4 raised); from 16 px the draws are unchanged.
            bw = int(rng.integers(max(1, w // 16), max(2, w // 5)))
            top = int(rng.uniform(0.1, 0.9) * horizon)
            color = rng.uniform(0.35, 0.8) * np.array([1.0, 0.98, 0.95])
            img[top:, x:x + bw] = color
            wy, wx = max(2, h // 60), max(2, w // 80)
            rows = (np.arange(top, h) // wy) % 2 == 0
            cols = (np.arange(x, min(x + bw, w)) // wx) % 2 == 0
            img[top:, x:x + bw][np.ix_(rows, cols)] *= 0.55
            x += bw
        img[horizon:] = np.array([0.35, 0.35, 0.36]) * (0.8 + 0.3 * spectral(
            (h - horizon, w), 2.0, rng))[..., None]
    else:  # rural: hills, fields in bands, tree line
        hills = (horizon - (0.15 * h * spectral((1, w), 3.0, rng)[0])).astype(int)
        rows = np.arange(h)[:, None]
        land = rows >= hills[None, :]
        fields = (rows // max(2, h // 20)) % 3
        palette = np.array([[0.30, 0.45, 0.18], [0.55, 0.50, 0.25], [0.22, 0.35, 0.15]])
        tex = 0.8 + 0.3 * spectral((h, w), 2.0, rng)
        img[land] = (palette[fields] * tex[..., None])[land]
        trees = land & (rows < hills[None, :] + h // 40)
        img[trees] = np.array([0.12, 0.22, 0.10])
    return np.clip(img * 255, 0, 255).astype(np.uint8)


CATEGORIES: dict[str, Callable[[int, np.random.Generator], Image]] = {
    "concrete": concrete, "steel": steel, "painted": painted, "wood": wood,
    "ground": ground, "scene": scene,
}
