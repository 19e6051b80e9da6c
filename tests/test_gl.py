"""Renderer tests on Mesa (llvmpipe in CI) at small sizes, against analytic depth, a CPU ray
cast (trimesh) and constructed label textures. The GL error state is checked around each test."""

import itertools
import re

import numpy as np
import pytest
import trimesh
from glhelpers import (
    LIGHT,
    camera,
    pixel_plate,
    plain_materials,
    quad,
    render_config,
    render_once,
    scene_of,
)
from trimesh.visual import TextureVisuals

from glsynth.appearance.materials import Material, plain_material
from glsynth.core.errors import UserError
from glsynth.core.labels import Component, Damage
from glsynth.core.paths import shader_dir
from glsynth.core.seeding import Stream, make_rng
from glsynth.render.gl import context as gl_context
from glsynth.render.gl.programs import PROGRAMS, shader_source
from glsynth.render.gl.renderer import Renderer

PLAIN = Material(base_color=(0.6, 0.6, 0.6, 1.0))


@pytest.fixture(scope="module")
def renderer():
    with Renderer(render_config(64, 48)) as r:
        yield r


@pytest.fixture(autouse=True)
def gl_clean(request):
    if "renderer" not in request.fixturenames:
        yield
        return
    r = request.getfixturevalue("renderer")
    assert r.ctx.error == "GL_NO_ERROR"
    yield
    assert r.ctx.error == "GL_NO_ERROR"


def test_every_shader_compiles_and_every_file_is_used(renderer):
    # Every combination of each program's variant flags that Variant.compiled allows is
    # compiled: 4 label, 8 + 1 colour (the ground's) and 8 plain ones.
    assert len(renderer.programs.keys()) == 21
    assert {name for name, _ in renderer.programs.keys()} == set(PROGRAMS)
    used = {f for vert, frag, _ in PROGRAMS.values() for f in (vert, frag)}
    included, pending = set(), set(used)
    while pending:  # includes may include (weathering.glsl includes concrete_detail.glsl)
        found = {m for f in pending for m in re.findall(r'#include "([\w.]+)"',
                                                        (shader_dir() / f).read_text())}
        pending = found - included
        included |= found
    on_disk = {p.name for p in shader_dir().iterdir() if p.suffix in {".vert", ".frag", ".glsl"}}
    assert on_disk == used | included
    assert "#include" not in shader_source("color.frag")  # expanded before compiling


@pytest.mark.parametrize("distance", [0.5, 5.0, 30.0, 100.0, 1000.0])
def test_fronto_parallel_plane_depth_is_exact(renderer, distance):
    h = 2.0 * distance
    plane = quad([[-h, -h, -distance], [h, -h, -distance], [h, h, -distance],
                  [-h, h, -distance]])
    renderer.load(scene_of(("slab_plane", Component.SLAB, plane, PLAIN)), LIGHT)
    out = renderer.render(camera())
    assert out.depth.dtype == np.float32
    # Float32 precision: within 2 ulp of the exact distance, everywhere.
    assert np.abs(out.depth - distance).max() <= 2 * np.spacing(np.float32(distance))
    assert np.all(out.component == Component.SLAB)


@pytest.mark.parametrize("distance", [0.5, 5.0, 30.0, 100.0])
def test_tilted_plane_matches_ray_plane_intersection(renderer, distance):
    # Plane through (0, 0, -d) turned 45 degrees about y.
    n = np.array([np.sin(np.pi / 4), 0.0, np.cos(np.pi / 4)])
    u = np.array([np.cos(np.pi / 4), 0.0, -np.sin(np.pi / 4)])
    v = np.array([0.0, 1.0, 0.0])
    p0 = np.array([0.0, 0.0, -distance])
    s = 3.0 * distance
    corners = [p0 - s * u - s * v, p0 + s * u - s * v, p0 + s * u + s * v, p0 - s * u + s * v]
    renderer.load(scene_of(("beam_tilted", Component.BEAM, quad(corners), PLAIN)), LIGHT)
    cam = camera()
    out = renderer.render(cam)
    _, dirs = cam.rays()
    t = (n @ p0) / (dirs @ n)  # dirs have unit length along the optical axis: t is depth
    hit = out.component == Component.BEAM
    assert hit.mean() > 0.9
    assert np.allclose(out.depth[hit], t[hit], rtol=2e-6, atol=0)


