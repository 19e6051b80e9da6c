"""Others, class 8 (glsynth.world.others): off in the paper preset, on in demo and inspection;
parts appended last from their own stream; placed outside the members they dress; labels and
depth that agree with the CPU ray cast; a jacket hides its column's damage; the glTF export
and the Cycles twin carry them."""

import dataclasses
import json
import shutil
import struct

import numpy as np
import pytest
from glhelpers import LIGHT, plain_materials, render_config

from glsynth.appearance.cracks import hinge_zones
from glsynth.appearance.damage_bank import DamageBank
from glsynth.appearance.dressing import clear_spans, dress, open_repository, spalls
from glsynth.appearance.materials import Material
from glsynth.appearance.signs import plate_image
from glsynth.core.config import Config, EnvironmentConfig, load_config
from glsynth.core.errors import UserError
from glsynth.core.geometry import transform_points
from glsynth.core.labels import Component, Damage
from glsynth.render.cycles import display, render_linear
from glsynth.render.export import export_environment
from glsynth.render.gl.renderer import Renderer
from glsynth.render.raycast import ray_cast
from glsynth.render.scene import build_scene
from glsynth.render.view import EnvironmentView
from glsynth.world.cameras import Camera
from glsynth.world.environment import PartKind, build_environment
from glsynth.world.others import JACKET_GAP_M

RULES = ("jacket_probability", "brace_probability", "downpipe_probability",
         "trough_probability", "sign_probability")
OTHER_KINDS = {PartKind.JACKET, PartKind.BRACE, PartKind.DOWNPIPE, PartKind.TROUGH,
               PartKind.SIGN}
BOXES = {PartKind.COLUMN, PartKind.CROSS_BEAM, PartKind.TIE_BEAM}


def config(base: Config | None = None, **rules: float) -> Config:
    """``base`` (default Config()) with the others' rules set (the rest 0)."""
    base = base or Config()
    values = {name: rules.get(name.removesuffix("_probability"), 0.0) for name in RULES}
    return dataclasses.replace(base, environment=dataclasses.replace(base.environment,
                                                                     **values))


@pytest.fixture(scope="module")
def jacketed():
    """Every column jacketed, a downpipe on both sides, troughs and a plate on every viaduct."""
    return build_environment(config(jacket=1, downpipe=1, trough=1, sign=1), 0, 0)


@pytest.fixture(scope="module")
def braced():
    return build_environment(config(brace=1, downpipe=1), 0, 0)


