"""The world around the viaducts (glsynth.world.surroundings): the paper's panels stay as they
were; the town keeps clear of the viaducts, is reproducible, renders labels and depth that
agree with the CPU ray cast, leaves the sky above its hills, and is exported."""

import dataclasses
import json
import struct

import numpy as np
import pytest
import trimesh
from glhelpers import LIGHT, plain_materials, render_config

from glsynth.appearance import town_textures
from glsynth.core.config import EnvironmentConfig, load_config
from glsynth.core.labels import Component
from glsynth.data.flight_export import depth_tolerance
from glsynth.render.export import export_environment
from glsynth.render.gl.renderer import Renderer
from glsynth.render.raycast import ray_cast
from glsynth.render.scene import build_scene
from glsynth.render.view import EnvironmentView
from glsynth.world.cameras import Camera
from glsynth.world.environment import PartKind, build_environment
from glsynth.world.surroundings import COLUMN_CLEARANCE_M, DECK_CLEARANCE_M, TOWN_KINDS
from glsynth.world.visibility import occlusion_extent

RC = render_config(160, 90)


def _config(preset: str = "demo", n_viaducts: int = 4, **environment):
    config = load_config(preset)
    env = dataclasses.replace(config.environment, n_viaducts=n_viaducts, **environment)
    return dataclasses.replace(config, environment=env)


@pytest.fixture(scope="module")
def town():
    return build_environment(_config(), 0, 0)


def test_paper_keeps_the_panels_and_the_demo_and_inspection_presets_build_the_town():
    assert EnvironmentConfig().world == "panels"
    paper = build_environment(_config("paper"), 0, 0)
    kinds = {p.kind for p in paper.parts}
    assert PartKind.SCENE in kinds and not kinds & TOWN_KINDS
    for preset in ("demo", "inspection"):
        assert load_config(preset).environment.world == "town"
        kinds = {p.kind for p in build_environment(_config(preset), 0, 1).parts}
        assert PartKind.SCENE not in kinds and TOWN_KINDS <= kinds, preset
    assert PartKind.UTILITY.component is Component.NONSTRUCTURAL
    assert {k.component for k in TOWN_KINDS - {PartKind.UTILITY}} == {Component.NONBRIDGE}


def test_town_parts_are_named_by_component_tag_kind_and_side(town):
    for part in town.parts:
        if part.kind in TOWN_KINDS:
            words = part.name.split("_")
            assert words[0] == {Component.NONBRIDGE: "nonbridge",
                                Component.NONSTRUCTURAL: "nonstructural"}[part.component]
            assert part.kind.value in words
            assert part.side is None or words[-1] == part.side


def test_the_town_moves_nothing_of_the_viaducts(town):
    panels = build_environment(_config(world="panels"), 0, 0)
    bridge = [p for p in panels.parts if p.viaduct is not None and p.kind is not PartKind.SCENE
              and p.kind is not PartKind.GROUND]
    same = {p.name: p for p in town.parts}
    for part in bridge:
        assert np.array_equal(same[part.name].mesh.vertices, part.mesh.vertices), part.name
    # Town parts come after the viaducts' own, and each strip adds one part per kind and side;
    # only the severe columns' crushed bands and bars ([damage] geometry) come after them.
    first_town = min(i for i, p in enumerate(town.parts) if p.kind in TOWN_KINDS)
    after = TOWN_KINDS | {PartKind.GROUND, PartKind.CRUSHED, PartKind.REBAR}
    assert all(p.kind in after or p.component is Component.OTHER
               for p in town.parts[first_town:])
    names = [p.name for p in town.parts]
    assert len(names) == len(set(names))


def test_the_town_is_reproducible_and_differs_between_environments(town):
    again = build_environment(_config(), 0, 0)
    other = build_environment(_config(), 0, 1)
    for a, b in zip(town.parts, again.parts):
        assert a.name == b.name and np.array_equal(a.mesh.vertices, b.mesh.vertices)
    mine = [p.mesh.vertices for p in town.parts if p.kind is PartKind.BUILDING]
    theirs = [p.mesh.vertices for p in other.parts if p.kind is PartKind.BUILDING]
    assert any(a.shape != b.shape or not np.allclose(a, b) for a, b in zip(mine, theirs))