def test_image_labels_and_depth_are_aligned(renderer):
    """An asymmetric scene: one box in the upper left of the view; a flip of rows or columns
    in any output would move it elsewhere."""
    from glsynth.world.meshes import box, pose

    b = box((1.0, 1.0, 1.0))
    b.apply_transform(pose(0.0, [-2.0, 1.2, -8.0]))
    renderer.load(scene_of(("column_box", Component.COLUMN, b,
                            Material(base_color=(1.0, 0.2, 0.1, 1.0)))), LIGHT)
    out = renderer.render(camera())
    hit = out.component == Component.COLUMN
    rows, cols = np.nonzero(hit)
    assert 0 < rows.max() < 24 and 0 < cols.max() < 32  # upper-left quadrant only
    assert np.array_equal(hit, out.depth < 1000.0)
    red = (out.color[..., 0].astype(int) - out.color[..., 2]) > 60
    assert (red == hit).mean() > 0.98  # colour agrees except maybe silhouette pixels
    # Projection of the box's front face centre lands where K says.
    k = camera().K
    col, row = k[0, 0] * -2.0 / 7.5 + k[0, 2], -k[1, 1] * 1.2 / 7.5 + k[1, 2]
    assert hit[int(round(row)), int(round(col))]


def test_damage_mask_projects_exactly_and_normal_map_only_shades(renderer):
    """A fronto-parallel plate whose UVs map the texture exactly onto the 64 x 48 image."""
    cam = camera()
    rng = make_rng(5, 0, Stream.DAMAGE)
    mask = rng.choice(np.array([1, 2, 3], np.uint8), size=(48, 64), p=[0.6, 0.3, 0.1])
    bumps = np.zeros((48, 64, 3), np.uint8)
    tilt = rng.normal(0, 0.5, (48, 64, 2))
    normal = np.dstack([tilt, np.ones((48, 64))])
    normal /= np.linalg.norm(normal, axis=2, keepdims=True)
    bumps[:] = np.round((normal * 0.5 + 0.5) * 255)
    plate = pixel_plate(cam, 10.0)
    base = Material(base_color=(0.7, 0.7, 0.7, 1.0), damage_mask=mask)
    bumpy = Material(base_color=(0.7, 0.7, 0.7, 1.0), damage_mask=mask, normal_map=bumps)
    renderer.load(scene_of(("column_plate", Component.COLUMN, plate, base)), LIGHT)
    flat = renderer.render(cam)
    renderer.load(scene_of(("column_plate", Component.COLUMN, plate, bumpy)), LIGHT)
    shaded = renderer.render(cam)
    # Image row 0 is the top; the mask's row 0 is the top of the texture (v = 1).
    assert np.array_equal(flat.damage, mask)
    assert np.array_equal(shaded.damage, flat.damage)
    assert np.array_equal(shaded.component, flat.component)
    assert np.array_equal(shaded.depth, flat.depth)
    diff = np.abs(shaded.color.astype(int) - flat.color.astype(int))
    assert diff.mean() > 5 and np.std(shaded.color) > 2 * np.std(flat.color)


def test_metallic_map_travels_in_the_base_textures_alpha(renderer):
    """The renderer samples the metallic map from the base colour texture's alpha: where the
    map is 255 the plate renders as the metallic factor alone, where it is 0 as metallic 0."""
    plate = pixel_plate(camera(), 10.0)
    colour = make_rng(6, 0, Stream.DAMAGE).integers(60, 200, (48, 64, 3), dtype=np.uint8)
    metal = np.zeros((48, 64), np.uint8)
    metal[:, :32] = 255

    def render(metallic: float, metallic_map: np.ndarray | None) -> np.ndarray:
        m = Material(base_color=(1.0, 1.0, 1.0, 1.0), metallic=metallic, roughness=0.3,
                     base_color_map=colour, metallic_map=metallic_map)
        renderer.load(scene_of(("column_plate", Component.COLUMN, plate, m)), LIGHT)
        return renderer.render(camera(), frozenset({"color"})).color

    mapped, steel, concrete = render(1.0, metal), render(1.0, None), render(0.0, None)
    assert not np.array_equal(steel, concrete)
    assert np.array_equal(mapped[:, :31], steel[:, :31])
    assert np.array_equal(mapped[:, 33:], concrete[:, 33:])
    with pytest.raises(ValueError, match="metallic_map: shape"):
        Material(base_color_map=colour, metallic_map=metal[:, :32])


