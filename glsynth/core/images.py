"""Resizing maps whose values must never blend (ids, masks): one convention everywhere."""

import numpy as np


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