def _centre_line(env, step: float = 0.25) -> np.ndarray:
    margin = env.config.environment.end_margin_m
    s = np.arange(-margin - 80.0, env.trajectory.total_length_m + margin + 80.0, step)
    return env.trajectory.frame(s)[0][:, :2]


def test_the_town_keeps_clear_of_the_decks_and_columns(town):
    line = _centre_line(town)
    half_deck = town.config.design.deck_width_m / 2
    for part in town.parts:
        if part.kind not in TOWN_KINDS or part.kind is PartKind.TERRAIN:
            continue
        xy = part.world_vertices()[:, :2]
        dist = np.min(np.linalg.norm(xy[:, None] - line[None], axis=-1), axis=1)
        if part.side is None:  # the paved strip under a deck: clear of every column
            assert part.kind is PartKind.ROAD
            _assert_clear_of_columns(town, xy)
            continue
        # Sweeps follow the centre line exactly; the tabulated frame is within 0.1 mm.
        assert dist.min() >= half_deck + DECK_CLEARANCE_M - 1e-3, part.name


def _assert_clear_of_columns(env, xy: np.ndarray) -> None:
    for info in env.viaducts:
        for col in info.columns:
            c, s = np.cos(col.heading), np.sin(col.heading)
            local = (xy - col.center_xy) @ np.array([[c, -s], [s, c]])
            a, b = col.section_m
            inside = ((np.abs(local[:, 0]) < a / 2 + COLUMN_CLEARANCE_M - 1e-6)
                      & (np.abs(local[:, 1]) < b / 2 + COLUMN_CLEARANCE_M - 1e-6))
            assert not inside.any(), col.name


def test_the_terrain_stays_under_the_ground_strips(town):
    """Where a ground strip lies over it, the terrain is below it (the strips hide it)."""
    terrain = next(p for p in town.parts if p.kind is PartKind.TERRAIN)
    ground = [p for p in town.parts if p.kind is PartKind.GROUND]
    v = terrain.world_vertices()
    origins = v + [0.0, 0.0, -50.0]
    up = np.tile([0.0, 0.0, 1.0], (len(v), 1))
    mesh = trimesh.util.concatenate([trimesh.Trimesh(p.world_vertices(), p.mesh.faces,
                                                     process=False) for p in ground])
    hits, rays, _ = mesh.ray.intersects_location(origins, up, multiple_hits=False)
    assert len(rays) > 50
    assert np.all(hits[:, 2] > v[rays, 2] + 0.5)


def _look(position: np.ndarray, forward: np.ndarray, width: int, height: int,
          focal_mm: float = 18.0) -> Camera:
    """A level-rolled camera at ``position`` looking along ``forward``."""
    z = -forward / np.linalg.norm(forward)
    x = np.cross([0.0, 0.0, 1.0], z)
    x /= np.linalg.norm(x)
    pose = np.eye(4)
    pose[:3, :3] = np.stack([x, np.cross(z, x), z], axis=1)
    pose[:3, 3] = position
    return Camera(width, height, focal_mm, 36.0, pose, RC.znear_m, RC.zfar_m)


def _town_cameras(env) -> list[Camera]:
    """Under the middle deck looking out sideways, and a drone above it looking out over the
    town to the hills."""
    s = np.array([env.trajectory.total_length_m / 2 + 3.0])
    point, tangent, normal = env.trajectory.frame(s)
    ground = float(env.trajectory.ground_at(s)[0])
    low = np.array([point[0, 0], point[0, 1], ground + 2.0])
    high = np.array([point[0, 0], point[0, 1], point[0, 2] + 25.0])
    return [_look(low, normal[0] + 0.3 * tangent[0], RC.width, RC.height),
            _look(high, -normal[0] + [0.0, 0.0, -0.15], RC.width, RC.height)]


@pytest.fixture(scope="module")
def rendered(town):
    cameras = _town_cameras(town)
    with Renderer(RC) as r:
        r.load(build_scene(town.parts, plain_materials(town)), LIGHT)
        outs = [r.render(c) for c in cameras]
        assert r.ctx.error == "GL_NO_ERROR"
    return cameras, outs