def test_msaa_changes_colour_edges_only_never_labels_or_depth():
    from glsynth.world.meshes import box, pose

    b = box((1.0, 1.0, 1.0))
    b.apply_transform(pose(0.4, [0.3, 0.2, -6.0]))
    scene = scene_of(("column_box", Component.COLUMN, b, plain_material(Component.COLUMN)))
    a, b4 = (render_once(scene, render_config(64, 48, msaa=msaa)) for msaa in (0, 4))
    assert np.array_equal(a.component, b4.component) and np.array_equal(a.depth, b4.depth)
    changed = np.any(a.color != b4.color, axis=2)
    assert changed.any()
    edge = np.zeros_like(changed)
    hit = a.component == Component.COLUMN
    edge[1:-1, 1:-1] = (hit[1:-1, 1:-1] != hit[:-2, 1:-1]) | (hit[1:-1, 1:-1] != hit[2:, 1:-1]) \
        | (hit[1:-1, 1:-1] != hit[1:-1, :-2]) | (hit[1:-1, 1:-1] != hit[1:-1, 2:])
    near_edge = edge | np.roll(edge, 1, 0) | np.roll(edge, -1, 0) | np.roll(edge, 1, 1) \
        | np.roll(edge, -1, 1)
    assert not np.any(changed & ~near_edge)


def _glowing(rgb: tuple[float, float, float]) -> Material:
    """Emission only: the colour says which surface a pixel shows."""
    return Material(base_color=(0.0, 0.0, 0.0, 1.0), emissive=rgb)


@pytest.mark.parametrize("msaa", [0, 4])
def test_colour_shows_the_surface_the_labels_name_where_surfaces_tie(msaa):
    """The colour pass shades against the label pass's depth; where surfaces tie in depth it
    must keep the one the labels keep (the first drawn), between parts and within one mesh."""
    d = 8.0
    left = quad([[-3.0, -2.0, -d], [0.5, -2.0, -d], [0.5, 2.0, -d], [-3.0, 2.0, -d]])
    right = quad([[-1.5, -2.0, -d], [-0.2, -2.0, -d], [-0.2, 2.0, -d], [-1.5, 2.0, -d]])
    # One mesh, two coplanar triangles over the same area: the first samples the texture's
    # left half (red, damage id 2), the second its right half (green, damage id 1).
    corners = np.array([[1.0, -2.0, -d], [3.5, -2.0, -d], [1.0, 2.0, -d]])
    pair = trimesh.Trimesh(np.vstack([corners, corners]), [[0, 1, 2], [3, 4, 5]],
                           process=False)
    pair.visual = TextureVisuals(uv=np.array([[0.1, 0.1], [0.4, 0.1], [0.1, 0.9],
                                              [0.6, 0.1], [0.9, 0.1], [0.6, 0.9]]))
    halves = np.zeros((8, 8, 3), np.uint8)
    halves[:, :4, 0] = halves[:, 4:, 1] = 255
    mask = np.ones((8, 8), np.uint8)
    mask[:, :4] = Damage.CONCRETE
    scene = scene_of(("beam_left", Component.BEAM, left, _glowing((2.0, 0.0, 0.0))),
                     ("slab_right", Component.SLAB, right, _glowing((0.0, 2.0, 0.0))),
                     ("column_pair", Component.COLUMN, pair,
                      Material(base_color=(0.0, 0.0, 0.0, 1.0), emissive=(2.0, 2.0, 2.0),
                               emissive_map=halves, damage_mask=mask)))
    out = render_once(scene, render_config(64, 48, msaa=msaa))
    red, green = out.color[..., 0].astype(int), out.color[..., 1].astype(int)
    # Away from silhouettes (MSAA blends those), each pixel glows in its labelled part's colour.
    inner = np.ones(out.component.shape, bool)
    for axis in (0, 1):
        for shift in (1, -1):
            inner &= out.component == np.roll(out.component, shift, axis)
            inner &= out.damage == np.roll(out.damage, shift, axis)
    beam = inner & (out.component == Component.BEAM)
    slab = inner & (out.component == Component.SLAB)
    column = inner & (out.component == Component.COLUMN)
    assert beam.sum() > 200 and slab.sum() > 100 and column.sum() > 100
    assert np.all(red[beam] > green[beam] + 100) and np.all(green[slab] > red[slab] + 100)
    # The pair's first triangle wins in the labels (damage id 2) and so in colour (red).
    assert np.all(out.damage[column] == Damage.CONCRETE)
    assert np.all(red[column] > green[column] + 100)


