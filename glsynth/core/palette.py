"""Colours for showing label maps to people: overlays and colour-mapped depth."""

import numpy as np

from glsynth.core.labels import Component, Damage

COMPONENT_RGB = np.array([
    (0, 0, 0),        # 0 unlabelled
    (70, 70, 70),     # 1 nonbridge
    (240, 200, 40),   # 2 slab
    (60, 180, 75),    # 3 beam
    (230, 25, 75),    # 4 column
    (0, 130, 200),    # 5 nonstructural
    (245, 130, 48),   # 6 rail
    (145, 30, 180),   # 7 sleeper
    (255, 255, 255),  # 8 other
], dtype=np.uint8)
assert len(COMPONENT_RGB) == len(Component)

DAMAGE_RGB = np.array([(0, 0, 0), (40, 40, 40), (255, 60, 0), (0, 220, 255)], dtype=np.uint8)
assert len(DAMAGE_RGB) == len(Damage)


def overlay(image: np.ndarray, ids: np.ndarray, palette: np.ndarray, alpha: float = 0.5,
            skip: tuple[int, ...] = ()) -> np.ndarray:
    """Blend palette colours of ``ids`` over an RGB image; ids in ``skip`` stay as they are."""
    colors = palette[np.clip(ids, 0, len(palette) - 1)].astype(np.float32)
    out = image.astype(np.float32)
    mask = ~np.isin(ids, skip)[..., None]
    blended = (1 - alpha) * out + alpha * colors
    return np.where(mask, blended, out).round().astype(np.uint8)


def depth_rgb(depth: np.ndarray, near: float = 0.5, far: float = 30.0) -> np.ndarray:
    """Depth coloured with matplotlib's turbo on a log scale; beyond ``far`` is black."""
    from matplotlib import colormaps

    d = np.clip(depth, near, far)
    t = np.log(d / near) / np.log(far / near)
    rgb = (colormaps["turbo"](t)[..., :3] * 255).round().astype(np.uint8)
    rgb[depth >= far] = 0
    return rgb


def grade_rgb(count: int) -> np.ndarray:
    """``count`` colours from narrow to wide (matplotlib's plasma, dark blue to yellow) for
    crack-width grades; (count, 3) uint8."""
    from matplotlib import colormaps

    t = np.linspace(0.0, 0.92, count)  # plasma's last tenth is too pale over concrete
    return (colormaps["plasma"](t)[:, :3] * 255).round().astype(np.uint8)
