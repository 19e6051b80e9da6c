"""Numerical stability at the extremes, end to end: each case renders or computes through the
real pipeline and checks there is no NaN or inf, no invalid id, and the documented behaviour.

| case | documented behaviour |
|---|---|
| depth at the near plane .. 1000 m | linear depth exact to float32 ulps; no-hit = zfar |
| focal 15 / 55 mm | views finite, ids valid, RRDR px/cm finite |
| heights 5.0 / 14.0 m x straight / tightest curve | rendered views finite and valid |
| damaged area 0 % / 100 % | rendered damage ids all 1 / all 2-3 |
| cover equal to the damage depth | no rebar exposed (exposure needs concrete deeper than bar) |
| camera inside a closed mesh | no face culling: it sees the inner faces, at their depth |
| camera seeing only sky | component 1, damage 1, depth zfar; filtered as single_component |
| px/cm at zero or huge depth | 0 (unreliable) at depth <= 0, finite large values near 0 |
| losses at zero error / absent classes | 0 with finite gradients; absent classes weight 0 |
| bf16 against fp32 network outputs | finite, within 5 % of the fp32 output's spread |
| sun at the zenith, grazing, below the horizon | shadows only darken; labels, depth unchanged |
"""

import dataclasses
import math

import numpy as np
import pytest
from glhelpers import LIGHT, camera, quad, render_config, scene_of

from glsynth.appearance.damage import damage_maps, sample_params
from glsynth.appearance.materials import Material
from glsynth.core.config import Config, DamageConfig, EnvironmentConfig
from glsynth.core.filters import pixels_per_cm, removal_reason, rrdr
from glsynth.core.labels import COMPONENT_IDS, DAMAGE_IDS, Component
from glsynth.core.seeding import Stream, make_rng
from glsynth.render.gl.renderer import Renderer
from glsynth.render.view import EnvironmentView, preview_config
from glsynth.world.lighting import environment_lighting
from glsynth.world.visibility import occlusion_extent

PLAIN = Material(base_color=(0.6, 0.6, 0.6, 1.0))


def assert_sane(output, zfar: float = 2000.0) -> None:
    assert np.isfinite(output.depth).all() and (output.depth > 0).all()
    assert (output.depth <= zfar).all()
    assert set(np.unique(output.component)) <= COMPONENT_IDS
    assert set(np.unique(output.damage)) <= DAMAGE_IDS
    if output.color is not None:
        assert output.color.dtype == np.uint8


@pytest.fixture(scope="module")
def small():
    with Renderer(render_config(64, 48)) as r:
        yield r


@pytest.mark.parametrize("distance", [0.05 * 1.001, 0.5, 30.0, 1000.0])
def test_depth_from_the_near_plane_to_1000_m(small, distance):
    plate = quad([[-1e4, -1e4, -distance], [1e4, -1e4, -distance], [1e4, 1e4, -distance],
                  [-1e4, 1e4, -distance]])
    small.load(scene_of(("column", Component.COLUMN, plate, PLAIN)), LIGHT)
    out = small.render(camera())
    assert_sane(out)
    assert np.allclose(out.depth, distance, rtol=4 * np.finfo(np.float32).eps)


@pytest.mark.parametrize("focal", [15.0, 55.0])
@pytest.mark.parametrize("height, radius", [(5.0, math.inf), (14.0, 500.0)])
def test_viaduct_views_at_the_extremes(focal, height, radius):
    # Two viaducts: the heights, curves and lenses at their extremes are the subject, not the
    # number of viaducts (each of the four openings dressed ten).
    environment = EnvironmentConfig(initial_height_m=(height, height), ground_amplitude_m=0.0,
                                    height_amplitude_m=0.0, min_radius_m=(radius, radius),
                                    n_viaducts=2, cutoff_factor=1.0)
    config = preview_config(Config(), 160)
    config = dataclasses.replace(
        config, environment=environment,
        cameras=dataclasses.replace(config.cameras, n_regular=3, n_closeup=3,
                                    focal_mm=(focal, focal)))
    with Renderer(config.render) as renderer:
        view = EnvironmentView.open(config, 0, 0, renderer)
        assert all(v.height_m == height for v in view.environment.viaducts)
        for index in range(6):
            placement, out = view.render(index)
            assert placement.camera.focal_mm == focal
            assert_sane(out)
            fx = placement.camera.fx
            assert np.isfinite(pixels_per_cm(out.depth, fx)).all()
            # 1.5 px/cm = f_px / (100 depth) <=> depth <= f_px / 150 (float32 rounding aside).
            near = out.depth.astype(np.float64) <= fx / 150
            edge = np.isclose(out.depth, fx / 150, rtol=1e-6)
            assert np.array_equal(rrdr(out.depth, fx)[~edge], near[~edge])


