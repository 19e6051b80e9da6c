"""Lighting (glsynth.world.lighting, shaders/color.frag, sky.frag, ssao.frag): closed-form
oracles, the sky model against its published formulas and against Blender, occlusion on
constructed scenes, and the extremes of the sun."""

import dataclasses
import math
import shutil

import numpy as np
import pytest
from glhelpers import LIGHT, camera, quad, render_config, scene_of

from glsynth.appearance.materials import Material
from glsynth.core.config import LightingConfig, RenderConfig
from glsynth.core.labels import Component
from glsynth.render.gl.renderer import Renderer
from glsynth.render.tonemap import tone_map
from glsynth.world.environment import Part, PartKind
from glsynth.world.lighting import (
    XYZ_TO_REC709,
    Preetham,
    environment_lighting,
    preetham_radiance,
    sh_basis,
    sky_directions,
)

NO_OCCLUSION = dict(ao="off", sky_visibility_maps=0, shadow_map_px=0)


def _render(scene, lighting, passes=frozenset({"color", "component", "damage", "depth"}),
            cam=None, **render):
    config = dataclasses.replace(render_config(64, 48), **render)
    with Renderer(config) as r:
        r.load(scene, lighting)
        out = r.render(cam or camera(), passes)
        assert r.ctx.error == "GL_NO_ERROR"
        ao = np.frombuffer(r.ao.read(), np.float16).reshape(config.height, config.width)
        ao = ao[::-1].astype(float)
        return out, ao


def _floor(material: Material, size: float = 50.0):
    """A horizontal plane (normal +z) 10 m below the camera, which looks straight down."""
    plane = quad([[-size, -size, -10], [size, -size, -10], [size, size, -10],
                  [-size, size, -10]])
    return scene_of(("ground_plane", Component.NONBRIDGE, plane, material))


def _ggx_radiance(base: float, metallic: float, roughness: float, n, v, to_sun,
                  sun: float, env: float) -> float:
    """The shader's BRDF (Burley diffuse as Cycles' Principled BSDF, GGX specular with Schlick
    Fresnel and Smith-Schlick shadowing) in closed form for a uniform environment of radiance
    ``env`` (every direction, so its irradiance is pi * env for any normal) and a sun of
    irradiance ``sun``."""
    n, v, s = (np.asarray(x, float) / np.linalg.norm(x) for x in (n, v, to_sun))
    h = (v + s) / np.linalg.norm(v + s)
    nl, nv = max(n @ s, 0.0), max(n @ v, 1e-4)
    nh, vh = max(n @ h, 0.0), max(v @ h, 0.0)
    r = min(max(roughness, 0.04), 1.0)
    a2 = (r * r) ** 2
    d = a2 / (math.pi * (nh * nh * (a2 - 1) + 1) ** 2)
    k = (r + 1) ** 2 / 8
    g = (nl / (nl * (1 - k) + k)) * (nv / (nv * (1 - k) + k))
    f0 = 0.04 * (1 - metallic) + base * metallic
    f = f0 + (1 - f0) * (1 - vh) ** 5
    specular = d * g * f / max(4 * nl * nv, 1e-4)
    fl, fv = (1 - nl) ** 5, (1 - nv) ** 5
    rr = r * (1 + s @ v)
    burley = (1 - 0.5 * fl) * (1 - 0.5 * fv) + rr * (fl + fv + fl * fv * (rr - 1))
    diffuse = burley * (1 - metallic) * base / math.pi
    f_env = f0 + (max(1 - r, f0) - f0) * (1 - nv) ** 5
    ambient = (1 - metallic) * base * env + f_env * env * (1 - 0.7 * r)
    return (diffuse + specular) * sun * nl + ambient


