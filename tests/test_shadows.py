"""Sun shadows: the light frustum (pure numpy) and the rendered shadow map, on constructed
scenes whose shadow is known exactly."""

import dataclasses

import numpy as np
import pytest
from glhelpers import LIGHT, camera, quad, render_config, scene_of

from glsynth.appearance.materials import Material
from glsynth.core.config import RenderConfig
from glsynth.core.labels import Component
from glsynth.render.gl.renderer import Renderer
from glsynth.world.sunlight import (
    frustum_corners,
    light_frame,
    shadow_casters,
    shadow_matrix,
    shadow_texel_m,
)

PLAIN = Material(base_color=(0.6, 0.6, 0.6, 1.0))
# The sun straight along +z: behind the default camera, which looks down -z.
ZENITH = dict(sun_elevation_deg=90.0, sun_azimuth_deg=0.0)


def sun_at(elevation: float, azimuth: float = 0.0) -> np.ndarray:
    return dataclasses.replace(LIGHT, sun_elevation_deg=elevation,
                               sun_azimuth_deg=azimuth).sun_direction


@pytest.mark.parametrize("elevation", [90.0, 50.0, 5.0, -10.0])
def test_light_frame_is_a_rotation_looking_away_from_the_sun(elevation):
    frame = light_frame(sun_at(elevation))
    assert np.allclose(frame @ frame.T, np.eye(3)) and np.isclose(np.linalg.det(frame), 1.0)
    assert np.allclose(frame[2], sun_at(elevation))


@pytest.mark.parametrize("distance", [1.0, 60.0, 5000.0])
def test_the_shadowed_frustum_fits_inside_the_shadow_map(distance):
    render = dataclasses.replace(RenderConfig(), shadow_distance_m=distance)
    pose = np.eye(4)
    pose[:3, 3] = [120.0, -40.0, 6.0]
    cam = camera(1920, 1080, 15.0, pose=pose)
    matrix = shadow_matrix(cam, render, sun_at(50.0, 30.0))
    corners = frustum_corners(cam, distance)
    clip = np.c_[corners, np.ones(8)] @ matrix.T
    assert np.all(np.abs(clip[:, :3]) < 1.0) and np.allclose(clip[:, 3], 1.0)
    # Square texels; 1000 of them span the footprint's longer side plus a 1 % margin.
    local = corners @ light_frame(sun_at(50.0, 30.0)).T
    side = (local.max(0) - local.min(0))[:2].max()
    assert shadow_texel_m(matrix, 1000) * 1000 == pytest.approx(side * 1.01, rel=1e-3)
    assert np.isclose(np.linalg.norm(matrix[0, :3]), np.linalg.norm(matrix[1, :3]))


def test_casters_are_the_parts_above_and_not_those_aside_or_below():
    render = dataclasses.replace(RenderConfig(), shadow_distance_m=20.0)
    cam = camera()  # looking down -z from the origin: with a zenith sun, straight away from it
    box = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    above = box + [0, 0, 300]         # far towards the sun, over the view
    aside = box + [500, 0, 300]       # towards the sun, but not over the view
    below = box + [0, 0, -100]        # farther from the sun than every receiver
    casts = shadow_casters(np.stack([above, aside, below]), [cam], sun_at(90.0),
                           [render.shadow_distance_m])
    assert casts.tolist() == [True, False, False]


def _scene(with_roof: bool):
    ground = quad([[-20, -20, -10], [20, -20, -10], [20, 20, -10], [-20, 20, -10]])
    items = [("ground_plane", Component.NONBRIDGE, ground, PLAIN)]
    if with_roof:
        # Over x > 0 only, 500 m towards the sun: far outside the shadow map's depth range, so
        # it shadows only through depth clamping.
        roof = quad([[0, -40, 500], [40, -40, 500], [40, 40, 500], [0, 40, 500]])
        items.append(("slab_roof", Component.SLAB, roof, PLAIN))
    return scene_of(*items)


def _render(scene, sun_irradiance: float = 3.0, **render):
    """The sun from kwargs sun_elevation_deg / sun_azimuth_deg; no occlusion of the ambient
    light, so that only the sun's shadow changes pixels."""
    light = {k: render.pop(k) for k in ("sun_elevation_deg", "sun_azimuth_deg") if k in render}
    lighting = dataclasses.replace(LIGHT, sun_irradiance=sun_irradiance, **light)
    with Renderer(dataclasses.replace(render_config(64, 48), ao="off", sky_visibility_maps=0,
                                      **render)) as r:
        r.load(scene, lighting)
        out = r.render(camera())
        assert r.ctx.error == "GL_NO_ERROR"
        return out


def test_a_roof_far_towards_the_sun_shadows_exactly_its_half_of_the_ground():
    shadowed = _render(_scene(True), **ZENITH, shadow_map_px=512)
    lit = _render(_scene(True), **ZENITH, shadow_map_px=0)
    ambient = _render(_scene(True), **ZENITH, shadow_map_px=0, sun_irradiance=0.0)
    # The roof covers world x > 0: image columns right of the centre (fx = 64, 64 px wide).
    left, right = slice(0, 29), slice(35, 64)
    assert np.array_equal(shadowed.color[:, left], lit.color[:, left])
    assert np.abs(shadowed.color[:, right].astype(int) - ambient.color[:, right]).max() <= 1
    assert shadowed.color[:, right].mean() < lit.color[:, right].mean() - 20
    # Shadows only shade: labels and depth are untouched.
    for name in ("component", "damage", "depth"):
        assert np.array_equal(getattr(shadowed, name), getattr(lit, name)), name


def test_beyond_the_shadow_distance_everything_is_lit_and_without_casters_nothing_changes():
    far = _render(_scene(True), **ZENITH, shadow_map_px=512, shadow_distance_m=5.0)
    lit = _render(_scene(True), **ZENITH, shadow_map_px=0)
    assert np.array_equal(far.color, lit.color)
    # No caster at all: the shadow pass runs and changes no pixel (no acne on the lit ground).
    alone = _render(_scene(False), **ZENITH, shadow_map_px=512)
    assert np.array_equal(alone.color, _render(_scene(False), **ZENITH, shadow_map_px=0).color)


@pytest.mark.parametrize("value", [32, -1, 1.5, True])
def test_shadow_map_size_is_checked(value):
    with pytest.raises(ValueError, match=r"render\.shadow_map_px"):
        RenderConfig(shadow_map_px=value)
