"""The tone map in numpy, for linear images that do not come from the GL colour pass (the
Cycles twin's): the same formulas as shaders/tonemap.glsl, chosen by [render] tone_map, then
rounded to 8 bits as the GL framebuffer does. tests/test_lighting.py checks the two agree."""

import numpy as np

TONE_MAP_FORMULA = {
    "standard": "x * exposure, clipped to [0, 1], then the sRGB curve (Blender's Standard "
                "view transform)",
    "exponential": "x * exposure, then 1 - exp(-x), then x ** (1 / 2.2)",
}


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    c = np.asarray(linear, np.float64)
    return np.where(c < 0.0031308, 12.92 * c, 1.055 * np.power(np.maximum(c, 0.0031308),
                                                               1 / 2.4) - 0.055)


def tone_map(radiance: np.ndarray, kind: str, exposure: float) -> np.ndarray:
    """Linear RGB radiance (..., 3) to uint8 display sRGB."""
    x = np.asarray(radiance, np.float64) * exposure
    if kind == "exponential":
        display = np.power(1.0 - np.exp(-np.maximum(x, 0.0)), 1 / 2.2)
    elif kind == "standard":
        display = srgb_encode(np.clip(x, 0.0, 1.0))
    else:
        raise ValueError(f"tone map {kind!r}: choose one of {', '.join(TONE_MAP_FORMULA)}")
    return np.rint(np.clip(display, 0.0, 1.0) * 255).astype(np.uint8)