@pytest.mark.parametrize("metallic,roughness", [(0.0, 1.0), (0.0, 0.35), (1.0, 0.5)])
def test_a_plane_under_a_known_sun_and_sky_has_the_closed_form_radiance(metallic, roughness):
    """A rough dielectric plane (Burley diffuse) and GGX planes, lit by a sun and a uniform
    environment (the uniform sky above, a ground of the same radiance below), within one
    8-bit step."""
    sky_radiance, sun = 0.12, 2.0
    elevation = 60.0
    # The ground's radiance albedo / pi x (pi x sky + sun x sin(elevation)) equals the sky's.
    albedo = math.pi * sky_radiance / (math.pi * sky_radiance + sun * math.sin(
        math.radians(elevation)))
    lighting = dataclasses.replace(
        LIGHT, sky="uniform", sky_rgb=(1.0, 1.0, 1.0), sky_strength=sky_radiance,
        sun_elevation_deg=elevation, sun_azimuth_deg=0.0, sun_irradiance=sun,
        ground_albedo=(albedo,) * 3)
    base = 0.45
    material = Material(base_color=(base, base, base, 1.0), metallic=metallic,
                        roughness=roughness)
    cam = camera()
    out, _ = _render(_floor(material), lighting, cam=cam, **NO_OCCLUSION)
    k = cam.K
    for row in range(20, 28):
        for col in range(28, 36):
            # Towards the camera from the point this pixel centre sees (camera = world here).
            view = -np.array([(col - k[0, 2]) / k[0, 0], -(row - k[1, 2]) / k[1, 1], -1.0])
            expected = _ggx_radiance(base, metallic, roughness, [0, 0, 1], view,
                                     lighting.sun_direction, sun, sky_radiance)
            target = tone_map(np.array([expected] * 3), 1.0).astype(int)
            assert np.abs(out.color[row, col].astype(int) - target).max() <= 1, (row, col)


def test_the_numpy_and_glsl_tone_maps_agree_on_the_sky():
    for exposure in (0.5, 1.0, 3.0):
        lighting = dataclasses.replace(LIGHT, sky="uniform", sky_rgb=(0.62, 0.74, 0.88),
                                       sky_strength=0.6, exposure=exposure)
        out, _ = _render(scene_of(), lighting, {"color"})
        expected = tone_map(np.array(lighting.sky_rgb) * 0.6, exposure)
        assert np.abs(out.color.reshape(-1, 3).astype(int) - expected).max() <= 1


def test_the_glsl_sky_is_the_numpy_preetham_sky_in_every_pixel():
    pose = np.eye(4)
    pose[:3, :3] = [[0, 0, 1], [1, 0, 0], [0, 1, 0]]  # looking along -y... at the horizon
    cam = camera(64, 48, 12.0, pose=pose)  # wide: elevations from about -30 to 30 deg
    lighting = dataclasses.replace(LIGHT, sun_elevation_deg=20.0, sun_azimuth_deg=250.0,
                                   exposure=2.0)
    out, _ = _render(scene_of(), lighting, {"color"}, cam=cam)
    k = cam.K
    cols, rows = np.meshgrid(np.arange(64), np.arange(48))
    rays = np.stack([(cols - k[0, 2]) / k[0, 0], -(rows - k[1, 2]) / k[1, 1],
                     -np.ones_like(cols, float)], -1).reshape(-1, 3)
    dirs = rays @ pose[:3, :3].T
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    expected = tone_map(lighting.sky_radiance(dirs), 2.0).reshape(48, 64, 3)
    assert np.abs(out.color.astype(int) - expected).max() <= 1


