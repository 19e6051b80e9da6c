import numpy as np
import pytest
from glhelpers import camera

from glsynth.world.environment import Part, PartKind
from glsynth.world.meshes import box, pose
from glsynth.world.visibility import visible_parts


def part(name, xyz, size=1.0):
    return Part(name, PartKind.COLUMN, None, box((size, size, size)), pose(0.3, xyz))


@pytest.mark.parametrize("name, xyz, seen", [
    ("ahead", (0, 0, -10), True),
    ("behind", (0, 0, 10), False),
    ("far_left", (-30, 0, -10), False),
    ("far_right", (30, 0, -10), False),
    ("far_up", (0, 30, -10), False),
    ("far_down", (0, -30, -10), False),
    ("straddles_near_plane", (0, 0, 0.2), True),
    ("just_inside_left_edge", (-5.5, 0, -10), True),
])
def test_frustum_cases(name, xyz, seen):
    # fx = width: the view spans x in [-d/2, d/2] at depth d.
    assert (name in visible_parts([part(name, xyz)], [camera()])) == seen


def test_union_over_cameras_and_environment_columns(env0):
    from glsynth.core.config import Config
    from glsynth.world.cameras import environment_camera

    cfg = Config()
    cams = [environment_camera(env0.trajectory, cfg.cameras, cfg.render, 0, 0, i).camera
            for i in range(100)]
    seen = visible_parts(env0.parts, cams)
    columns = [p.name for p in env0.parts if p.kind is PartKind.COLUMN]
    assert seen & set(columns)
    assert seen == set().union(*(visible_parts(env0.parts, [c]) for c in cams))
    one = visible_parts(env0.parts, cams[:1])
    assert one <= seen and len(one) < len(seen)
    turned = np.eye(4)
    turned[:3, :3] = [[1, 0, 0], [0, -1, 0], [0, 0, -1]]  # looking up the +z axis into the sky
    turned[:3, 3] = [0, 0, 500.0]
    assert visible_parts(env0.parts, [camera(pose=turned)]) == set()


@pytest.mark.parametrize("name, xyz, inside", [
    ("centre", (0, 0, 0), True),
    ("beyond_plus_x", (3, 0, 0), False),
    ("beyond_minus_y", (0, -3, 0), False),
    ("straddles_the_x_side", (1.2, 0, 0), True),
    ("beyond_in_depth", (0, 0, 50), True),  # depth is clamped in the shadow pass, never culled
])
def test_clip_volume_sides_in_x_and_y(name, xyz, inside):
    from glsynth.world.visibility import in_clip_xy, part_corners

    # An orthographic clip volume 4 m wide and tall around the origin (the sun's shadow map).
    ortho = np.diag([0.5, 0.5, -0.1, 1.0])
    corners = part_corners(part(name, xyz))[None]
    assert in_clip_xy(corners, ortho).tolist() == [inside]
