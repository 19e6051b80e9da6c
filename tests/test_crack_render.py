"""Cracks on rendered data (docs/design.md, "Cracks"): the width map, the labelling rule and
the darkening, on small scenes with known geometry. The camera sits at the origin looking down
-z with fx = width, so a fronto-parallel surface z metres away has pixels z / width metres
wide; the part's mesh frame is the world's, so crack points are given where they are seen."""

import numpy as np
import pytest
import trimesh
from glhelpers import LIGHT, camera, quad, render_config, scene_of
from scipy import ndimage

from glsynth.appearance.cracks import CrackNetwork
from glsynth.appearance.materials import Material, srgb_decode
from glsynth.core.labels import Component, Damage
from glsynth.render.cracks_index import CRACK_CONTRAST, crack_contrast
from glsynth.render.gl.renderer import Renderer
from glsynth.world.meshes import box

W, H = 160, 120
GREY = (0.25, 0.25, 0.25, 1.0)
"""Mid-grey concrete: the colour stays far from both ends of 8 bits."""


@pytest.fixture(scope="module")
def renderer():
    with Renderer(render_config(W, H)) as r:
        yield r
        assert r.ctx.error == "GL_NO_ERROR"


def network(points, widths_m) -> CrackNetwork:
    """One crack of straight segments (N, 2, 3) with their end widths (N, 2) in metres."""
    points = np.asarray(points, np.float64)
    return CrackNetwork(points, np.broadcast_to(np.asarray(widths_m, np.float64),
                                                points.shape[:2]).copy(),
                        np.zeros(len(points), np.int32), ("flexural",))


def render(renderer, mesh, cracks, cam=None):
    """The renders of ``mesh`` (labelled a column) without and with ``cracks``."""
    outs = []
    for net in (None, cracks):
        renderer.load(scene_of(("part", Component.COLUMN, mesh,
                                Material(base_color=GREY, cracks=net))), LIGHT)
        outs.append(renderer.render(cam or camera(W, H)))
    return outs


def plane(z: float, half: float | None = None) -> trimesh.Trimesh:
    """A fronto-parallel plane z metres away, filling the view."""
    h = half or z
    return quad([[-h, -h, -z], [h, -h, -z], [h, h, -z], [-h, h, -z]])


def darkening(out, base) -> np.ndarray:
    """(H, W) the share of the crack-free render's light that the cracks take away."""
    lit, unlit = srgb_decode(out.color).mean(2), srgb_decode(base.color).mean(2)
    return 1.0 - lit / unlit


def vertical_crack(z: float, width_m: float, x_px: float = 80.3) -> CrackNetwork:
    """A crack along the image's columns at image column ``x_px`` (pixel centres at .0),
    through the whole height, on the plane z metres away."""
    x = (x_px - (W - 1) / 2) * z / W
    return network([[[x, -z, -z], [x, z, -z]]], width_m)


@pytest.mark.parametrize("z", [1.0, 1.1])
def test_a_straight_crack_has_its_width_and_darkens_by_its_share_of_each_pixel(renderer, z):
    w = 2e-3
    net = vertical_crack(z, w)
    base, out = render(renderer, plane(z), net)
    crack = out.damage == Damage.CONCRETE
    assert np.array_equal(base.damage, np.full((H, W), Damage.NO_DAMAGE))
    assert np.all(out.crack_width[crack] == np.float32(w * 1000)) and crack.sum() >= H
    assert not out.crack_width[~crack].any() and not base.crack_width.any()
    per_row = darkening(out, base).sum(1)
    expected = crack_contrast(net) * w / (z / W)
    assert np.abs(per_row / expected - 1).max() <= 0.10
    # Away from the crack, not a byte changes.
    far = np.abs(np.arange(W) - 80.3) > 4
    assert np.array_equal(out.color[:, far], base.color[:, far])


