"""Small geometry every layer uses: points under a 4x4 transform, the distance from points
to line segments, and the triangle of a mesh that a point on its surface lies on. It sits in
core so that world, appearance, render and data share one copy (shaders/cracks.glsl keeps
its own segment distance in GLSL; tests/test_crack_shader.py compares the two)."""

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


def nearest_triangles(triangles: np.ndarray, points: np.ndarray, chunk: int = 256
                      ) -> np.ndarray:
    """(M,) the index of the triangle of ``triangles`` (T, 3, 3) that each of ``points``
    (M, 3) lies on or nearest to, judged by the distance to the triangle's plane and to the
    farthest edge line it lies outside: a lower bound of the distance that is zero only on the
    triangle, so a point on a mesh's surface finds its own triangle (trimesh's exact
    nearest-point query needs rtree, a compiled dependency, for this one question)."""
    v0, v1, v2 = (triangles[:, k] for k in range(3))
    normal = np.cross(v1 - v0, v2 - v0)
    size = np.linalg.norm(normal, axis=1, keepdims=True)
    normal /= np.maximum(size, 1e-300)
    degenerate = size[:, 0] == 0  # no plane, no edges: it would score 0 everywhere
    corners = np.stack([v0, v1, v2], 1)
    edges = np.roll(corners, -1, axis=1) - corners
    inward = np.cross(normal[:, None], edges)
    inward /= np.maximum(np.linalg.norm(inward, axis=2, keepdims=True), 1e-300)
    out = np.empty(len(points), np.int64)
    for start in range(0, len(points), chunk):
        p = points[start:start + chunk, None]
        plane = np.abs(np.sum((p - v0) * normal, -1))
        side = np.einsum("mtkd,tkd->mtk", p[:, :, None] - corners, inward)
        outside = np.maximum(-side.min(-1), 0.0)
        score = np.where(degenerate, np.inf, np.hypot(plane, outside))
        out[start:start + chunk] = np.argmin(score, axis=1)
    return out