@pytest.mark.parametrize("area", [0.0, 1.0])
def test_zero_and_full_damaged_area_render_as_such(small, area):
    import tempfile

    from glsynth.appearance.damage_bank import BankEntry, damage_material
    from glsynth.appearance.repository import TextureRepository, generate_repository

    cfg = DamageConfig(resolution=64)
    rng = make_rng(0, 0, Stream.DAMAGE, 0)
    params = dataclasses.replace(sample_params(cfg, "severe", rng), area=area)
    maps = damage_maps(params, cfg, rng)
    assert np.isfinite(maps.displacement_m).all()
    with tempfile.TemporaryDirectory() as tmp:
        repo = TextureRepository(generate_repository(tmp, 0, 1, 16), 16)
        material = damage_material(BankEntry("severe", 0, params, maps, (0, 0, 0)), repo, cfg,
                                   scale=1.0)
    plate = quad([[-50, -50, -3], [50, -50, -3], [50, 50, -3], [-50, 50, -3]],
                 uv=np.array([[0, 0], [40, 0], [40, 40], [0, 40]], float))
    small.load(scene_of(("column", Component.COLUMN, plate, material)), LIGHT)
    out = small.render(camera())
    assert_sane(out)
    if area == 0.0:
        assert (out.damage == 1).all()
    else:
        assert (out.damage >= 2).all()


def test_cover_equal_to_the_damage_depth_exposes_no_rebar():
    cfg = DamageConfig(resolution=128)
    rng = make_rng(0, 0, Stream.DAMAGE, 1)
    params = sample_params(cfg, "severe", rng)
    params = dataclasses.replace(params, area=0.3, axial_cover_m=params.depth_m,
                                 stirrup_cover_m=params.depth_m)
    maps = damage_maps(params, cfg, rng)
    assert (maps.mask == 2).any() and not (maps.mask == 3).any()
    assert np.isfinite(maps.displacement_m).all()
    # Stored as float32: at most one ulp above d.
    assert maps.displacement_m.max() <= np.nextafter(np.float32(params.depth_m), np.float32(1))


def test_camera_inside_a_closed_mesh_sees_its_inner_faces(small):
    import trimesh

    box = trimesh.creation.box((2.0, 2.0, 2.0))
    box.visual = trimesh.visual.TextureVisuals(uv=np.zeros((len(box.vertices), 2)))
    wall = quad([[-1e3, -1e3, -50], [1e3, -1e3, -50], [1e3, 1e3, -50], [-1e3, 1e3, -50]])
    small.load(scene_of(("column", Component.COLUMN, box, PLAIN),
                        ("slab", Component.SLAB, wall, PLAIN)), LIGHT)
    out = small.render(camera())
    assert_sane(out)
    # No face culling: the inner faces of the box, 1 m away along the axis, hide the wall.
    assert (out.component == Component.COLUMN).all() and np.allclose(out.depth, 1.0, rtol=1e-6)


def test_camera_seeing_only_sky(small):
    floor = quad([[-1e3, -1e3, 0], [1e3, -1e3, 0], [1e3, 1e3, 0], [-1e3, 1e3, 0]])
    pose = np.eye(4)
    pose[:3, 3] = (0.0, 0.0, 5.0)  # above the floor, looking up (+z) at the sky
    pose[:3, :3] = np.diag([1.0, -1.0, -1.0])
    small.load(scene_of(("ground", Component.NONBRIDGE, floor, PLAIN)), LIGHT)
    out = small.render(camera(pose=pose))
    assert_sane(out)
    assert (out.component == 1).all() and (out.damage == 1).all() and (out.depth == 2000).all()
    assert removal_reason(out.color, out.component, out.depth) == "single_component"