def test_the_preetham_sky_matches_the_published_zenith_values():
    """At the zenith, Y, x and y are the model's zenith formulas (Preetham et al. 1999,
    Appendix A.2; Y x 0.06 as Blender scales it), here written out independently."""
    for turbidity, elevation in ((2.0, 60.0), (3.0, 30.0), (6.0, 10.0)):
        theta = math.radians(90.0 - elevation)
        sun = np.array([math.sin(theta), 0.0, math.cos(theta)])
        chi = (4 / 9 - turbidity / 120) * (math.pi - 2 * theta)
        y_zenith = ((4.0453 * turbidity - 4.9710) * math.tan(chi) - 0.2155 * turbidity
                    + 2.4192) * 0.06
        t = np.array([turbidity ** 2, turbidity, 1.0])
        x_zenith = t @ np.array([[0.00166, -0.00375, 0.00209, 0.0],
                                 [-0.02903, 0.06377, -0.03202, 0.00394],
                                 [0.11693, -0.21196, 0.06052, 0.25886]]) @ [theta ** 3,
                                                                             theta ** 2,
                                                                             theta, 1.0]
        y_chr = t @ np.array([[0.00275, -0.00610, 0.00317, 0.0],
                              [-0.04214, 0.08970, -0.04153, 0.00516],
                              [0.15346, -0.26756, 0.06670, 0.26688]]) @ [theta ** 3,
                                                                          theta ** 2,
                                                                          theta, 1.0]
        xyz = np.array([x_zenith / y_chr * y_zenith, y_zenith,
                        (1 - x_zenith - y_chr) / y_chr * y_zenith])
        rgb = preetham_radiance(Preetham.make(turbidity, sun), sun, np.array([[0, 0, 1.0]]))
        assert np.allclose(rgb[0], XYZ_TO_REC709 @ xyz, rtol=1e-6)
        # Brighter towards the sun than away from it, at the same elevation.
        toward = preetham_radiance(Preetham.make(turbidity, sun), sun,
                                   np.array([[math.cos(0.3), 0.0, math.sin(0.3)],
                                             [-math.cos(0.3), 0.0, math.sin(0.3)]]))
        assert toward[0].sum() > toward[1].sum()


def test_sh_irradiance_of_a_uniform_sphere_is_pi_times_its_radiance():
    """Sky and ground of the same radiance: the order-2 SH irradiance is exact (pi L)."""
    sky, sun, el = 0.2, 1.5, 40.0
    albedo = math.pi * sky / (math.pi * sky + sun * math.sin(math.radians(el)))
    lighting = dataclasses.replace(LIGHT, sky="uniform", sky_rgb=(1.0, 1.0, 1.0),
                                   sky_strength=sky, sun_elevation_deg=el, sun_irradiance=sun,
                                   ground_albedo=(albedo,) * 3)
    sky_sh, ground_sh = lighting.irradiance_sh(rows=128)
    normals = np.concatenate([sky_directions(16), -sky_directions(16)])
    irradiance = sh_basis(normals) @ (sky_sh + ground_sh)
    assert np.allclose(irradiance, math.pi * sky, rtol=2e-3)


def test_ambient_occlusion_is_one_on_an_open_plane_and_below_one_in_an_inside_corner():
    matte = Material(base_color=(0.5, 0.5, 0.5, 1.0), roughness=1.0)
    open_out, open_ao = _render(_floor(matte), LIGHT, ao="ssao", sky_visibility_maps=0)
    hit = open_out.depth < 2000
    assert hit.all() and open_ao[hit].min() > 0.999
    # A wall standing on the floor along x = 0: the corner line runs down the image centre.
    wall = quad([[0, -50, -10], [0, 50, -10], [0, 50, -5], [0, -50, -5]])
    scene = scene_of(("ground_plane", Component.NONBRIDGE,
                      quad([[-50, -50, -10], [50, -50, -10], [50, 50, -10], [-50, 50, -10]]),
                      matte), ("column_wall", Component.COLUMN, wall, matte))
    cam_pose = np.eye(4)
    cam_pose[:3, 3] = [-3.0, 0.0, 0.0]  # 3 m to the floor side of the wall, looking down
    _, ao = _render(scene, LIGHT, cam=camera(64, 48, 20.0, pose=cam_pose), ao="ssao",
                    ao_radius_m=2.0, sky_visibility_maps=0)
    # The wall's foot (x = 0, 10 m down) is image column 42; a column is 0.28 m of floor.
    floor_near_corner = ao[20:28, 39:42]  # floor 0.1-0.9 m from the wall
    floor_far = ao[20:28, 2:8]            # floor 8 m and more away: open
    assert floor_near_corner.mean() < 0.93 and floor_far.min() > 0.999