def look_at(eye, target, width=160, height=90, focal_mm=20.0) -> Camera:
    """A camera at ``eye`` looking at ``target`` (up is +z)."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    f = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(f, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    pose = np.eye(4)
    pose[:3, :3] = np.stack([right, np.cross(right, f), -f], axis=1)
    pose[:3, 3] = eye
    return Camera(width, height, focal_mm, 36.0, pose, 0.05, 500.0)


def test_only_the_paper_preset_has_no_others():
    paper = load_config("paper").environment
    assert all(getattr(paper, r) == 0.0 for r in RULES)
    env = build_environment(load_config("paper"), 0, 0)
    assert not [p for p in env.parts if p.component is Component.OTHER]
    for preset in ("demo", "inspection"):
        on = load_config(preset).environment
        assert all(0.0 < getattr(on, r) <= 1.0 for r in RULES)
    with pytest.raises(UserError, match=r"environment\.jacket_probability = 1\.5"):
        EnvironmentConfig(jacket_probability=1.5)


def test_others_come_last_from_their_own_stream(jacketed):
    off = build_environment(Config(), 0, 0)
    n = len(off.parts)
    assert [p.name for p in jacketed.parts[:n]] == [p.name for p in off.parts]
    assert all(np.array_equal(a.mesh.vertices, b.mesh.vertices)
               for a, b in zip(jacketed.parts[:n], off.parts))
    others = jacketed.parts[n:]
    assert {p.kind for p in others} == OTHER_KINDS - {PartKind.BRACE}
    assert all(p.component is Component.OTHER for p in others)
    # One part per kind per viaduct: jackets, downpipes, troughs and plates on all ten.
    assert len(others) == 4 * len(jacketed.viaducts)
    again = build_environment(config(jacket=1, downpipe=1, trough=1, sign=1), 0, 0)
    assert all(np.array_equal(a.mesh.vertices, b.mesh.vertices)
               for a, b in zip(others, again.parts[n:]))
    # A rule drawn or not moves no other rule's pieces.
    fewer = build_environment(config(jacket=1, downpipe=1, sign=1), 0, 0)
    kept = {p.name: p for p in fewer.parts[n:]}
    assert all(np.array_equal(p.mesh.vertices, kept[p.name].mesh.vertices)
               for p in others if p.kind is not PartKind.TROUGH)


def _inside(points: np.ndarray, part) -> np.ndarray:
    """Whether points lie strictly inside a box part (1 mm in from its faces)."""
    local = transform_points(np.linalg.inv(part.pose), points)
    return np.all(np.abs(local) < part.mesh.extents / 2 - 1e-3, axis=1)


@pytest.mark.parametrize("name", ["jacketed", "braced"])
def test_others_stay_out_of_columns_and_beams(name, request):
    """Jackets, downpipes, troughs and plates stand outside every column and beam box (brace
    ends reach into the columns by design); a jacket's shells clear the beams by the gap."""
    env = request.getfixturevalue(name)
    boxes = [p for p in env.parts if p.kind in BOXES]
    for part in env.parts:
        if part.kind in OTHER_KINDS - {PartKind.BRACE}:
            points = part.world_vertices()
            hits = [b.name for b in boxes if b.viaduct == part.viaduct
                    and _inside(points, b).any()]
            assert not hits, (part.name, hits)
    for part in (p for p in env.parts if p.kind is PartKind.JACKET):
        columns = [c for c in env.viaducts[part.viaduct].columns]
        z = part.world_vertices()[:, 2]
        assert z.min() < min(c.bottom_z for c in columns)
        top = max(c.top_z for c in columns) - env.config.design.embed_m - JACKET_GAP_M
        assert z.max() <= top + 1e-9


def _agrees_with_the_ray_cast(env, camera: Camera) -> np.ndarray:
    """GL's labels and depth against the ray cast's, as test_render_viaduct compares them:
    component labels on >= 99.99 % of the pixels away from edges, depth within 1 mm there.
    Returns the component labels."""
    materials = plain_materials(env)
    with Renderer(render_config(camera.width, camera.height)) as r:
        r.load(build_scene(env.parts, materials), LIGHT)
        out = r.render(camera)
    truth = ray_cast(env.parts, materials, camera)
    comp, depth = truth.component, truth.depth.astype(np.float64)
    interior = np.zeros(comp.shape, bool)
    core = (slice(1, -1), slice(1, -1))
    same = np.ones(comp[core].shape, bool)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            shifted = (slice(1 + dr, comp.shape[0] - 1 + dr),
                       slice(1 + dc, comp.shape[1] - 1 + dc))
            same &= (comp[shifted] == comp[core]) & np.isclose(depth[shifted], depth[core],
                                                               rtol=0.05)
    interior[core] = same
    assert interior.mean() > 0.5
    assert (out.component[interior] == comp[interior]).mean() >= 0.9999
    hit = interior & (depth < camera.zfar)
    assert np.abs(out.depth[hit] - depth[hit]).max() <= 1e-3
    return out.component


def _column_view(env, row: int, side: int, distance: float, eye_m: float, target_m: float,
                 **camera) -> Camera:
    """From ``distance`` outside column ``side`` (0: left) of ``row`` of viaduct 0, ``eye_m``
    above its bottom, looking at its axis ``target_m`` above its bottom."""
    column = env.viaducts[0].columns[2 * row + side]
    heading = column.heading
    outward = (1.0 if side == 0 else -1.0) * np.array([-np.sin(heading), np.cos(heading), 0])
    base = np.array([*column.center_xy, column.bottom_z])
    return look_at(base + distance * outward + [0, 0, eye_m], base + [0, 0, target_m],
                   **camera)