def test_pixels_per_cm_at_zero_and_huge_depth():
    depth = np.array([0.0, -1.0, np.nan, np.inf, 1e-30, 1e-6, 1e6])
    ppcm = pixels_per_cm(depth, 1000.0)
    assert np.isfinite(ppcm).all()
    assert ppcm[:4].tolist() == [0, 0, 0, 0] and ppcm[4] > 1e20 and ppcm[6] == 1e-5
    assert rrdr(depth, 1000.0).tolist() == [False] * 4 + [True, True, False]
    assert rrdr(depth, None).tolist() == [False] * 7
    with pytest.raises(ValueError, match="focal_px"):
        rrdr(depth, 0.0)


def test_losses_with_zero_error_and_absent_classes():
    torch = pytest.importorskip("torch", reason="needs the [model] extra")
    from glsynth.model.losses import berhu, class_frequencies, mfb_weights, weighted_cross_entropy

    prediction = torch.zeros(1, 4, 4, requires_grad=True)
    loss = berhu(prediction, torch.zeros(1, 4, 4))
    loss.backward()
    assert loss.item() == 0 and torch.isfinite(prediction.grad).all()
    weights = torch.tensor(mfb_weights(class_frequencies([10, 0, 5], [100, 0, 100])),
                           dtype=torch.float32)
    assert weights.tolist() == [0.75, 0.0, 1.5]
    logits = torch.randn(1, 3, 4, 4, requires_grad=True)
    loss = weighted_cross_entropy(logits, torch.full((1, 4, 4), 2), weights)
    loss.backward()
    assert loss.item() == 0 and torch.isfinite(logits.grad).all()


def test_bf16_against_fp32_network_outputs():
    torch = pytest.importorskip("torch", reason="needs the [model] extra")
    from glsynth.model.fcn58 import FCN58
    from glsynth.model.train import seeded_torch

    with seeded_torch(0):
        model = FCN58(8).eval()
        images = torch.rand(2, 3, 108, 192)
    with torch.no_grad():
        reference = model(images)
        with torch.autocast("cpu", dtype=torch.bfloat16):
            half = model(images).float()
    assert torch.isfinite(half).all()
    # Measured: the largest difference is 3.0-3.2 % of the spread over three seeds.
    assert float((half - reference).abs().max()) < 0.05 * float(reference.std())


@pytest.fixture(scope="module")
def sunlit():
    """Environment 0 at preview size, opened once for every sun elevation and relit per test
    (Renderer.relight draws what opening under that light draws). cull=False uploads every
    part, so whatever a sun anywhere shadows with is there; beside it a renderer without
    shadow maps holding the same scene."""
    config = preview_config(Config(), 160)
    config = dataclasses.replace(
        config, cameras=dataclasses.replace(config.cameras, n_regular=2, n_closeup=2))
    with (Renderer(config.render) as renderer,
          Renderer(dataclasses.replace(config.render, shadow_map_px=0)) as unshadowed):
        view = EnvironmentView.open(config, 0, 0, renderer, cull=False)
        # The same sky-visibility maps as the view's (fitted to the whole environment).
        unshadowed.load(view.scene, view.lighting, occlusion_extent(view.environment.parts))
        yield view, unshadowed


@pytest.mark.parametrize("elevation", [90.0, 50.0, 1.0, -5.0])
def test_shadows_only_darken_with_the_sun_anywhere(sunlit, elevation):
    view, unshadowed = sunlit
    lighting = dataclasses.replace(view.config.lighting, sun_elevation_deg=(elevation, elevation))
    view.lighting = environment_lighting(lighting, 0, 0,
                                         ground_albedo=np.array(view.lighting.ground_albedo))
    assert view.lighting.sun_elevation_deg == elevation
    view.renderer.relight(view.lighting)
    unshadowed.relight(view.lighting)
    darker = 0
    for index in range(4):
        placement, out = view.render(index)
        lit = unshadowed.render(placement.camera)
        assert_sane(out)
        for name in ("component", "damage", "depth"):
            assert np.array_equal(getattr(out, name), getattr(lit, name))
        assert np.all(out.color.astype(int) <= lit.color.astype(int) + 1)
        darker += int((out.color.astype(int) < lit.color.astype(int) - 8).any(axis=2).sum())
    if elevation == 50.0:  # a mid-height sun: the deck's shadow is in these views
        assert darker > 0
