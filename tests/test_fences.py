"""See-through fences ([environment] fences = "open", glsynth.world.fences): posts, rails and
bars with openings that show what lies behind, in the render, the ray cast and the glTF alike."""

import dataclasses

import numpy as np
import pytest
import trimesh
from glhelpers import LIGHT, camera, plain_materials, render_config

from glsynth.core.config import Config, EnvironmentConfig, config_from_dict, load_config
from glsynth.core.errors import UserError
from glsynth.core.labels import Component
from glsynth.render.gl.renderer import Renderer
from glsynth.render.gltf import gltf_binary
from glsynth.render.raycast import ray_cast
from glsynth.render.scene import build_scene
from glsynth.world import fences
from glsynth.world.environment import PartKind, build_environment

W, H = 200, 150
DISTANCE = 2.5
"""The camera stands this far outside the deck edge."""


def _env(kind: str):
    config = dataclasses.replace(Config(), environment=EnvironmentConfig(
        n_viaducts=4, fences=kind))
    return build_environment(config, 0, 0)


@pytest.fixture(scope="module")
def envs():
    return {kind: _env(kind) for kind in ("solid", "open")}


def _frame(env, viaduct: float = 1.5):
    s = np.array([viaduct * env.config.design.length_m])
    points, _, normal = env.trajectory.frame(s)
    return points[0], normal[0]


def _fence_camera(env):
    """Outside the left fence, a little above it, looking across the deck."""
    deck, across = _frame(env)
    eye = deck + (env.config.design.deck_width_m / 2 + DISTANCE) * across
    eye[2] += 1.0
    target = deck + [0.0, 0.0, 0.5]
    z = (eye - target) / np.linalg.norm(eye - target)
    x = np.cross([0.0, 0.0, 1.0], z)
    x /= np.linalg.norm(x)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = x, np.cross(z, x), z, eye
    return camera(W, H, 24.0, pose)


def test_switch_defaults_presets_and_refusal():
    assert Config().environment.fences == "solid" == load_config("paper").environment.fences
    assert load_config("demo").environment.fences == "open"
    assert load_config("inspection").environment.fences == "open"
    with pytest.raises(UserError, match="fences"):
        config_from_dict({"environment": {"fences": "mesh"}})


def test_open_fences_replace_the_solid_ones_in_place(envs):
    solid, open_ = envs["solid"], envs["open"]
    assert [(p.name, p.kind) for p in solid.parts] == [(p.name, p.kind) for p in open_.parts]
    for a, b in zip(solid.parts, open_.parts):
        if a.kind is not PartKind.FENCE:
            assert np.array_equal(a.mesh.vertices, b.mesh.vertices), a.name
            continue
        # The railing fills the solid fence's band, and is far lighter than a wall of its size.
        assert np.allclose(a.mesh.bounds, b.mesh.bounds, atol=0.02), a.name
        assert b.mesh.volume < 0.5 * a.mesh.volume


def test_posts_and_bars_leave_no_opening_wider_than_the_spacing():
    posts, bars = fences._positions(0.0, 23.4)
    assert posts[0] == fences.POST_WIDTH_M / 2 and posts[-1] == 23.4 - fences.POST_WIDTH_M / 2
    assert np.diff(posts).max() <= fences.POST_SPACING_M + 1e-9
    uprights = np.sort(np.concatenate([posts, bars]))
    assert np.diff(uprights).max() <= fences.BAR_SPACING_M + fences.POST_WIDTH_M


def _embree(parts):
    from trimesh.ray.ray_pyembree import RayMeshIntersector

    scene = trimesh.util.concatenate([trimesh.Trimesh(p.world_vertices(), p.mesh.faces,
                                                      process=False) for p in parts])
    return RayMeshIntersector(scene)


def test_a_ray_through_an_opening_reaches_what_lies_behind(envs):
    """Level rays across the track at mid height, from outside the left fence: through the
    middle of each opening they pass the fence, through a bar they stop at it."""
    env = envs["open"]
    d = env.config.design
    i = 1
    posts, bars = fences._positions(i * d.length_m, (i + 1) * d.length_m)
    gaps = (bars[1:] + bars[:-1]) / 2
    gaps = gaps[np.diff(bars) < fences.BAR_SPACING_M + 1e-9]  # two bars, no post between
    results = {}
    for name, s in (("gap", gaps), ("bar", bars)):
        points, _, normal = env.trajectory.frame(s)
        origin = points + (d.deck_width_m / 2 + 1.0) * normal
        origin[:, 2] += d.fence_height_m / 2
        for kind in ("solid", "open"):
            _, ray, loc = _embree(envs[kind].parts).intersects_id(
                origin, -normal, multiple_hits=False, return_locations=True)
            assert sorted(ray) == list(range(len(origin)))
            distance = np.einsum("ij,ij->i", loc - origin[ray], -normal[ray])
            # Past the fence (1 m to 1.1 m along the ray) by more than a metre.
            results[name, kind] = distance > 1.0 + d.fence_thickness_m + 1.0
    assert not results["gap", "solid"].any() and not results["bar", "open"].any()
    assert results["gap", "open"].all()


@pytest.fixture(scope="module")
def fence_views(envs):
    out = {}
    for kind, env in envs.items():
        cam = _fence_camera(env)
        mats = plain_materials(env)
        with Renderer(render_config(W, H)) as r:
            r.load(build_scene(env.parts, mats), LIGHT)
            out[kind] = (r.render(cam), ray_cast(env.parts, mats, cam))
    return out


def test_the_render_shows_the_background_through_the_openings(fence_views):
    solid, _ = fence_views["solid"]
    open_, _ = fence_views["open"]
    fence = solid.component == Component.NONSTRUCTURAL
    near = fence & (solid.depth < DISTANCE + 2.0)  # the solid fence's face fills these
    assert near.mean() > 0.15
    behind = near & (open_.depth > solid.depth + 1.0)
    assert behind.sum() > 0.3 * near.sum()
    assert len(np.unique(open_.component[behind])) >= 2  # the track and deck behind it


def test_labels_and_depth_agree_with_the_ray_cast_through_the_openings(fence_views):
    render, truth = fence_views["open"]
    inner = np.zeros(truth.depth.shape, bool)
    core = (slice(1, -1), slice(1, -1))
    same = np.ones(truth.depth[core].shape, bool)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            s = (slice(1 + dr, H - 1 + dr), slice(1 + dc, W - 1 + dc))
            same &= truth.component[s] == truth.component[core]
            same &= np.isclose(truth.depth[s], truth.depth[core], rtol=0.05)
    inner[core] = same
    solid, _ = fence_views["solid"]
    through = inner & (solid.component == Component.NONSTRUCTURAL) & (
        truth.depth > solid.depth + 1.0)
    assert through.sum() > 500
    for mask in (inner, through):
        assert (render.component[mask] == truth.component[mask]).mean() >= 0.9999
        assert np.abs(render.depth[mask] - truth.depth[mask]).max() < 1e-3


def test_the_gltf_carries_the_open_fence(envs):
    env = envs["open"]
    fence = [p for p in env.parts if p.kind is PartKind.FENCE][:2]
    import io

    scene = trimesh.load(io.BytesIO(gltf_binary(fence, plain_materials(env))),
                         file_type="glb", process=False)
    for part in fence:
        transform, geometry = scene.graph[part.name]
        loaded = trimesh.transform_points(scene.geometry[geometry].vertices, transform)
        world = part.world_vertices()
        assert np.allclose(loaded, np.c_[world[:, 0], world[:, 2], -world[:, 1]], atol=1e-4)
        assert len(scene.geometry[geometry].faces) == len(part.mesh.faces)