def test_a_view_of_others_agrees_with_the_ray_cast(jacketed, braced):
    pipe = next(p for p in jacketed.parts if p.kind is PartKind.DOWNPIPE and p.viaduct == 0)
    # The column the left downpipe runs down: the one nearest its lowest point.
    low = pipe.world_vertices()[np.argmin(pipe.world_vertices()[:, 2])]
    left = [c for c in jacketed.viaducts[0].columns[0::2]]
    row = int(np.argmin([np.hypot(*(np.array(c.center_xy) - low[:2])) for c in left]))
    comp = _agrees_with_the_ray_cast(jacketed, _column_view(jacketed, row, 0, 6.0, 1.5, 2.5))
    assert (comp == Component.OTHER).mean() > 0.05
    assert not (comp == Component.COLUMN).any()  # the jackets hide the columns
    comp = _agrees_with_the_ray_cast(braced, _column_view(braced, 1, 0, 12.0, 2.0, 3.0))
    assert (comp == Component.OTHER).mean() > 0.02 and (comp == Component.COLUMN).any()


def _small(base: Config, **rules: float) -> Config:
    cfg = config(base, **rules)
    return dataclasses.replace(
        cfg, materials=dataclasses.replace(cfg.materials, texture_size=32, builtin_size=64,
                                           images_per_category=3),
        damage=dataclasses.replace(cfg.damage, resolution=128),
        render=dataclasses.replace(cfg.render, width=160, height=90))


@pytest.mark.slow
def test_a_jacket_hides_its_column_damage():
    """Jacketed columns keep their drawn damage (the DAMAGE stream does not know of jackets),
    but the jacket is the nearest surface: the pixels a jacket covers, damaged concrete
    with the jackets off, show no damage with them on."""
    on, off = _small(load_config("demo"), jacket=1), _small(load_config("demo"))
    env = build_environment(on, 0, 0)
    dressing = dress(env, on, open_repository(on), DamageBank(on.damage, 0), set())
    spalling = next(p for p in env.parts if p.kind is PartKind.COLUMN and p.viaduct == 0
                    and dressing.assignments[p.name].damage["damaged"]
                    and spalls(on.damage, dressing.assignments[p.name].damage["severity"]))
    z0, z1 = hinge_zones(on.damage, clear_spans(env, spalling))[0]
    info = next(c for v in env.viaducts for c in v.columns if c.name == spalling.name)
    side = 0 if spalling.side == "l" else 1
    row = env.viaducts[0].columns.index(info) // 2
    centre = (info.top_z + info.bottom_z) / 2
    target = (z0 + z1) / 2 + centre - info.bottom_z
    camera = _column_view(env, row, side, 2.0, max(target, 1.5), target)
    outputs = {}
    for name, cfg in (("on", on), ("off", off)):
        view = EnvironmentView.open(cfg, 0, 0, cameras=[camera])
        with view.renderer:
            outputs[name] = view.renderer.render(camera)
    jacket = outputs["on"].component == Component.OTHER
    assert jacket.mean() > 0.2
    assert (outputs["off"].damage[jacket] != Damage.NO_DAMAGE).sum() > 20
    assert (outputs["on"].damage[jacket] == Damage.NO_DAMAGE).all()