@pytest.mark.parametrize("msaa", [0, 4])
def test_parts_out_of_view_are_not_drawn_and_change_no_byte(monkeypatch, msaa):
    """Each view draws only the parts whose boxes may be in its frustum (the sun's shadow pass
    draws the rest); every pass gives the same bytes as drawing everything."""
    import glsynth.render.gl.renderer as renderer_module
    from glsynth.world.meshes import box, pose

    def part(name, component, xyz):
        mesh = box((1.0, 1.0, 1.0))
        mesh.apply_transform(pose(0.3, xyz))
        return (name, component, mesh, plain_material(component))

    floor = quad([[-30.0, -3.0, 5.0], [30.0, -3.0, 5.0], [30.0, -3.0, -40.0],
                  [-30.0, -3.0, -40.0]])
    scene = scene_of(("ground_floor", Component.NONBRIDGE, floor,
                      plain_material(Component.NONBRIDGE)),
                     part("column_seen", Component.COLUMN, [0.5, 0.0, -6.0]),
                     part("column_edge", Component.COLUMN, [3.0, 0.5, -6.0]),
                     part("beam_behind", Component.BEAM, [0.0, 0.0, 4.0]),
                     part("beam_aside", Component.BEAM, [40.0, 0.0, -6.0]))
    seen_counts = []

    def counting(corners, cam):
        seen = seen_by(corners, cam)
        seen_counts.append(int(seen.sum()))
        return seen

    seen_by = renderer_module.seen_by
    outputs = []
    for test in (counting, lambda corners, cam: np.ones(len(corners), bool)):
        monkeypatch.setattr(renderer_module, "seen_by", test)
        outputs.append(render_once(scene, render_config(64, 48, msaa=msaa)))
    assert seen_counts == [3]  # the floor and two columns; not the beams
    culled, everything = outputs
    for name in ("color", "component", "damage", "depth"):
        assert np.array_equal(getattr(culled, name), getattr(everything, name)), name


def test_msaa_keeps_the_single_sample_colour_inside_a_surface_to_the_byte():
    """A wall filling the view, with a texture that changes at every pixel: every pixel is
    inside the surface (msaa_interior.frag), so MSAA 4 gives the single-sample bytes."""
    d = 6.0
    wall = quad([[-20.0, -20.0, -d], [20.0, -20.0, -d], [20.0, 20.0, -d], [-20.0, 20.0, -d]],
                uv=np.array([[0.0, 0.0], [8.0, 0.0], [8.0, 8.0], [0.0, 8.0]]))
    levels = (np.arange(64 * 64 * 3).reshape(64, 64, 3) * 37 % 256).astype(np.uint8)
    scene = scene_of(("slab_wall", Component.SLAB, wall,
                      Material(base_color=(0.0, 0.0, 0.0, 1.0), emissive=(1.5, 1.5, 1.5),
                               emissive_map=levels)))
    images = [render_once(scene, render_config(64, 48, msaa=msaa), passes={"color"}).color
              for msaa in (0, 4)]
    assert len(np.unique(images[0].reshape(-1, 3), axis=0)) > 500  # no flat field
    assert np.array_equal(images[0], images[1])


