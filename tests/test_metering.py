"""The face meter's sight lines (glsynth.appearance.metering.blocked): parts hide light by
their triangles, not by their boxes."""

import numpy as np

from glsynth.appearance.metering import blocked
from glsynth.world import meshes
from glsynth.world.environment import Part, PartKind
from glsynth.world.visibility import rays_meet_triangles


def _diagonal_slab() -> Part:
    """A 40 x 10 x 0.3 m slab 8 m up, run at 45 degrees to the world axes and baked into
    world vertices (identity pose), as the parts swept along the track are."""
    mesh = meshes.box((40.0, 10.0, 0.3))
    mesh.apply_transform(meshes.pose(np.pi / 4, [0.0, 0.0, 8.0]))
    return Part("slab_v00", PartKind.SLAB, 0, mesh, np.eye(4))


def test_a_swept_slab_hides_only_what_lies_under_it_not_its_box():
    slab = _diagonal_slab()
    up = np.array([[0.0, 0.0, 1.0]])
    under = np.array([0.0, 0.0, 2.0])
    # Inside the slab's world box (a 35 m square) but 12 m off its diagonal: open sky.
    beside = np.array([12.0 / np.sqrt(2), -12.0 / np.sqrt(2), 2.0])
    lo, hi = slab.mesh.bounds
    assert np.all(lo[:2] <= beside[:2]) and np.all(beside[:2] <= hi[:2])
    assert blocked(under, up, [slab]).tolist() == [True]
    assert blocked(beside, up, [slab]).tolist() == [False]
    # A ray from beside that slants across the slab is hidden; one that slants away is not.
    towards = np.array([[-0.6, 0.6, 0.4]]) / np.linalg.norm([-0.6, 0.6, 0.4])
    assert blocked(beside, np.concatenate([towards, -towards * [1, 1, -1]]),
                   [slab]).tolist() == [True, False]


def test_rays_meet_triangles_both_sides_forward_only():
    tri = np.array([[[-1.0, -1.0, 1.0], [1.0, -1.0, 1.0], [0.0, 1.0, 1.0]]])
    dirs = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
    assert rays_meet_triangles(np.zeros(3), dirs, tri).tolist() == [True, False, False]
    assert rays_meet_triangles(np.array([0.0, 0.0, 2.0]), dirs, tri).tolist() == \
        [False, True, False]