def test_a_roof_hides_the_sky_from_the_floor_under_it():
    """The sky-visibility maps: with no sun, floor under a roof is darker than open floor."""
    matte = Material(base_color=(0.5, 0.5, 0.5, 1.0), roughness=1.0)
    floor = quad([[-60, -60, -10], [60, -60, -10], [60, 60, -10], [-60, 60, -10]])
    roof = quad([[0, -60, -4], [60, -60, -4], [60, 60, -4], [0, 60, -4]])
    scene = scene_of(("ground_plane", Component.NONBRIDGE, floor, matte),
                     ("slab_roof", Component.SLAB, roof, matte))
    dark = dataclasses.replace(LIGHT, sun_irradiance=0.0, ground_albedo=(0.0,) * 3)

    def floor_at(x: float, **render) -> np.ndarray:
        pose = np.eye(4)
        pose[:3, 3] = [x, 0.0, -6.0]  # 4 m above the floor, looking down, under the roof
        out, _ = _render(scene, dark, cam=camera(64, 48, 60.0, pose=pose), ao="off", **render)
        return out.color.astype(float)

    open_floor, covered = floor_at(-25.0), floor_at(25.0)  # 25 m outside | 25 m inside
    # Deep under a roof 6 m up, only the sky below about 14 deg is seen.
    assert covered.mean() < 0.5 * open_floor.mean()
    # Without the maps the roof hides nothing; in the open the maps change nearly nothing.
    assert np.abs(floor_at(25.0, sky_visibility_maps=0)
                  - floor_at(-25.0, sky_visibility_maps=0)).max() <= 1
    assert np.abs(floor_at(-25.0, sky_visibility_maps=0) - open_floor).mean() < 4


def test_sky_visibility_is_upsampled_within_each_surface():
    """The sky visibility is evaluated at every second pixel and upsampled by surface: a plate
    0.3 m above a floor shows, at every pixel, the colour it has with no floor under it,
    although the floor along its edges, half hidden from the sky by it, is far darker."""
    matte = Material(base_color=(0.5, 0.5, 0.5, 1.0), roughness=1.0)
    floor = quad([[-30, -30, -10], [30, -30, -10], [30, 30, -10], [-30, 30, -10]])
    plate = quad([[-0.6, -0.5, -9.7], [0.7, -0.5, -9.7], [0.7, 0.6, -9.7], [-0.6, 0.6, -9.7]])
    dark = dataclasses.replace(LIGHT, sun_irradiance=0.0, ground_albedo=(0.0,) * 3)
    pose = np.eye(4)
    pose[:3, 3] = [0.0, 0.0, -6.0]  # looking straight down at the plate
    cam = camera(64, 48, 60.0, pose=pose)
    extent = np.array([[-30.0, -30.0, -10.0], [30.0, 30.0, -9.7]])  # the same sky maps
    outs = []
    for parts in ((("ground_plane", Component.NONBRIDGE, floor, matte),
                   ("slab_plate", Component.SLAB, plate, matte)),
                  (("slab_plate", Component.SLAB, plate, matte),)):
        with Renderer(render_config(64, 48)) as r:
            r.load(scene_of(*parts), dark, extent)
            outs.append(r.render(cam))
            assert r.ctx.error == "GL_NO_ERROR"
    with_floor, alone = outs
    on_plate = with_floor.component == Component.SLAB
    assert np.array_equal(on_plate, alone.component == Component.SLAB) and on_plate.sum() > 500
    assert np.array_equal(with_floor.color[on_plate], alone.color[on_plate])
    ring = np.zeros_like(on_plate)  # floor pixels next to the plate
    for axis in (0, 1):
        for shift in (1, -1):
            ring |= np.roll(on_plate, shift, axis)
    ring &= ~on_plate
    grey = with_floor.color[..., 0].astype(float)
    assert grey[ring].mean() < grey[on_plate].mean() - 10