def test_every_pixel_of_the_shading_normal_target_is_written_sky_included():
    """Under MSAA the colour pass keeps its shading normals for the resolve, which reads them
    beside sky pixels too. A fragment output a shader leaves unwritten is undefined in GL, and
    llvmpipe left varying garbage (NaN included) at sky pixels, so a few edge pixels changed
    from run to run. The sky writes a zero normal; surfaces write unit normals."""
    square = quad([[-1.0, -1.0, -6.0], [1.0, -1.0, -6.0], [1.0, 1.0, -6.0], [-1.0, 1.0, -6.0]])
    with Renderer(render_config(64, 48, msaa=4)) as r:
        r.load(scene_of(("column_square", Component.COLUMN, square, PLAIN)), LIGHT)
        out = r.render(camera())
        normals = np.frombuffer(r.normal_target.read(), np.float16).reshape(48, 64, 4)[::-1]
        assert r.ctx.error == "GL_NO_ERROR"
    sky = out.component != Component.COLUMN
    assert 100 < sky.sum() < sky.size - 100
    assert np.all(normals[sky].view(np.uint16) == 0)  # bit for bit: no -0, no NaN
    lengths = np.linalg.norm(normals[~sky, :3].astype(np.float64), axis=1)
    assert np.all(np.abs(lengths - 1.0) < 2e-3) and np.all(normals[~sky, 3] == 1.0)


