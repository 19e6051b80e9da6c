"""The tone map in numpy, for linear images that do not come from the GL colour pass (the
Cycles twin's): the formula of shaders/tonemap.glsl, then rounded to 8 bits as the GL
framebuffer does. tests/test_lighting.py checks the two agree."""

import numpy as np

TONE_MAP_FORMULA = ("x * exposure, clipped to [0, 1], then the sRGB curve (Blender's Standard "
                    "view transform)")


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    c = np.asarray(linear, np.float64)
    return np.where(c < 0.0031308, 12.92 * c, 1.055 * np.power(np.maximum(c, 0.0031308),
                                                               1 / 2.4) - 0.055)


def tone_map(radiance: np.ndarray, exposure: float) -> np.ndarray:
    """Linear RGB radiance (..., 3) to uint8 display sRGB."""
    display = srgb_encode(np.clip(np.asarray(radiance, np.float64) * exposure, 0.0, 1.0))
    return np.rint(np.clip(display, 0.0, 1.0) * 255).astype(np.uint8)
