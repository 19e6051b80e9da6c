"""The face meter's box test over many posed parts at once (glsynth.appearance.metering.blocked,
part_boxes): a ray is hidden exactly where it meets some part's triangles."""

import numpy as np

from glsynth.appearance.metering import blocked, hemisphere, part_boxes
from glsynth.world import meshes
from glsynth.world.environment import Part, PartKind
from glsynth.world.visibility import rays_meet_triangles


def _posed_boxes() -> list[Part]:
    """Twelve boxes of several sizes on a ring 5 m around the origin, from 1 to 8 m up, each
    turned about z and x and moved by its own pose (mesh frame != world), as members are."""
    parts = []
    for i in range(12):
        mesh = meshes.box((1.0 + 0.2 * i, 2.5 - 0.1 * i, 0.5 + 0.3 * (i % 4)))
        angle = i * np.pi / 6
        pose = meshes.pose(0.7 * i, [5 * np.cos(angle), 5 * np.sin(angle), 1.0 + 0.6 * i])
        tilt = np.eye(4)
        c, s = np.cos(0.4 * i), np.sin(0.4 * i)
        tilt[1:3, 1:3] = [[c, -s], [s, c]]
        parts.append(Part(f"column_{i}", PartKind.COLUMN, 0, mesh, pose @ tilt))
    return parts


def test_many_posed_parts_hide_a_ray_where_their_triangles_do():
    parts = _posed_boxes()
    origin = np.array([0.2, -0.1, 0.5])
    dirs = np.concatenate([hemisphere(np.array([0.0, 0.0, 1.0])),
                           hemisphere(np.array([1.0, 0.0, 0.0]))])
    triangles = np.concatenate([p.world_vertices()[p.mesh.faces] for p in parts])
    truth = rays_meet_triangles(origin, dirs, triangles)
    assert 0.1 < truth.mean() < 0.9  # some hidden, some open: the test can tell
    assert np.array_equal(blocked(origin, dirs, parts), truth)
    assert np.array_equal(blocked(origin, dirs, parts, part_boxes(parts)), truth)
    one_by_one = np.any([blocked(origin, dirs, [p]) for p in parts], axis=0)
    assert np.array_equal(one_by_one, truth)
    assert not blocked(origin, dirs, []).any()
