"""Severe damage as geometry ([damage] geometry = true, glsynth.world.severe): a severe column's
hinge bands lose concrete, show buckled bars and broken hoops in depth, labels and silhouette,
as the CPU ray cast and the glTF (the Cycles twin's scene) see them too."""

import dataclasses
import io
import json
import struct

import numpy as np
import pytest
from glhelpers import LIGHT, camera, render_config

from glsynth.appearance.damage_bank import DamageBank
from glsynth.appearance.dressing import dress, open_repository
from glsynth.core.config import Config, config_from_dict, load_config
from glsynth.core.errors import UserError
from glsynth.core.labels import Component, Damage
from glsynth.core.seeding import Stream, make_rng
from glsynth.render.gl.renderer import Renderer
from glsynth.render.gltf import gltf_binary
from glsynth.render.raycast import ray_cast
from glsynth.render.scene import build_scene
from glsynth.world import meshes
from glsynth.world.environment import PartKind, build_environment
from glsynth.world.severe import (
    TUBE_SEGMENTS,
    Band,
    column_damage_rng,
    crushed_bands,
    crushed_surface,
    draw_severity,
    severe_column,
    tubes,
)

W, H = 240, 300
DISTANCE = 1.5
"""The camera stands this far in front of the column face: a bar is 3-4 pixels wide."""


def _config(geometry: bool) -> Config:
    demo = load_config("demo")
    return dataclasses.replace(
        demo, environment=dataclasses.replace(demo.environment, n_viaducts=4),
        damage=dataclasses.replace(demo.damage, resolution=64, geometry=geometry),
        materials=dataclasses.replace(demo.materials, texture_size=32))


@pytest.fixture(scope="module")
def envs():
    return build_environment(_config(True), 3, 0), build_environment(_config(False), 3, 0)


def _severe_columns(env):
    return [(i, p) for i, p in enumerate(env.parts) if p.kind is PartKind.COLUMN
            and draw_severity(env.config.damage, column_damage_rng(3, 0, i)) == "severe"]


def test_switch_defaults_and_presets():
    assert Config().damage.geometry is False and load_config("paper").damage.geometry is False
    assert load_config("demo").damage.geometry and load_config("inspection").damage.geometry
    with pytest.raises(UserError, match="geometry"):
        config_from_dict({"damage": {"geometry": 1}})


def test_parts_are_appended_and_only_severe_columns_change(envs):
    on, off = envs
    n = len(off.parts)
    assert [(p.name, p.kind) for p in on.parts[:n]] == [(p.name, p.kind) for p in off.parts]
    severe = dict(_severe_columns(on))
    assert len(severe) >= 3
    for i, (a, b) in enumerate(zip(on.parts[:n], off.parts)):
        same = np.array_equal(a.mesh.vertices, b.mesh.vertices)
        assert same != (i in severe), a.name
        # A cut column keeps its box's bounds (face cameras and cracks read them).
        assert np.allclose(a.mesh.bounds, b.mesh.bounds) and np.array_equal(a.pose, b.pose)
    added = on.parts[n:]
    assert [p.kind for p in added] == [PartKind.CRUSHED, PartKind.REBAR] * len(severe)
    assert {p.component for p in added} == {Component.COLUMN}
    # Each pair lies within its column's box, grown by what buckled steel may stick out.
    for (_, column), pair in zip(severe.items(), np.reshape(added, (-1, 2))):
        local = np.linalg.solve(column.pose, np.c_[pair[1].world_vertices(),
                                                   np.ones(len(pair[1].mesh.vertices))].T).T
        assert np.all(np.abs(local[:, :2]) <= column.mesh.extents[:2] / 2 + 0.2)


def test_new_parts_are_named_by_the_convention_and_face_outwards(envs):
    on, off = envs
    assert {PartKind.CRUSHED, PartKind.REBAR} <= {p.kind for p in on.parts}
    names = [p.name for p in on.parts]
    assert len(names) == len(set(names))
    for part in on.parts[len(off.parts):]:
        words = part.name.split("_")
        assert words[0] == "column" and part.kind.value in words


def test_the_crushed_surface_faces_outward_around_a_reduced_section():
    section, band = (0.8, 0.7), Band(0.0, 1.0, 0.05, 0.15)
    mesh = crushed_surface(section, band, make_rng(0, 0, Stream.SEVERE))
    v = mesh.vertices[mesh.faces]
    # Closed by the intact rectangles at both ends (the top one, at z = 1, facing +z): by
    # the divergence theorem its volume, positive only if the faces face outward.
    volume = np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6 \
        + section[0] * section[1] / 3
    intact = section[0] * section[1]
    deepest = (section[0] - 2 * band.loss_m) * (section[1] - 2 * band.loss_m)
    assert deepest < volume < 0.9 * intact
    # The ends meet the intact box's edges.
    for z in (band.z0, band.z1):
        ring = mesh.vertices[np.isclose(mesh.vertices[:, 2], z)]
        assert np.allclose(np.abs(ring[:, :2]).max(axis=0), np.array(section) / 2)
        on_edge = np.isclose(np.abs(ring[:, 0]), section[0] / 2) | np.isclose(
            np.abs(ring[:, 1]), section[1] / 2)
        assert on_edge.all()


