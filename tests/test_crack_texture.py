"""Cracks baked into a sparse coverage texture for the Cycles twin
(glsynth.render.crack_texture): the texel's share against an independent integral, the
texture on a column's faces read back as the Blender material reads it, the texel rule and its
bound, and the 16-bit encoding. Pure numpy."""

import numpy as np
import pytest

from glsynth.appearance.cracks import CrackNetwork
from glsynth.core.seeding import Stream, make_rng
from glsynth.render import crack_texture
from glsynth.render.crack_texture import (
    BLOCK,
    MAX_TEXELS,
    TEXELS_PER_FOOTPRINT,
    bake_for_views,
    bake_texture,
    decode,
    encode,
    finest_footprint,
    texel_coverage,
)
from glsynth.world import meshes
from glsynth.world.cameras import Camera

ROWS = 4000
"""Rows of the reference integral: its error is below 1e-5 of a texel's area."""


def strip_share(centre: np.ndarray, h: float, normal: np.ndarray, offset: float,
                width: float) -> np.ndarray:
    """The share of each square texel (centres (n, 2), edge h) inside the strip
    |p . normal - offset| <= width / 2, integrated row by row: exact along each row (an
    interval), midpoint rule across rows. Independent of texel_coverage's formula."""
    y = centre[:, 1:2] + ((np.arange(ROWS) + 0.5) / ROWS - 0.5) * h  # (n, ROWS)
    nx, ny = normal
    ends = np.stack([(offset - width / 2 - y * ny) / nx, (offset + width / 2 - y * ny) / nx])
    lo, hi = ends.min(0), ends.max(0)
    x0, x1 = centre[:, :1] - h / 2, centre[:, :1] + h / 2
    return np.clip(np.minimum(hi, x1) - np.maximum(lo, x0), 0, None).mean(1) / h


@pytest.mark.parametrize("width", [2.5, 1.0, 0.3, 0.05])
def test_a_texels_share_is_the_area_the_band_cuts_from_it(width):
    rng = make_rng(29, 0, Stream.DAMAGE, int(width * 100))
    angle = rng.uniform(0.05, np.pi / 2 - 0.05, 200) * rng.choice([-1, 1], 200)
    normal = np.stack([np.cos(angle), np.sin(angle)], 1)
    d = rng.uniform(0, width / 2 + 1.0, 200)
    share = texel_coverage(d, np.full(200, width), np.abs(normal[:, 0]), np.abs(normal[:, 1]))
    truth = np.array([strip_share(np.zeros((1, 2)), 1.0, n, di, width)[0]
                      for n, di in zip(normal, d)])
    assert np.abs(share - truth).max() < 1e-4 * max(width, 1.0)
    assert share.max() > 0 and share.min() == 0


def test_an_axis_aligned_band_is_its_overlap_with_the_texel():
    d = np.array([0.0, 0.4, 0.5, 0.6, 1.2])
    share = texel_coverage(d, np.full(5, 0.2), np.ones(5), np.zeros(5))
    assert share == pytest.approx([0.2, 0.2, 0.1, 0.0, 0.0])


def _column_network(width_m: float) -> tuple[CrackNetwork, np.ndarray, np.ndarray]:
    """On a 0.8 x 0.6 x 4 m column: a straight crack across the +x face at 30 degrees, and a
    crack turning the corner from the +x face onto the +y face; with the first's end points."""
    a, b = np.array([0.4, -0.25, 0.5]), np.array([0.4, 0.2, 0.5 + 0.45 * np.tan(np.pi / 6)])
    corner = np.array([0.4, 0.3, 1.2])
    points = np.array([[a, b], [[0.4, 0.0, 1.25], corner], [corner, [0.1, 0.3, 1.22]]])
    net = CrackNetwork(points, np.full((3, 2), width_m), np.array([0, 1, 1], np.int32),
                       ("shear", "flexural"))
    return net, a, b


BOX = meshes.box((0.8, 0.6, 4.0))
PLUS_X, PLUS_Y = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])