def test_an_emitting_roof_lights_the_floor_with_its_radiance():
    """Where a part hides the sky, its emitted radiance comes instead (scene panels): under an
    emitting roof that hides every sky direction, a matte floor of albedo a reflects
    a * L * (1 - sin^2 8 deg), the projected solid angle of the sampled sky above 8 deg over pi
    (exact for the 16 equal-solid-angle directions, uniform in z)."""
    from glsynth.world.lighting import SKY_MIN_ELEVATION_DEG

    albedo, radiance = 0.5, 0.8
    matte = Material(base_color=(albedo, albedo, albedo, 1.0), roughness=1.0)
    glowing = Material(base_color=(0.0, 0.0, 0.0, 1.0), emissive=(radiance,) * 3)
    floor = quad([[-60, -60, -10], [60, -60, -10], [60, 60, -10], [-60, 60, -10]])
    roof = quad([[-60, -60, -4], [60, -60, -4], [60, 60, -4], [-60, 60, -4]])
    dark = dataclasses.replace(LIGHT, sun_irradiance=0.0, ground_albedo=(0.0,) * 3)
    pose = np.eye(4)
    pose[:3, 3] = [0.0, 0.0, -6.0]  # 4 m above the floor, looking down
    cam = camera(64, 48, 60.0, pose=pose)
    z0 = math.sin(math.radians(SKY_MIN_ELEVATION_DEG))
    want = tone_map(np.full(3, albedo * radiance * (1 - z0 * z0)), 1.0)
    lit, _ = _render(scene_of(("ground_plane", Component.NONBRIDGE, floor, matte),
                              ("slab_roof", Component.SLAB, roof, glowing)), dark, cam=cam)
    assert np.abs(lit.color.astype(int) - want.astype(int)).max() <= 1
    unlit, _ = _render(scene_of(("ground_plane", Component.NONBRIDGE, floor, matte),
                                ("slab_roof", Component.SLAB, roof, matte)), dark, cam=cam)
    assert unlit.color.max() <= 2


def test_surface_albedo_is_the_mean_texel_colour_under_the_uvs():
    from glsynth.appearance.materials import srgb_decode, surface_albedo

    texture = np.zeros((4, 4, 3), np.uint8)
    texture[:, :2] = (200, 40, 40)   # left half (u < 0.5)
    texture[:, 2:] = (40, 200, 40)
    plane = quad([[0, 0, 0], [10, 0, 0], [10, 10, 0], [0, 10, 0]])
    whole = Material(base_color=(0.5, 1.0, 1.0, 1.0), base_color_map=texture)
    left = Material(base_color=(1.0, 1.0, 1.0, 1.0), base_color_map=texture,
                    uv_scale=0.4)  # u in [0, 0.4]: the red half
    part = Part("ground_x", PartKind.GROUND, None, plane, np.eye(4))
    red, green = srgb_decode(np.array([200, 40, 40])), srgb_decode(np.array([40, 200, 40]))
    assert np.allclose(surface_albedo([part], {"ground_x": whole}),
                       (red + green) / 2 * [0.5, 1.0, 1.0], atol=5e-3)
    assert np.allclose(surface_albedo([part], {"ground_x": left}), red)


def test_no_lighting_knob_changes_labels_or_depth():
    from glsynth.core.config import config_from_dict, load_config
    from glsynth.render.view import EnvironmentView, preview_config

    # Two viaducts: each variant opens the environment anew (ten took 6 s an opening). Knobs
    # that do not exclude each other share a variant: a change in labels shows in any mix.
    base = config_from_dict({"environment": {"n_viaducts": 2, "cutoff_factor": 1.0}},
                            preview_config(load_config("demo"), 96))
    variants = [{}, {"render": {"ao": "off", "sky_visibility_maps": 0},
                     "lighting": {"sky": "uniform", "sun_elevation_deg": [-20.0, -20.0]}},
                {"lighting": {"sun_elevation_deg": [1.0, 1.0], "exposure": 4.0,
                              "turbidity": [9.0, 10.0]}}]
    reference = None
    for change in variants:
        config = config_from_dict(change, base)
        with Renderer(config.render) as renderer:
            # Culled for the three cameras rendered (the same bytes: test_render_viaduct).
            view = EnvironmentView.open(config, 0, 0, renderer, rendering=(0, 5, 11))
            outs = [view.render(i)[1] for i in (0, 5, 11)]
        if reference is None:
            reference = outs
            continue
        for a, b in zip(reference, outs):
            for name in ("component", "damage", "depth"):
                assert np.array_equal(getattr(a, name), getattr(b, name)), (change, name)