def _interior(depth: np.ndarray, comp: np.ndarray) -> np.ndarray:
    """Pixels away from edges: one component in the 3x3 neighbourhood, and one plane there.
    A plane's inverse depth is linear across the image, so its second differences along the
    rows, columns and both diagonals vanish; a silhouette or a fold between two surfaces of
    one component (a roof's edge over a wall) does not."""
    w = np.where(np.isfinite(depth), 1.0 / depth, 0.0)
    core = (slice(1, -1), slice(1, -1))
    same = np.ones(depth[core].shape, bool)

    def at(dr: int, dc: int) -> tuple[slice, slice]:
        return slice(1 + dr, depth.shape[0] - 1 + dr), slice(1 + dc, depth.shape[1] - 1 + dc)

    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            same &= comp[at(dr, dc)] == comp[core]
            same &= np.isfinite(depth[at(dr, dc)]) == np.isfinite(depth[core])
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        bend = np.abs(w[at(dr, dc)] + w[at(-dr, -dc)] - 2 * w[core])
        same &= bend <= 1e-3 * w[core]
    interior = np.zeros(depth.shape, bool)
    interior[core] = same
    return interior


def test_town_labels_and_depth_match_the_cpu_ray_cast(town, rendered):
    cameras, outs = rendered
    without = [p for p in town.parts if p.kind not in TOWN_KINDS]
    for camera, out in zip(cameras, outs):
        truth = ray_cast(town.parts, plain_materials(town), camera)
        depth = np.where(truth.depth < camera.zfar, truth.depth, np.inf)
        bare = ray_cast(without, plain_materials(town), camera).depth
        town_pixels = np.abs(np.minimum(bare, camera.zfar) - np.minimum(truth.depth,
                                                                        camera.zfar)) > 1e-3
        assert town_pixels.mean() > 0.2  # the camera sees the town
        interior = _interior(depth, truth.component)
        assert interior.mean() > 0.6
        hit = interior & np.isfinite(depth)
        # Depth within 1 mm, and within the float depth buffer's 1e-4 beyond 10 m.
        assert np.all(np.abs(out.depth[hit] - depth[hit])
                      <= np.maximum(1e-3, 1e-4 * depth[hit]))
        agree = out.component[interior] == truth.component[interior]
        assert agree.mean() >= 0.9999