@pytest.mark.parametrize("width_mm", [2.0, 0.2, 0.05])
def test_the_texture_holds_the_exact_share_on_a_columns_faces(width_mm):
    width, h = width_mm / 1000, 1e-3
    net, a, b = _column_network(width)
    texture = bake_texture(net, BOX, h)
    assert sorted(tuple(g.normal) for g in texture.planes) == [(0, 1, 0), (1, 0, 0)]
    lengths = np.linalg.norm(net.points[:, 1] - net.points[:, 0], axis=1)
    assert texture.atlas.sum() * h * h == pytest.approx(width * lengths.sum(), rel=0.01)
    # Texel centres round the first crack, read as the material reads them
    face = next(g for g in texture.planes if g.normal[0] == 1.0)
    ends = np.stack([[p @ face.u_axis, p @ face.v_axis] for p in (a, b)])
    cols, rows = np.meshgrid(np.arange(0, 500), np.arange(0, 300))
    uv = face.corner + (np.stack([cols.ravel(), rows.ravel()], 1) + 0.5) * h
    along = (ends[1] - ends[0]) / np.linalg.norm(ends[1] - ends[0])
    t = (uv - ends[0]) @ along / np.linalg.norm(ends[1] - ends[0])
    normal = np.array([-along[1], along[0]])
    near = np.abs((uv - ends[0]) @ normal) < width / 2 + 2 * h
    span = (t > 0.05) & (t < 0.5)  # away from the tips and from the other crack
    points = face.offset * face.normal + uv[:, :1] * face.u_axis + uv[:, 1:] * face.v_axis
    got = texture.lookup(points, np.tile(PLUS_X, (len(points), 1)))
    truth = strip_share(uv[near & span] - ends[0], h, normal, 0.0, width)
    assert truth.sum() > 0 and np.abs(got[near & span] - truth).max() < 1e-4
    assert not got[~near & span].any()
    # The same points seen from another face's side, or on the opposite face: no crack
    assert not texture.lookup(points, np.tile(PLUS_Y, (len(points), 1))).any()
    assert not texture.lookup(points * [-1, 1, 1], np.tile(-PLUS_X, (len(points), 1))).any()


def test_a_plane_reads_no_other_planes_blocks():
    net, _, _ = _column_network(2e-3)
    texture = bake_texture(net, BOX, 1e-3)
    # Along the +x face's horizontal line through the first crack, far beyond its grid: the
    # clamp keeps the point in the plane's own empty border column
    z = 0.5 + 0.25 * np.tan(np.pi / 6)
    y = np.linspace(-0.3, 0.3, 6001)
    points = np.stack([np.full_like(y, 0.4), y, np.full_like(y, z)], 1)
    got = texture.lookup(points, np.tile(PLUS_X, (len(y), 1)))
    assert 0 < got.sum() * 1e-4 < 3 * 2e-3 / np.cos(np.pi / 6)
    far = np.stack([np.full(5, 0.4), np.full(5, 0.29), np.linspace(-1.9, 1.9, 5)], 1)
    assert not texture.lookup(far * [1, 40, 1], np.tile(PLUS_X, (5, 1))).any()
    assert texture.indirection[:, 0].max() == 0