@pytest.mark.parametrize("elevation", [0.5, 0.0, -10.0, -90.0])
def test_grazing_and_below_horizon_suns_stay_finite(elevation):
    lighting = environment_lighting(LightingConfig(sun_elevation_deg=(elevation, elevation)),
                                    0, 0)
    assert (lighting.sun_irradiance > 0) == (elevation > 0)
    for part in lighting.irradiance_sh():
        assert np.isfinite(part).all()
    assert np.isfinite(lighting.sky_radiance(sky_directions(16))).all()
    assert lighting.sky_sun_direction[2] >= 0
    matte = Material(base_color=(0.5, 0.5, 0.5, 1.0), roughness=1.0)
    out, ao = _render(_floor(matte), lighting)
    assert np.isfinite(ao).all()
    if elevation <= 0:  # the sun lights nothing: as with a zero sun
        unlit, _ = _render(_floor(matte), dataclasses.replace(lighting, sun_irradiance=0.0))
        assert np.array_equal(out.color, unlit.color)


def test_the_sun_and_sky_are_drawn_per_environment_from_their_ranges():
    config = LightingConfig()
    a, b = environment_lighting(config, 0, 0), environment_lighting(config, 0, 1)
    assert a == environment_lighting(config, 0, 0) and a != b
    for light in (a, b):
        assert config.sun_elevation_deg[0] <= light.sun_elevation_deg <= \
            config.sun_elevation_deg[1]
        assert config.turbidity[0] <= light.turbidity <= config.turbidity[1]
        assert config.sun_irradiance[0] <= light.sun_irradiance <= config.sun_irradiance[1]


@pytest.mark.parametrize("cls,field,value", [
    (LightingConfig, "sky", "hosek"), (RenderConfig, "ao", "hbao"),
    (LightingConfig, "turbidity", (1.0, 3.0)), (LightingConfig, "sun_elevation_deg", 50.0),
    (RenderConfig, "sky_visibility_maps", 5)])
def test_lighting_settings_are_checked(cls, field, value):
    section = "lighting" if cls is LightingConfig else "render"
    with pytest.raises(ValueError, match=rf"{section}\.{field}"):
        cls(**{field: value})


BLENDER = shutil.which("blender")
needs_blender = pytest.mark.skipif(BLENDER is None, reason="Blender is not installed (Debian "
                                   "package blender; scripts/install.sh installs it): the "
                                   "Cycles comparisons are skipped")


@pytest.mark.slow
@needs_blender
def test_cycles_sky_is_glsynths_sky(tmp_path):
    """Blender's own Preetham sky texture against glsynth's, pixel by pixel (no geometry in
    view: a tiny plane far behind the camera)."""
    from glsynth.render.cycles import display, render_linear

    pose = np.eye(4)
    pose[:3, :3] = [[0, 0, 1], [1, 0, 0], [0, 1, 0]]
    cam = camera(48, 32, 14.0, pose=pose)
    lighting = dataclasses.replace(LIGHT, sun_elevation_deg=25.0, sun_azimuth_deg=80.0,
                                   exposure=2.0)
    speck = quad([[-0.1, 5, -0.1], [0.1, 5, -0.1], [0.1, 5, 0.1], [-0.1, 5, 0.1]])
    parts = [Part("speck_plane", PartKind.SCENE, None, speck, np.eye(4))]
    result = render_linear(parts, {"speck_plane": Material()}, lighting, [cam], [1],
                           16, tmp_path / "work", BLENDER)
    cycles = display(result.linear[0], lighting).astype(int)
    out, _ = _render(scene_of(), lighting, {"color"}, cam=cam, width=48, height=32)
    # Blender's XYZ-to-RGB matrix and float maths differ in the last digits: within 2 steps.
    assert np.abs(cycles - out.color).max() <= 2, np.abs(cycles - out.color).max()