def test_the_dressing_calls_the_same_columns_severe(envs):
    on, _ = envs
    cfg = on.config
    dressing = dress(on, cfg, open_repository(cfg), DamageBank(cfg.damage, 3), set())
    severe = {p.name for _, p in _severe_columns(on)}
    recorded = {p.name for p in on.parts if p.kind is PartKind.COLUMN
                and dressing.assignments[p.name].damage.get("severity") == "severe"}
    assert severe == recorded
    for part in on.parts:
        if part.kind in (PartKind.CRUSHED, PartKind.REBAR):
            mask = dressing.materials[part.name].damage_mask
            expected = Damage.CONCRETE if part.kind is PartKind.CRUSHED else Damage.REBAR
            assert mask.shape == (1, 1) and mask[0, 0] == expected


def test_bands_sit_in_the_hinge_zones_and_the_box_is_cut_there(envs):
    on, _ = envs
    for ordinal, part in _severe_columns(on)[:4]:
        rng = make_rng(3, 0, Stream.SEVERE, ordinal)
        section = tuple(float(e) for e in part.mesh.extents[:2])
        spans = [(-part.mesh.extents[2] / 2, part.mesh.extents[2] / 2 - 0.05)]
        bands = crushed_bands(on.config.damage, section, spans, rng)
        depth = max(section)
        (z0, z1), = spans
        assert len(bands) == 2
        assert 0.1 * depth - 1e-9 <= bands[0].z0 - z0 and bands[0].z1 - z0 <= 1.5 * depth
        assert 0.1 * depth - 1e-9 <= z1 - bands[1].z1 and z1 - bands[1].z0 <= 1.5 * depth
        assert all(b.cover_m < b.loss_m < min(section) / 2 for b in bands)
        cut, _, _ = severe_column(on.config, part, spans, make_rng(3, 0, Stream.SEVERE, ordinal))
        z = cut.vertices[:, 2]
        for band in bands:  # no surface of the box is left inside a band
            assert not np.any((z > band.z0 + 1e-9) & (z < band.z1 - 1e-9))
        # The sides keep the whole box's UVs: v runs up from the column's foot.
        side = np.abs(cut.vertex_normals[:, 2]) < 0.5
        assert np.allclose(cut.visual.uv[side, 1], z[side] + part.mesh.extents[2] / 2)


def test_tubes_are_the_sweeps_they_vectorise():
    rng = make_rng(0, 0, Stream.SEVERE)
    paths = [np.cumsum(rng.normal(size=(k, 3)), axis=0) for k in (5, 7, 5)]
    hints = [np.tile([0.0, 0.0, 1.0], (len(p), 1)) for p in paths]
    merged = tubes(paths, hints, 0.02)
    singles = []
    for path, hint in zip(paths, hints):
        d = np.gradient(path, axis=0)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        up = hint - np.sum(hint * d, axis=1, keepdims=True) * d
        up /= np.linalg.norm(up, axis=1, keepdims=True)
        singles.append(meshes.sweep(meshes.circle(0.02, TUBE_SEGMENTS), path, np.cross(up, d),
                                    up, closed=True, smooth=True, caps=True))
    # Grouped by length: the two 5-point paths first, then the 7-point one.
    expected = [singles[0], singles[2], singles[1]]
    assert np.allclose(merged.vertices, np.concatenate([m.vertices for m in expected]))
    assert np.allclose(merged.visual.uv, np.concatenate([m.visual.uv for m in expected]))
    # Capped tubes with outward faces: a positive volume, the sweeps' own.
    assert merged.volume > 0
    assert np.isclose(merged.volume, sum(m.volume for m in singles))


def _band_camera(env, column, band_z: float):
    """DISTANCE in front of a column's +x face, level with ``band_z`` (world), looking at it."""
    r = column.pose[:3, :3]
    target = column.pose[:3, 3].copy()
    target[2] = band_z
    eye = target + (DISTANCE + column.mesh.extents[0] / 2) * r[:, 0]
    z = r[:, 0]
    x = np.cross([0.0, 0.0, 1.0], z)
    x /= np.linalg.norm(x)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = x, np.cross(z, x), z, eye
    return camera(W, H, 30.0, pose)


def _no_cracks(materials, names):
    """The materials without cracks: the ray cast does not cast them (glsynth.render.raycast)."""
    return {n: dataclasses.replace(materials[n], cracks=None) for n in names}