def test_msaa_samples_on_a_silhouette_take_their_own_surfaces_colour():
    """A red square before a green wall. Each MSAA sample takes the colour shaded at a pixel
    centre on its own surface: a pixel lies within the colours of its 3x3 neighbourhood
    without MSAA, and a pixel whose centre lies just off the square (a sample on it) shows red,
    one whose centre lies just inside shows green."""
    from glsynth.world.meshes import pose

    wall = quad([[-20.0, -20.0, -12.0], [20.0, -20.0, -12.0], [20.0, 20.0, -12.0],
                 [-20.0, 20.0, -12.0]])
    square = quad([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
    square.apply_transform(pose(0.5, [0.2, 0.1, -6.0]))
    scene = scene_of(("slab_wall", Component.SLAB, wall, _glowing((0.0, 0.6, 0.0))),
                     ("column_square", Component.COLUMN, square, _glowing((0.6, 0.0, 0.0))))
    single, multi = (render_once(scene, render_config(64, 48, msaa=msaa), passes={"color"})
                     .color.astype(int) for msaa in (0, 4))
    padded = np.pad(single, ((1, 1), (1, 1), (0, 0)), mode="edge")
    windows = np.stack([padded[i:i + 48, j:j + 64] for i in range(3) for j in range(3)])
    assert np.all(multi >= windows.min(0) - 1) and np.all(multi <= windows.max(0) + 1)
    # Signed distance in pixels from each pixel centre to the square's outline (> 0 outside),
    # by its four edges' half-planes; corners left out, where that is not the distance.
    k = camera().K
    corners = square.vertices[[0, 1, 2, 3]]
    px = np.stack([k[0, 0] * corners[:, 0] / -corners[:, 2] + k[0, 2],
                   k[1, 2] - k[1, 1] * corners[:, 1] / -corners[:, 2]], 1)
    rows, cols = np.mgrid[0:48, 0:64]
    centres = np.stack([cols, rows], -1).astype(float)
    (ux, uy), (vx, vy) = px[1] - px[0], px[2] - px[0]
    inward = np.sign(ux * vy - uy * vx)
    distance = np.full((48, 64), -np.inf)
    for a, b in zip(px, np.roll(px, -1, 0), strict=True):
        edge = b - a
        outward = inward * np.array([edge[1], -edge[0]]) / np.linalg.norm(edge)
        distance = np.maximum(distance, (centres - a) @ outward)
    near_corner = np.min([np.linalg.norm(centres - c, axis=-1) for c in px], 0) < 2.0
    wall_red, wall_green = single[0, 0, 0], single[0, 0, 1]
    just_off = (distance > 0.0) & (distance < 0.2) & ~near_corner
    just_in = (distance < 0.0) & (distance > -0.2) & ~near_corner
    assert just_off.sum() >= 4 and just_in.sum() >= 4
    assert np.all(multi[just_off, 0] >= wall_red + 20)
    square_green = single[24, 33, 1]
    assert single[24, 33, 0] > wall_red + 60  # the square's middle
    assert np.all(multi[just_in, 1] >= square_green + 20)
    assert wall_green > square_green + 60


def test_more_msaa_samples_than_the_gl_has_is_one_clear_error():
    with Renderer(render_config()) as r:
        most = r.ctx.max_samples
    if 2 * most > 16:
        pytest.skip(f"this GL has {most} samples, more than [render] msaa allows")
    with pytest.raises(UserError, match=rf"msaa = {2 * most}: .* at most {most} samples"):
        Renderer(render_config(msaa=2 * most))


def test_unknown_platform_and_failure_message(monkeypatch):
    with pytest.raises(UserError, match="GL platform 'vulkan'"):
        gl_context.create_context("vulkan")

    def broken(name):
        raise OSError(f"lib for {name} not found")

    monkeypatch.setattr(gl_context, "_create", broken)
    with pytest.raises(gl_context.GLUnavailableError) as info:
        gl_context.create_context()
    message = str(info.value)
    assert "EGL: OSError" in message and "OSMESA: OSError" in message
    assert "libegl1" in message and "libosmesa6" in message
    assert "\n" not in message and isinstance(info.value, UserError)  # one line for the CLI


def test_egl_and_osmesa_render_the_same(env0):
    from glsynth.core.config import Config
    from glsynth.render.scene import build_scene
    from glsynth.world.cameras import environment_camera

    rc = render_config(96, 54)
    scene = build_scene(env0.parts, plain_materials(env0))
    cam = environment_camera(env0.trajectory, Config().cameras, rc, 0, 0, 60).camera
    e, o = (render_once(scene, rc, cam, platform=platform) for platform in ("egl", "osmesa"))
    assert np.array_equal(e.component, o.component) and np.array_equal(e.depth, o.depth)
    assert np.abs(e.color.astype(int) - o.color.astype(int)).max() <= 1


def test_rendered_damage_plate_shows_ids_exactly_where_the_mask_says(tmp_path):
    """A real bank texture (64 px) on a plate that maps texels to pixels one to one."""
    from glsynth.appearance.damage_bank import DamageBank, damage_material
    from glsynth.appearance.repository import TextureRepository, generate_repository
    from glsynth.core.config import DamageConfig

    repo = TextureRepository(generate_repository(tmp_path / "r", 0, 2, 16), 16)
    cfg = DamageConfig(resolution=64)
    entry = DamageBank(cfg, 0, cache_dir=tmp_path).entry("severe", 3, repo)
    material = damage_material(entry, repo, cfg, scale=1.0)
    cam = camera(64, 64)
    plate = pixel_plate(cam, 4.0)
    out = render_once(scene_of(("column_plate", Component.COLUMN, plate, material)),
                      render_config(64, 64), cam)
    mask = entry.maps.mask
    assert (mask == 2).any() and (mask == 3).any()
    assert np.array_equal(out.damage, mask)
    assert np.all(out.component == Component.COLUMN)
    # Sound concrete (1), the second concrete image where concrete is damaged (2) and metallic
    # steel where rebar is exposed (3): the colour maps follow the mask if the three regions'
    # mean luminances lie more than two pixel standard deviations apart, pair by pair (here
    # 3.0, 7.6 and 2.8). Maps one texel off the mask leave them at most 1.7 apart, maps flipped
    # or 8 texels off at most 0.7 (measured on this plate), so the test tells them apart.
    luminance = out.color.astype(float) @ np.array([0.2126, 0.7152, 0.0722])
    for a, b in itertools.combinations([luminance[mask == v] for v in (1, 2, 3)], 2):
        assert abs(a.mean() - b.mean()) > 2 * np.sqrt((a.var() + b.var()) / 2)
