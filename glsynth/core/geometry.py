"""Small geometry every layer uses: points under a 4x4 transform, and the distance from points
to line segments. It sits in core so that world, appearance, render and data share one copy
(shaders/cracks.glsl keeps its own in GLSL; tests/test_crack_shader.py compares the two)."""

import functools
import operator
from collections.abc import Sequence

import numpy as np


def transform_points(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``points`` (..., 3) under the affine part of the 4x4 ``matrix`` (a pose or a view):
    rotation and translation, no perspective divide."""
    return points @ matrix[:3, :3].T + matrix[:3, 3]


def _dot(u: Sequence[np.ndarray], v: Sequence[np.ndarray]) -> np.ndarray:
    """Sum of the products of per-axis arrays, axis after axis (x, then y, then z: the order,
    and so the bits, of numpy's sum over a last axis of 2 or 3)."""
    return functools.reduce(operator.add, (a * b for a, b in zip(u, v)))


def segment_distance_axes(p: Sequence[np.ndarray], a: Sequence[np.ndarray],
                          ab: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """``segment_distance`` on per-axis arrays that broadcast (points ``p``, segment starts
    ``a`` and directions ``ab``, one array per axis): no (..., D) temporaries, for callers
    that test many points against many segments."""
    length2 = _dot(ab, ab)
    t = np.clip(_dot([pq - aq for pq, aq in zip(p, a)], ab)
                / np.where(length2 > 0, length2, 1.0), 0.0, 1.0)
    t = np.where(length2 > 0, t, 0.0)  # a point segment: its start is the nearest point
    r = [pq - (aq + t * abq) for pq, aq, abq in zip(p, a, ab)]
    return np.sqrt(_dot(r, r)), t


def segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray,
                                                                           np.ndarray]:
    """Distance from points ``p`` (..., D) to segments a-b (..., D) (arrays that broadcast; D
    is 2 or 3), and the parameter t in [0, 1] of the nearest point a + t (b - a)."""
    axes = range(p.shape[-1])
    return segment_distance_axes([p[..., q] for q in axes], [a[..., q] for q in axes],
                                 [b[..., q] - a[..., q] for q in axes])
