"""glsynth.core.geometry: the one point-to-segment distance and point transform."""

import numpy as np
import pytest
import trimesh

from glsynth.core.geometry import (
    nearest_triangles,
    segment_distance,
    segment_distance_axes,
    transform_points,
)
from glsynth.core.seeding import Stream, make_rng
from glsynth.world.meshes import pose


def _sampled(p: np.ndarray, a: np.ndarray, b: np.ndarray, n: int = 20001
             ) -> tuple[np.ndarray, np.ndarray]:
    """Nearest of n points along each segment: distance and parameter, by brute force."""
    t = np.linspace(0.0, 1.0, n)
    points = a[..., None, :] + t[:, None] * (b - a)[..., None, :]
    d = np.linalg.norm(p[..., None, :] - points, axis=-1)
    return d.min(-1), t[d.argmin(-1)]


@pytest.mark.parametrize("dim", [2, 3])
def test_segment_distance_matches_the_nearest_of_dense_samples(dim):
    rng = make_rng(0, 0, Stream.GEOMETRY)
    p, a, b = (rng.normal(size=(400, dim)) for _ in range(3))
    d, t = segment_distance(p, a, b)
    d_ref, t_ref = _sampled(p, a, b)
    step = np.linalg.norm(b - a, axis=1) / 20000
    assert np.all(d <= d_ref + 1e-12) and np.all(d_ref - d <= step)  # samples are step apart
    assert np.all((t >= 0) & (t <= 1))
    inside = (t > 1e-3) & (t < 1 - 1e-3)  # the foot of the perpendicular: at a right angle
    foot = a + t[:, None] * (b - a)
    assert np.allclose(np.sum((p - foot) * (b - a), 1)[inside], 0.0, atol=1e-9)
    assert np.abs(t - t_ref).max() < 0.05


def test_segment_distance_of_end_points_and_point_segments():
    a, b = np.array([0.0, 0.0, 0.0]), np.array([2.0, 0.0, 0.0])
    d, t = segment_distance(np.array([[-3.0, 4.0, 0.0], [5.0, 0.0, 4.0], [1.0, 1.0, 0.0]]), a, b)
    assert d.tolist() == [5.0, 5.0, 1.0] and t.tolist() == [0.0, 1.0, 0.5]
    d, t = segment_distance(np.array([3.0, 4.0, 0.0]), a, a)  # a point: no division by zero
    assert d == 5.0 and t == 0.0


def test_per_axis_arrays_give_the_same_bits_as_stacked_ones():
    """cracks_index tests cells per axis, crack_texture and the tests stacked: the same grid."""
    rng = make_rng(0, 1, Stream.GEOMETRY)
    p, a, b = rng.normal(size=(300, 1, 3)), rng.normal(size=(1, 200, 3)), \
        rng.normal(size=(1, 200, 3))
    b[0, :20] = a[0, :20]
    d, t = segment_distance(p, a, b)
    d_axes, t_axes = segment_distance_axes([p[..., q] for q in range(3)],
                                           [a[..., q] for q in range(3)],
                                           [b[..., q] - a[..., q] for q in range(3)])
    assert d.tobytes() == d_axes.tobytes() and t.tobytes() == t_axes.tobytes()


def test_transform_points_is_the_homogeneous_product():
    rng = make_rng(0, 2, Stream.GEOMETRY)
    matrix = pose(0.7, [1.0, -2.0, 3.0])
    points = rng.normal(size=(5, 4, 3))
    homogeneous = np.concatenate([points, np.ones((5, 4, 1))], -1) @ matrix.T
    assert np.allclose(transform_points(matrix, points), homogeneous[..., :3], atol=1e-12)


def test_nearest_triangles_finds_the_triangle_a_surface_point_lies_on():
    """Points on an I-shaped girder's surface (trimesh's surface samples) find their own
    triangle, or another that holds the point (on an edge they share)."""
    flange = trimesh.creation.box((2.0, 0.4, 0.05))
    mesh = trimesh.util.concatenate([flange, trimesh.creation.box((2.0, 0.05, 0.5)),
                                     flange.copy().apply_translation((0, 0, 0.5))])
    rng = make_rng(1, 0, Stream.GEOMETRY)
    points, faces = trimesh.sample.sample_surface(mesh, 4000, seed=int(rng.integers(1 << 31)))
    found = nearest_triangles(mesh.triangles, points)
    same = found == faces
    assert same.mean() > 0.99
    closest = trimesh.triangles.closest_point(mesh.triangles[found], points)
    assert np.abs(closest - points).max() < 1e-9
    # A zero-area triangle (no plane, no edges) is never the nearest.
    sliver = np.zeros((1, 3, 3))
    assert np.array_equal(nearest_triangles(np.concatenate([sliver, mesh.triangles]), points),
                          found + 1)