def _camera(distance_m: float, width: int = 1920, focal_mm: float = 36.0) -> Camera:
    pose = np.eye(4)
    pose[:3, :3] = [[0, 0, 1], [1, 0, 0], [0, 1, 0]]  # looking down -x onto the +x face
    pose[:3, 3] = [0.4 + distance_m, 0.0, 0.8]
    return Camera(width, width * 9 // 16, focal_mm, 36.0, pose, 0.05, 2000.0)


def test_texels_are_half_the_finest_pixel_footprint_within_the_bound():
    net, _, _ = _column_network(1e-3)
    box, pose = BOX, np.eye(4)
    pose[:3, 3] = [10.0, -3.0, 4.0]
    cams = [_camera(8.0), _camera(3.0)]
    for cam in cams:
        cam.pose[:3, 3] += pose[:3, 3]
    nearest = 3.0  # the +x face's first crack passes 3.002 m from the nearer camera
    assert finest_footprint(net, pose, cams) == pytest.approx(nearest / 1920, rel=0.02)
    # A camera 0.5 m away that looks away from the cracks sets nothing, unless it is alone
    away = _camera(0.5)
    away.pose[:3, :3] = away.pose[:3, :3] @ np.diag([-1.0, 1.0, -1.0])
    away.pose[:3, 3] += pose[:3, 3]
    assert finest_footprint(net, pose, cams + [away]) == finest_footprint(net, pose, cams)
    assert finest_footprint(net, pose, [away]) == pytest.approx(0.5 / 1920, rel=0.1)
    [texture] = bake_for_views([(net, box, pose)], cams)
    assert texture.texel_m == pytest.approx(nearest / 1920 / TEXELS_PER_FOOTPRINT, rel=0.02)
    assert texture.texels < 2e5  # the cracks' blocks only, not the faces
    used = np.sort(texture.indirection[texture.indirection > 0])
    assert np.array_equal(used, np.arange(1, len(used) + 1))  # each block stored once
    assert texture.atlas.shape[0] // BLOCK == np.ceil(np.sqrt(len(used) + 1))


def test_a_close_view_is_bounded(monkeypatch):
    # 0.3 m away with a 105 mm lens: 0.06 mm pixels give these 1.1 m of cracks 5.0 M texels,
    # more than a quarter of the bound (4.2 M): the texels grow
    monkeypatch.setattr(crack_texture, "MAX_TEXELS", MAX_TEXELS // 4)
    net, _, _ = _column_network(1e-3)
    close = [_camera(0.3, focal_mm=105.0)]
    [texture] = bake_for_views([(net, BOX, np.eye(4))], close)
    assert texture.texel_m > finest_footprint(net, np.eye(4), close) / TEXELS_PER_FOOTPRINT
    assert MAX_TEXELS // 4 / 1.25 ** 2 < texture.texels <= MAX_TEXELS // 4


def test_the_bound_is_shared_by_the_jobs_members(monkeypatch):
    monkeypatch.setattr(crack_texture, "MAX_TEXELS", 200_000)
    net, _, _ = _column_network(1e-3)
    cams = [_camera(1.0)]
    [one] = bake_for_views([(net, BOX, np.eye(4))], cams)
    two = bake_for_views([(net, BOX, np.eye(4))] * 2, cams)
    assert two[0].texel_m == two[1].texel_m > one.texel_m
    assert two[0].texels * 2 <= 200_000 < one.texels * 2


def test_coverage_survives_the_16_bit_encoding():
    random = make_rng(29, 0, Stream.DAMAGE).random(96)
    coverage = np.concatenate([[0.0, 1.0, 1 / 65280, 0.5], random])
    tile = coverage.reshape(10, 10)
    image = encode(tile)
    assert image.dtype == np.uint8 and image.shape == (10, 10, 3)
    assert np.abs(decode(image) - tile).max() <= 0.5 / 65280 + 1e-12
    assert np.array_equal(encode(tile)[0], encode(tile[::-1])[-1])  # PNG rows: top first
    blocks = encode(np.array([[0, 1, 255, 256, 65535]]), 1)
    assert (blocks[0, :, 0].astype(int) * 256 + blocks[0, :, 1]).tolist() == [0, 1, 255, 256,
                                                                               65535]
    with pytest.raises(ValueError, match="16 bits"):
        encode(np.array([[65536]]), 1)


def test_a_curved_girders_cracks_read_back_from_their_own_facets():
    """A girder at the tightest radius is flat pieces a hundredth of a radian apart, several
    within the lookup's millimetre of a point near their joints: each crack's centreline,
    read as the Blender material reads it, finds coverage from the nearest facet's texels,
    as a flat face's does (summing the planes in reach read wrong texels)."""
    from test_girder_cracks import cracks_of, curved_env, tightest_girders

    env = curved_env()
    part = tightest_girders(env)[0]
    every = cracks_of(env, part, 1)
    # Every fifth of the cracks that have segments two texels wide: 12 cracks over 24 facets
    # bake in 4 s (all 189 took a minute); the facets and the lookup are what is tested.
    chosen = np.unique(every.crack[every.widths_m.min(1) >= 4e-4])[::5]
    keep = np.isin(every.crack, chosen)
    net = CrackNetwork(every.points[keep], every.widths_m[keep],
                       np.searchsorted(chosen, every.crack[keep]).astype(np.int32),
                       tuple(every.kinds[i] for i in chosen))
    texture = bake_texture(net, part.mesh, 2e-4)
    ends = net.points
    mid = (ends[:, 0] + ends[:, 1]) / 2
    face_normals = np.asarray(part.mesh.face_normals)
    corners = np.asarray(part.mesh.vertices)[part.mesh.faces[:, 0]]
    gap = np.abs(mid @ face_normals.T - np.einsum("ij,ij->i", face_normals, corners))
    normals = face_normals[np.argmin(gap, axis=1)]  # a face whose plane holds the point
    got = texture.lookup(mid, normals)
    wide = net.widths_m.min(1) >= 4e-4  # two texels and more: the centre texel is covered
    assert wide.sum() > 50
    assert np.all((got >= 0) & (got <= 1))
    assert np.mean(got[wide] > 0.5) > 0.95