@pytest.fixture(scope="module")
def band_views(envs):
    on, off = envs
    ordinal, column = _severe_columns(on)[0]
    crushed = next(p for p in on.parts if p.kind is PartKind.CRUSHED)
    band_z = float(crushed.world_vertices()[:, 2].min()) + 0.3
    cam = _band_camera(on, column, band_z)
    out = {}
    for env in (on, off):
        cfg = env.config
        dressing = dress(env, cfg, open_repository(cfg), DamageBank(cfg.damage, 3),
                         {column.name})
        mats = _no_cracks(dressing.materials, [p.name for p in env.parts])
        with Renderer(render_config(W, H)) as r:
            r.load(build_scene(env.parts, mats), LIGHT)
            out[env is on] = (r.render(cam), ray_cast(env.parts, mats, cam))
    return cam, out


def test_a_severe_column_depth_follows_the_lost_concrete_and_the_buckled_bars(band_views):
    _, out = band_views
    (on, _), (off, _) = out[True], out[False]
    column = off.component == Component.COLUMN
    assert column.mean() > 0.08
    deeper = (on.depth - off.depth > 0.02) & column & (on.component == Component.COLUMN)
    nearer = (off.depth - on.depth > 0.005) & (on.component == Component.COLUMN)
    assert deeper.sum() > 200, "no lost concrete in depth"
    assert nearer.sum() > 20, "no buckled bar in front of the face"
    assert (on.damage[deeper] != Damage.NO_DAMAGE).mean() > 0.95
    assert {Damage.CONCRETE, Damage.REBAR} <= set(np.unique(on.damage[column]).tolist())
    # The silhouette: rows where the intact prism shows column but the damaged one does not.
    assert np.any(column & (on.component != Component.COLUMN))


def _interior(depth: np.ndarray, comp: np.ndarray, dmg: np.ndarray) -> np.ndarray:
    """Pixels whose 3x3 neighbourhood has one component and damage id and a smooth depth."""
    inner = np.zeros(depth.shape, bool)
    core = (slice(1, -1), slice(1, -1))
    same = np.ones(depth[core].shape, bool)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            s = (slice(1 + dr, depth.shape[0] - 1 + dr), slice(1 + dc, depth.shape[1] - 1 + dc))
            same &= (comp[s] == comp[core]) & (dmg[s] == dmg[core])
            same &= np.isclose(depth[s], depth[core], rtol=0.05)
    inner[core] = same
    return inner


def test_labels_and_depth_agree_with_the_ray_cast(band_views):
    cam, out = band_views
    render, truth = out[True]
    inner = _interior(truth.depth, truth.component, truth.damage)
    hit = inner & (truth.depth < cam.zfar)
    assert hit.sum() > 0.3 * hit.size
    assert (render.component[inner] == truth.component[inner]).mean() >= 0.9999
    assert (render.damage[inner] == truth.damage[inner]).mean() >= 0.9999
    assert np.abs(render.depth[hit] - truth.depth[hit]).max() < 1e-3
    for kind_id in (Damage.CONCRETE, Damage.REBAR):
        assert (truth.damage[inner] == kind_id).sum() > 20


def test_the_gltf_carries_the_new_parts_with_their_damage(envs):
    on, _ = envs
    cfg = on.config
    dressing = dress(on, cfg, open_repository(cfg), DamageBank(cfg.damage, 3), set())
    parts = [p for p in on.parts if p.kind in (PartKind.CRUSHED, PartKind.REBAR)][:4]
    data = gltf_binary(parts, dressing.materials)
    length = struct.unpack("<I", data[12:16])[0]
    tree = json.loads(data[20:20 + length])
    nodes = {n["name"]: n for n in tree["nodes"] if "mesh" in n}
    assert sorted(nodes) == sorted(p.name for p in parts)
    import trimesh
    from PIL import Image

    scene = trimesh.load(io.BytesIO(data), file_type="glb", process=False)
    for part in parts:
        transform, geometry = scene.graph[part.name]
        loaded = trimesh.transform_points(scene.geometry[geometry].vertices, transform)
        world = part.world_vertices()
        assert np.allclose(loaded, np.c_[world[:, 0], world[:, 2], -world[:, 1]], atol=1e-4)
        primitive = tree["meshes"][nodes[part.name]["mesh"]]["primitives"][0]
        extras = tree["materials"][primitive["material"]]["extras"]["glsynth_damage_mask"]
        image = tree["images"][tree["textures"][extras["index"]]["source"]]
        view = tree["bufferViews"][image["bufferView"]]
        start = 20 + length + 8 + view.get("byteOffset", 0)
        mask = np.asarray(Image.open(io.BytesIO(data[start:start + view["byteLength"]])))
        assert mask.size == 1 and int(mask.flat[0]) == int(
            Damage.CONCRETE if part.kind is PartKind.CRUSHED else Damage.REBAR)