def test_the_sky_shows_above_the_hills(rendered):
    cameras, outs = rendered
    drone = outs[1]
    sky = drone.depth >= cameras[1].zfar * 0.999
    top, bottom = sky[: RC.height // 4], sky[-RC.height // 4:]
    assert top.mean() > 0.9 and not bottom.any()
    # Every column of the image meets land below its sky: the hills close the horizon.
    first_land = np.argmax(~sky, axis=0)
    assert np.all(first_land > 0)
    horizon = drone.depth[first_land, np.arange(RC.width)]
    assert np.median(horizon) > 300.0


def test_the_gltf_export_carries_the_town(town, tmp_path):
    glb, _ = export_environment(town, tmp_path / "scene.glb")
    data = glb.read_bytes()
    chunk_len = struct.unpack("<I", data[12:16])[0]
    gltf = json.loads(data[20:20 + chunk_len])
    nodes = {n["name"] for n in gltf["nodes"] if "mesh" in n}
    assert nodes == {p.name for p in town.parts}
    scene = trimesh.load(glb, process=False)
    for part in (p for p in town.parts if p.kind in TOWN_KINDS):
        transform, geometry = scene.graph[part.name]
        loaded = trimesh.transform_points(scene.geometry[geometry].vertices, transform)
        world = part.world_vertices()
        expected = np.stack([world[:, 0], world[:, 2], -world[:, 1]], axis=1)
        assert np.allclose(loaded, expected, atol=1e-3), part.name


def test_town_textures_are_made_from_their_seed():
    town_textures.image.cache_clear()
    first = town_textures.image("facade", 2, 64, 0)
    town_textures.image.cache_clear()
    assert np.array_equal(first, town_textures.image("facade", 2, 64, 0))
    assert not np.array_equal(first, town_textures.image("facade", 3, 64, 0))
    assert first.shape == (64, 64, 3) and not first.flags.writeable
    for category in town_textures.CATEGORIES:
        img = town_textures.image(category, 0, 64, 0)
        assert img.std() > 2.0, category


def test_demo_views_show_the_town_and_sky_and_no_panel():
    """The demo preset's own cameras, dressed and culled as generate renders them: no part
    of the scene is a panel (none is emissive), the town is in view beyond the panels' 30 m
    and the sky shows."""
    config = load_config("demo")
    config = dataclasses.replace(
        config, render=dataclasses.replace(config.render, width=192, height=108, msaa=0,
                                           shadow_map_px=512, sky_visibility_maps=4,
                                           sky_visibility_px=256),
        materials=dataclasses.replace(config.materials, texture_size=64, builtin_size=64,
                                      images_per_category=3),
        damage=dataclasses.replace(config.damage, resolution=64))
    view = EnvironmentView.open(config, 0, 0)
    kinds = {p.name: p.kind for p in view.environment.parts}
    assert PartKind.SCENE not in kinds.values()
    assert all(info.material.emissive_map is None and max(info.material.emissive) == 0.0
               for info in view.scene.parts.values())
    assert TOWN_KINDS & {kinds[name] for name in view.scene.parts}
    far_land = sky = 0.0
    for index in range(config.cameras.total):
        _, out = view.render(index, photo=False)
        zfar = config.render.zfar_m
        far_land += np.mean((out.component == Component.NONBRIDGE) & (out.depth > 35.0)
                            & (out.depth < zfar * 0.999))
        sky += np.mean(out.depth >= zfar * 0.999)
    assert far_land > 0.05 and sky > 0.05


def test_the_far_terrain_is_open_to_the_sky_outside_the_visibility_maps(town):
    """The sky-visibility maps are fitted to all but the terrain (occlusion_extent); the land
    beyond them reads as open sky, as with no maps at all, not a neighbouring map's depths."""
    extent = occlusion_extent(town.parts)
    terrain = next(p for p in town.parts if p.kind is PartKind.TERRAIN)
    assert np.ptp(extent[:, 0]) < 0.5 * np.ptp(terrain.world_vertices()[:, 0])
    drone = _town_cameras(town)[1]
    colours = []
    for maps in (16, 0):
        config = dataclasses.replace(RC, sky_visibility_maps=maps)
        with Renderer(config) as r:
            r.load(build_scene(town.parts, plain_materials(town)), LIGHT, extent)
            out = r.render(drone)
        colours.append(out.color.astype(int))
    # Terrain pixels well beyond the town (depth from the last render: the same geometry).
    far = (out.depth > 400.0) & (out.depth < RC.zfar_m * 0.999)
    far[1:-1, 1:-1] &= far[:-2, 1:-1] & far[2:, 1:-1] & far[1:-1, :-2] & far[1:-1, 2:]
    assert far.sum() > 200
    diff = np.abs(colours[0] - colours[1]).max(axis=-1)[far]
    assert np.mean(diff <= 1) > 0.99


def test_a_wire_or_a_sliver_between_silhouettes_is_no_slope_for_flight_points():
    """flight_export.depth_tolerance: a slope's change per pixel is its tolerance; a one-pixel
    wire across the view, or a one-pixel far wall between a column and the sky, has none (a
    point behind the wire, or on the column, would otherwise be seen there)."""
    slope = np.tile(10.0 + 0.1 * np.arange(9.0), (5, 1))  # depth rising 0.1 m a column
    assert np.allclose(depth_tolerance(slope)[:, 1:-1], 0.1)
    wire = np.full((5, 9), 40.0)
    wire[2] = 12.0
    assert depth_tolerance(wire)[2].max() == 0.0
    sliver = np.full((5, 9), 2000.0)
    sliver[:, :4], sliver[:, 4] = 2.7, 27.6  # column | far wall | sky
    assert depth_tolerance(sliver)[:, 4].max() == 0.0