def test_the_gltf_export_carries_the_others(jacketed, tmp_path):
    out = tmp_path / "scene.glb"
    export_environment(jacketed, out)
    data = out.read_bytes()
    length, _ = struct.unpack("<II", data[12:20])
    nodes = {n["name"]: n for n in json.loads(data[20:20 + length])["nodes"] if "mesh" in n}
    others = [p for p in jacketed.parts if p.component is Component.OTHER]
    assert others and all(nodes[p.name]["extras"]["component_id"] == Component.OTHER
                          for p in others)


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("blender") is None, reason="Blender is not installed")
def test_the_cycles_twin_draws_the_others(jacketed, tmp_path):
    """Cycles path-traces the jackets with their own material: red where GL labels class 8."""
    grey = Material(base_color=(0.4, 0.4, 0.4, 1.0))
    red = Material(base_color=(0.8, 0.05, 0.05, 1.0))
    camera = _column_view(jacketed, 1, 0, 6.0, 1.5, 2.5, width=64, height=36)
    materials = {p.name: red if p.component is Component.OTHER else grey
                 for p in jacketed.parts}
    with Renderer(render_config(64, 36)) as r:
        r.load(build_scene(jacketed.parts, materials), LIGHT)
        labels = r.render(camera).component
    linear = render_linear(jacketed.parts, materials, LIGHT, [camera], [3], 16,
                           tmp_path / "work", shutil.which("blender")).linear[0]
    colour = display(linear, LIGHT).astype(float)
    jacket = labels == Component.OTHER
    assert jacket.mean() > 0.1
    # Away from the jackets' outlines, where Cycles averages a pixel's area and GL's labels
    # take its centre: red over green of the mean colour.
    inner = np.zeros_like(jacket)
    inner[1:-1, 1:-1] = jacket[1:-1, 1:-1] & jacket[1:-1, :-2] & jacket[1:-1, 2:]
    outer = np.zeros_like(jacket)
    outer[1:-1, 1:-1] = ~(jacket[1:-1, 1:-1] | jacket[1:-1, :-2] | jacket[1:-1, 2:])
    assert inner.sum() > 50 and outer.sum() > 500
    red = {name: colour[mask, 0].mean() / colour[mask, 1].mean()
           for name, mask in (("jacket", inner), ("rest", outer))}
    assert red["jacket"] > 3.0 and red["rest"] < 1.5, red


def test_a_plate_shows_a_number_once_on_its_face(jacketed):
    """A plate's material is its number's image (glsynth.appearance.signs), scaled so that
    the outer face shows it once, upright and left to right as seen from outside."""
    cfg = _small(jacketed.config)
    dressing = dress(jacketed, cfg, open_repository(cfg), DamageBank(cfg.damage, 0), set())
    signs = [p for p in jacketed.parts if p.kind is PartKind.SIGN]
    numbers = set()
    for part in signs:
        material = dressing.materials[part.name]
        number = next(n for n in range(1, 1000)
                      if np.array_equal(plate_image(n), material.base_color_map))
        numbers.add(number)
        mesh = part.mesh
        column = min((c for v in jacketed.viaducts for c in v.columns),
                     key=lambda c: np.hypot(*(np.array(c.center_xy) - mesh.centroid[:2])))
        across = np.array([-np.sin(column.heading), np.cos(column.heading), 0.0])
        outward = np.sign((mesh.centroid[:2] - column.center_xy) @ across[:2]) * across
        # The outer face: its UVs times uv_scale span [0, 1], u growing to the viewer's right
        # (looking at the face from outside, up is +z), v growing up.
        face = mesh.faces[mesh.face_normals @ outward > 0.99].ravel()
        uv = mesh.visual.uv[face] * material.uv_scale
        assert np.allclose(uv.min(0), 0.0) and np.allclose(uv.max(0), 1.0)
        right = np.cross(-outward, [0.0, 0.0, 1.0])
        xyz = mesh.vertices[face]
        assert np.corrcoef(uv[:, 0], xyz @ right)[0, 1] > 0.99
        assert np.corrcoef(uv[:, 1], xyz[:, 2])[0, 1] > 0.99
    assert len(signs) == len(jacketed.viaducts) and len(numbers) > 1
    ink = plate_image(407) != plate_image(0)
    assert ink.any() and not np.array_equal(plate_image(407), plate_image(408))
