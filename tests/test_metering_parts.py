"""The face meter's box test over many posed parts at once (glsynth.appearance.metering.blocked,
part_boxes): a ray is hidden exactly where it meets some part's triangles; and a face's
irradiance, cast once for the sun and both skies, is each cast's on its own."""

import dataclasses

import numpy as np
import pytest

from glsynth.appearance.metering import (
    FACE_NORMALS,
    LIFT_M,
    blocked,
    face_irradiance,
    hemisphere,
    part_boxes,
)
from glsynth.core.config import load_config
from glsynth.world import meshes
from glsynth.world.cameras import FaceAim
from glsynth.world.environment import Part, PartKind
from glsynth.world.lighting import Lighting, environment_lighting, sh_basis
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


def _irradiance_cast_by_cast(aim: FaceAim, member: Part, others: list[Part],
                             lighting: Lighting) -> np.ndarray:
    """face_irradiance as three casts against the other parts, each on its own."""
    normal = member.pose[:3, :3] @ np.array(FACE_NORMALS[aim.face])
    origin = np.asarray(aim.point) + LIFT_M * normal
    sun = lighting.sun_direction
    sun_share = lighting.sun_irradiance * max(float(sun @ normal), 0.0)
    if blocked(origin, sun[None], others)[0]:
        sun_share = 0.0
    seen = hemisphere(normal)
    seen = seen[seen[:, 2] > 0.0]
    face_open = 1.0 - blocked(origin, seen, others).mean() if len(seen) else 0.0
    point_open = 1.0 - blocked(origin, hemisphere(np.array([0.0, 0.0, 1.0])), others).mean()
    sky_sh, ground_sh = lighting.irradiance_sh()
    basis = sh_basis(normal[None])[0]
    return sun_share + (np.maximum(basis @ sky_sh, 0.0) * face_open
                        + np.maximum(basis @ ground_sh, 0.0) * (0.25 + 0.75 * point_open))


def test_a_faces_irradiance_is_its_three_casts_each_on_its_own():
    """A column's faces among the ring of posed boxes, with the sun (30 degrees up, along +x)
    on the +x face, once hidden by a box 4 m towards it and once not: the sun hidden or not,
    the face's and the point's open sky, each cast on its own against the other parts (the
    aimed member itself left out), give the irradiance that face_irradiance finds in one
    cast, with part_boxes gathered by it or handed in."""
    config = load_config("inspection").lighting
    lighting = environment_lighting(dataclasses.replace(
        config, sun_elevation_deg=(30.0, 30.0), sun_azimuth_deg=(0.0, 0.0)), 0, 0)
    member = Part("column_x", PartKind.COLUMN, 0, meshes.box((1.0, 1.0, 4.0)),
                  meshes.pose(0.0, [0.0, 0.0, 2.0]))
    point = np.array([0.5, 0.0, 2.0])
    blocker = Part("blocker", PartKind.COLUMN, 0, meshes.box((1.0, 1.0, 1.0)),
                   meshes.pose(0.0, point + 4.0 * lighting.sun_direction))
    found = {}
    for name, others in (("lit", _posed_boxes()), ("shaded", _posed_boxes() + [blocker])):
        parts = [member] + others
        for face in ("+x", "-y", "-z"):
            aim = FaceAim(member.name, face, tuple(point), 1.0, 0.0, 0.0, 1)
            expected = _irradiance_cast_by_cast(aim, member, others, lighting)
            assert np.array_equal(face_irradiance(aim, parts, lighting), expected), face
            assert np.array_equal(face_irradiance(aim, parts, lighting, part_boxes(parts)),
                                  expected)
            found[name, face] = expected
    # The sun reaches the +x face only without the blocker: the cases can tell the casts apart.
    sun_on_face = lighting.sun_irradiance * lighting.sun_direction[0]
    assert found["lit", "+x"] - found["shaded", "+x"] == pytest.approx([sun_on_face] * 3,
                                                                        rel=0.05)


def test_a_ray_in_a_boxs_side_plane_reaches_the_triangles():
    """A ray running in the plane of a box's side (its slab test divides 0 by 0 there) grazes
    the box's edges, which the triangle test counts as met: the NaN is left out of the slab
    test, not let decide it."""
    box = Part("column", PartKind.COLUMN, 0, meshes.box((2.0, 2.0, 2.0)), np.eye(4))
    triangles = box.world_vertices()[box.mesh.faces]
    up = np.array([[0.0, 0.0, 1.0]])
    for origin in ([-1.0, 0.3, -5.0], [1.0, -0.5, -5.0]):  # in the planes x = -1 and x = 1
        assert rays_meet_triangles(np.array(origin), up, triangles).tolist() == [True]
        assert blocked(np.array(origin), up, [box]).tolist() == [True]