def test_each_crack_network_darkens_by_its_own_contrast(renderer):
    """A network's contrast lies in CRACK_CONTRAST's range, is the same for the same network
    and differs between networks (here by more than a tenth); two members in one view, the
    left half and the right, each darken by their own."""
    z, widths = 1.0, (2.0e-3, 2.1e-3)
    nets = [vertical_crack(z, w, x) for w, x in zip(widths, (40.3, 120.3), strict=True)]
    contrasts = [crack_contrast(n) for n in nets]
    assert all(CRACK_CONTRAST[0] <= c <= CRACK_CONTRAST[1] for c in contrasts)
    assert crack_contrast(vertical_crack(z, widths[0])) == contrasts[0]
    assert abs(contrasts[1] - contrasts[0]) > 0.1
    x_mid = 0.0  # on the plane, between image columns 79 and 80
    halves = [quad([[-z, -z, -z], [x_mid, -z, -z], [x_mid, z, -z], [-z, z, -z]]),
              quad([[x_mid, -z, -z], [z, -z, -z], [z, z, -z], [x_mid, z, -z]])]
    outs = []
    for cracks in ((None, None), nets):
        items = [(f"member_{i}", Component.COLUMN, mesh, Material(base_color=GREY, cracks=c))
                 for i, (mesh, c) in enumerate(zip(halves, cracks, strict=True))]
        renderer.load(scene_of(*items), LIGHT)
        outs.append(renderer.render(camera(W, H)))
    per_row = darkening(outs[1], outs[0])
    for w, contrast, columns in zip(widths, contrasts, (slice(0, W // 2), slice(W // 2, W)),
                                    strict=True):
        expected = contrast * w / (z / W)
        assert np.abs(per_row[:, columns].sum(1) / expected - 1).max() <= 0.10


def test_the_darkening_per_unit_length_is_the_same_at_1_and_1_1_m(renderer):
    w = 1e-3
    per_length = []
    for z in (1.0, 1.1):
        base, out = render(renderer, plane(z), vertical_crack(z, w))
        # Darkened area on the surface per metre of crack: sum of darkening x pixel area over
        # the crack's length in view (H pixels of z / W).
        per_length.append(darkening(out, base).sum() * (z / W) ** 2 / (H * z / W))
    assert per_length[1] == pytest.approx(per_length[0], rel=0.05)
    assert per_length[0] == pytest.approx(crack_contrast(vertical_crack(1.0, w)) * w, rel=0.10)


def test_a_tenth_of_a_pixel_crack_is_labelled_on_every_centreline_pixel(renderer):
    """A slanted crack 0.1 px wide: every pixel its centreline crosses is labelled, the label
    never breaks, and its mean darkening per row is coverage x contrast."""
    z = 1.0
    s = z / W
    # From above the image to below it, in pixels from the image's centre.
    top, bottom = np.array([-35.3, 70.0]) * s, np.array([29.9, -70.0]) * s
    net = network([[[top[0], top[1], -z], [bottom[0], bottom[1], -z]]], 0.1 * s)
    base, out = render(renderer, plane(z), net)
    crack = out.damage == Damage.CONCRETE
    labels, count = ndimage.label(crack)  # 4-connected
    assert count == 1
    # The centreline at 64 points per pixel row: each point's pixel is labelled.
    t = np.linspace(0, 1, 140 * 64)
    x = (top[0] + t * (bottom[0] - top[0])) / s + (W - 1) / 2
    y = (H - 1) / 2 - (top[1] + t * (bottom[1] - top[1])) / s
    inside = (y > -0.5) & (y < H - 0.5)
    assert crack[np.floor(y[inside] + 0.5).astype(int), np.floor(x[inside] + 0.5).astype(int)]\
        .all()
    # Coverage across the crack: 0.1 px / cos(slant) of each row (the row crosses the crack
    # obliquely), times the contrast; per row within 10 % on average over the rows.
    dx, dy = bottom - top
    across_row = 0.1 * np.hypot(dx, dy) / abs(dy)
    rows = slice(int((H - 1) / 2 - 50), int((H - 1) / 2 + 50))
    per_row = darkening(out, base)[rows].sum(1)
    assert per_row.mean() == pytest.approx(crack_contrast(net) * across_row, rel=0.10)
    assert np.all(out.crack_width[crack] == np.float32(0.1 * s * 1000))


def test_a_crack_at_a_grazing_angle_stays_continuous_and_keeps_its_width(renderer):
    """The plane turned 78 degrees from the view; the crack runs down its slope, away from
    the camera."""
    angle = np.radians(78.0)
    slope = np.array([0.0, np.cos(angle), -np.sin(angle)])  # up the plane, away from the eye
    centre = np.array([0.0, -0.1, -1.0])
    across = np.array([1.0, 0.0, 0.0])
    corners = [centre + a * across * 0.6 + b * slope * 2.0 for a, b in
               ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    w = 0.5e-3
    net = network([[centre - 2.5 * slope + 0.001 * across, centre + 2.5 * slope]], w)
    base, out = render(renderer, quad(corners), net)
    crack = out.damage == Damage.CONCRETE
    labels, count = ndimage.label(crack)
    assert count == 1
    rows = np.nonzero(crack.any(1))[0]
    seen = np.nonzero((base.depth < 1000).any(1))[0]
    assert rows.min() == seen.min() and rows.max() == seen.max()  # the whole plane in view
    assert np.all(out.crack_width[crack] == np.float32(w * 1000))
    assert not out.crack_width[~crack].any()


def test_a_crack_turning_a_columns_corner_is_continuous_across_the_edge(renderer):
    """A 0.6 m square column seen on its corner; a horizontal crack on face x = +0.3 meets
    the edge and turns onto face y = +0.3."""
    a = 0.3
    mesh = box((2 * a, 2 * a, 3.0))
    # Camera 2.5 m out along the diagonal, looking at the edge (x = y = a).
    eye = np.array([2.0, 2.0, 0.0])
    forward = -eye / np.linalg.norm(eye)
    pose = np.eye(4)
    pose[:3, 2] = -forward
    pose[:3, 0] = np.cross([0, 0, 1.0], pose[:3, 2])
    pose[:3, 1] = [0, 0, 1.0]
    pose[:3, 3] = eye
    z = 0.05
    net = network([[[a, -0.2, z], [a, a, z + 0.02]], [[a, a, z + 0.02], [-0.2, a, z]]],
                  [[0.3e-3, 0.6e-3], [0.6e-3, 0.3e-3]])
    base, out = render(renderer, mesh, net, camera(W, H, pose=pose))
    crack = out.damage == Damage.CONCRETE
    labels, count = ndimage.label(crack)
    assert count == 1
    edge = W // 2  # the edge projects onto the image's centre column
    columns = np.nonzero(crack.any(0))[0]
    assert columns.min() < edge - 15 and columns.max() > edge + 15
    assert out.crack_width[crack].min() >= 0.3 - 1e-6
    assert out.crack_width[crack].max() <= 0.6 + 1e-6


def test_no_cracks_in_view_keeps_every_byte(renderer):
    """A material whose cracks lie outside the view draws through the crack variants and
    gives the crack-free render's bytes."""
    z = 1.0
    far_away = network([[[0.0, 5.0, -z], [0.2, 5.0, -z]]], 1e-3)
    base, out = render(renderer, plane(z, 6.0), far_away)
    for name in ("color", "component", "damage", "depth", "crack_width"):
        assert np.array_equal(getattr(out, name), getattr(base, name)), name
    assert not out.crack_width.any() and out.crack_width.dtype == np.float32


@pytest.mark.parametrize(("w", "z"), [(0.05e-3, 0.3), (0.05e-3, 16.0), (5e-3, 0.3),
                                      (5e-3, 16.0)])
def test_widths_at_both_ends_near_and_far(renderer, w, z):
    """0.05 and 5 mm cracks at 0.3 m (1.9 mm pixels) and 16 m (100 mm pixels: the grid's
    reach, |dp/dx| + |dp/dy| up to four cell edges) are labelled on every row with their
    width, and darken by w / pixel x contrast."""
    net = vertical_crack(z, w)
    base, out = render(renderer, plane(z), net)
    crack = out.damage == Damage.CONCRETE
    assert crack.any(1).all() and ndimage.label(crack)[1] == 1
    assert np.all(out.crack_width[crack] == np.float32(w * 1000))
    expected = crack_contrast(net) * w / (z / W)
    per_row = darkening(out, base).sum(1)
    # Below one 8-bit step (about 1 % of the light here) darkening cannot be measured.
    assert np.abs(per_row - expected).max() <= max(0.10 * expected, 0.03)


def test_under_msaa_a_crack_darkens_as_without_it():
    """The multisample resolve takes colours shaded at pixel centres, whose coverage already
    integrates the pixel: across a crack on a tilted plane the darkening per row is the same
    as without MSAA, within 10 %."""
    z, w = 1.0, 1e-3
    corners = [[-1.0, -1.0, -z - 0.3], [1.0, -1.0, -z - 0.3], [1.0, 1.0, -z + 0.3],
               [-1.0, 1.0, -z + 0.3]]
    crack = network([[[0.0013, -1.0, -z - 0.3], [0.0013, 1.0, -z + 0.3]]], w)
    per_row = []
    for msaa in (0, 4):
        with Renderer(render_config(W, H, msaa)) as r:
            base, out = render(r, quad(corners), crack)
            assert r.ctx.error == "GL_NO_ERROR"
        per_row.append(darkening(out, base).sum(1))
        assert np.all(out.crack_width[out.damage == Damage.CONCRETE] == np.float32(w * 1000))
    assert np.abs(per_row[1] / per_row[0] - 1).max() <= 0.10
    assert per_row[0].min() > 0.1


def test_a_crack_far_from_the_mesh_frames_origin_renders_as_near_it(renderer):
    """A girder's mesh frame is the world frame: the plane, its 0.05 mm crack and the camera
    moved 700 m from the origin (a float32 coordinate there is good to 30 um) label the same
    pixels with the same width and darken them as at the origin, through a 105 mm lens at
    0.3 m (0.64 mm pixels)."""
    z, w, shift = 0.3, 0.05e-3, np.array([700.0, -400.0, 25.0])
    fx = W * 105.0 / 36.0
    x = (80.3 - (W - 1) / 2) * z / fx
    outs = []
    for offset in (np.zeros(3), shift):
        mesh = plane(z).copy()
        mesh.vertices = mesh.vertices + offset
        net = network([[[x, -z, -z] + offset, [x, z, -z] + offset]], w)
        pose = np.eye(4)
        pose[:3, 3] = offset
        base, out = render(renderer, mesh, net, camera(W, H, focal_mm=105.0, pose=pose))
        outs.append((out, darkening(out, base).sum(1)))
    (near, near_rows), (far, far_rows) = outs
    crack = near.damage == Damage.CONCRETE
    assert crack.any(1).all()
    assert np.array_equal(far.damage, near.damage)
    assert np.array_equal(far.crack_width, near.crack_width)
    expected = crack_contrast(net) * w / (z / fx)
    assert np.abs(near_rows / expected - 1).max() <= 0.10
    assert np.abs(far_rows - near_rows).max() <= 0.02 * expected


def test_cracks_are_uploaded_when_a_view_first_shows_their_part(renderer):
    """Two cracked planes, one before the camera and one behind it: loading packs neither,
    a view packs the one it shows, prepare_cracks packs the rest, and the bytes of a view
    do not depend on which were packed before it."""
    z = 1.0
    behind = np.diag([-1.0, 1.0, -1.0, 1.0])  # turned half about y: looks down +z
    crack = vertical_crack(z, 2e-3)
    turned = network(crack.points * [-1.0, 1.0, -1.0], crack.widths_m)
    renderer.load(scene_of(
        ("front", Component.COLUMN, plane(z), Material(base_color=GREY, cracks=crack)),
        ("back", Component.COLUMN, plane(z).apply_transform(behind),
         Material(base_color=GREY, cracks=turned))), LIGHT)
    assert renderer.prepare_cracks(limit=0) == 2
    lazy = renderer.render(camera(W, H))
    assert renderer.prepare_cracks(limit=0) == 1
    assert renderer.prepare_cracks() == 0
    eager = renderer.render(camera(W, H))
    for name in ("color", "component", "damage", "depth", "crack_width"):
        assert np.array_equal(getattr(lazy, name), getattr(eager, name)), name
    assert (lazy.damage == Damage.CONCRETE).sum() >= H
    back = renderer.render(camera(W, H, pose=behind))
    assert (back.damage == Damage.CONCRETE).sum() >= H
