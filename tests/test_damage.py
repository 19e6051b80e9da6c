import dataclasses

import numpy as np
import pytest

from glsynth.appearance.damage import (
    SEVERITIES,
    DamageParams,
    compose_rgb,
    concrete_profile,
    damage_maps,
    encode_normals,
    metallic_map,
    normal_components,
    normal_map,
    rebar_depth,
    sample_params,
    threshold_for_area,
)
from glsynth.appearance.noise import perlin
from glsynth.core.config import DamageConfig
from glsynth.core.labels import Damage
from glsynth.core.seeding import Stream, make_rng

SIZE = 128
CFG = DamageConfig(resolution=SIZE)


def rng(item: int = 0):
    return make_rng(0, 0, Stream.DAMAGE, item)


def params(**changes) -> DamageParams:
    base = sample_params(CFG, "severe", rng(99))
    return dataclasses.replace(base, **changes)


@pytest.mark.parametrize("severity", SEVERITIES)
def test_achieved_area_matches_the_target_over_many_seeds(severity):
    for item in range(25):
        r = rng(item)
        p = sample_params(CFG, severity, r)
        lo, hi = CFG.area_range(severity)
        assert lo <= p.area <= hi
        maps = damage_maps(p, CFG, r)
        achieved = float((maps.mask != Damage.NO_DAMAGE).mean())
        assert abs(achieved - p.area) <= 0.005


@pytest.mark.parametrize("area", [0.0, 1e-5, 0.5, 0.999, 1.0])
def test_area_extremes(area):
    maps = damage_maps(params(area=area), CFG, rng(1))
    achieved = float((maps.mask != Damage.NO_DAMAGE).mean())
    assert abs(achieved - area) <= 0.005
    assert np.all(np.isfinite(maps.displacement_m)) and maps.displacement_m.min() >= 0
    if area == 1.0:
        assert np.all(maps.mask != Damage.NO_DAMAGE)


@pytest.mark.parametrize("area, depth", [(0.0, 0.05), (0.3, 0.0), (0.0, 0.0)])
def test_zero_depth_or_zero_area_is_finite_and_undamaged(area, depth):
    maps = damage_maps(params(area=area, depth_m=depth), CFG, rng(2))
    assert np.all(maps.mask == Damage.NO_DAMAGE)
    assert np.all(maps.displacement_m == 0.0)
    nx, ny, nz = normal_components(maps.displacement_m, CFG.tile_m / SIZE)
    assert np.all(nx == 0) and np.all(ny == 0) and np.all(nz == 1)


def test_profile_follows_equations_1_and_2():
    noise = perlin(SIZE, 40, 60, 8, rng(3))
    profile, t = concrete_profile(noise, 0.2, 0.07)
    gap = t - np.minimum(t, np.abs(noise))  # t - P-
    assert np.allclose(profile, 0.07 * gap / gap.max(), atol=1e-7)
    assert profile.max() == pytest.approx(0.07)
    assert np.array_equal(profile > 0, np.abs(noise) < t)


def test_threshold_counts_exactly():
    values = np.abs(perlin(64, 20, 20, 4, rng(4)))
    for area in (0.0, 0.01, 0.37, 1.0):
        t = threshold_for_area(values, area)
        assert int((values < t).sum()) == round(area * values.size)
    with pytest.raises(ValueError, match="area"):
        threshold_for_area(values, 1.5)


def test_damage_maps_keep_the_papers_rules():
    """Section 3.3 as stated, not as composed: the damaged share is the sampled area exactly,
    intact concrete is not displaced, nothing is deeper than d, and rebar shows only below
    its cover and inside damage deeper than that cover."""
    exposed_somewhere = 0
    for item in range(10):
        r = rng(100 + item)
        p = sample_params(CFG, "severe", r)
        maps = damage_maps(p, CFG, r)
        intact = maps.mask == Damage.NO_DAMAGE
        exposed = maps.mask == Damage.REBAR
        assert set(np.unique(maps.mask)) <= {1, 2, 3}
        assert int((~intact).sum()) == round(p.area * SIZE * SIZE)
        assert np.all(maps.displacement_m[intact] == 0)
        assert np.all(maps.displacement_m[~intact] > 0)
        assert maps.displacement_m.max() <= p.depth_m * (1 + 1e-6)
        bar = maps.displacement_m[exposed]
        assert np.all(bar >= p.stirrup_cover_m) and np.all(bar < p.depth_m)
        exposed_somewhere += int(exposed.any())
    assert exposed_somewhere >= 5  # severe damage (2-10 cm deep) usually reaches the bars


def test_rebar_geometry_cover_radius_and_ripple():
    p = params(axial_cover_m=0.05, stirrup_cover_m=0.03)
    depth = rebar_depth(SIZE * 4, p, CFG, rng(5))
    assert depth[np.isfinite(depth)].min() == pytest.approx(0.03, abs=1e-3)
    # An axial bar: a vertical band about 2 x size/200 pixels wide, rippled by 10 %.
    size = SIZE * 4
    axial_only = dataclasses.replace(p, stirrup_spacing_px=1e9)
    cfg = dataclasses.replace(CFG, stirrup_radius=1e-6)
    bars = np.isfinite(rebar_depth(size, axial_only, cfg, rng(6)))
    widths = bars.sum(axis=1) / max(1, round(size / axial_only.axial_spacing_px))
    radius = size * CFG.axial_radius
    assert widths.min() == pytest.approx(2 * radius * 0.9, abs=2)
    assert widths.max() == pytest.approx(2 * radius * 1.1, abs=2)
    assert np.min(depth[np.isfinite(depth)]) >= 0.03 - 1e-6


def test_masks_partition_and_maps_are_consistent():
    r = rng(7)
    p = sample_params(CFG, "medium", r)
    maps = damage_maps(p, CFG, r)
    assert maps.mask.dtype == np.uint8
    assert set(np.unique(maps.mask)) <= {1, 2, 3}
    assert sum(int((maps.mask == i).sum()) for i in (1, 2, 3)) == maps.mask.size
    metal = metallic_map(maps.mask)
    assert metal.dtype == np.uint8 and metal.shape == maps.mask.shape
    assert np.array_equal(metal == 255, maps.mask == Damage.REBAR)
    assert np.all(metal[maps.mask != Damage.REBAR] == 0)


def test_normals_are_unit_length_and_tilt_with_the_slope():
    r = rng(8)
    maps = damage_maps(sample_params(CFG, "severe", r), CFG, r)
    nx, ny, nz = normal_components(maps.displacement_m, CFG.tile_m / SIZE)
    assert np.allclose(nx ** 2 + ny ** 2 + nz ** 2, 1.0, atol=1e-5)
    assert nz.min() > 0
    encoded = encode_normals(nx, ny, nz).astype(np.float64) / 127.5 - 1.0
    assert np.allclose(np.linalg.norm(encoded, axis=2), 1.0, atol=0.02)
    # A ramp deepening towards +u: the surface falls to the right, its normal leans to +u.
    ramp = np.tile(np.linspace(0.0, 0.01, 64, dtype=np.float32), (64, 1))
    x, _, _ = normal_components(ramp, 0.01)
    assert np.all(x[:, 1:-1] > 0)


@pytest.mark.parametrize("severity, area", [("slight", None), ("medium", None),
                                            ("severe", None), ("severe", 0.0), ("severe", 1.0)])
def test_sparse_normal_map_equals_the_dense_path_byte_for_byte(severity, area):
    """normal_map computes only the pixels that are not flat; the bytes must be those of
    encode_normals(normal_components(...)) for every severity and at zero and full area."""
    r = rng(12)
    p = sample_params(CFG, severity, r)
    if area is not None:
        p = dataclasses.replace(p, area=area)
    maps = damage_maps(p, CFG, r, size=512)
    pixel_m = CFG.tile_m / 512
    dense = encode_normals(*normal_components(maps.displacement_m, pixel_m))
    sparse = normal_map(maps.displacement_m, pixel_m)
    assert sparse.dtype == np.uint8 and sparse.shape == (512, 512, 3)
    assert sparse.tobytes() == dense.tobytes()
    flat = np.all(sparse == (128, 128, 255), axis=2)
    assert flat.all() if area == 0.0 else 0 < flat.sum() < flat.size


def test_same_seed_identical_bytes_and_workers_do_not_matter():
    a = damage_maps(sample_params(CFG, "severe", rng(9)), CFG, _reseeded(9))
    b = damage_maps(sample_params(CFG, "severe", rng(9)), CFG, _reseeded(9))
    assert a.mask.tobytes() == b.mask.tobytes()
    assert a.displacement_m.tobytes() == b.displacement_m.tobytes()
    one = perlin(512, 100, 300, 8, rng(10), workers=1)
    two = perlin(512, 100, 300, 8, rng(10), workers=2)
    assert one.tobytes() == two.tobytes()


def _reseeded(item):
    r = rng(item)
    sample_params(CFG, "severe", r)
    return r


def test_noise_tiles_seamlessly():
    n = perlin(256, 60, 90, 8, rng(11))
    seam = np.abs(n[:, 0] - n[:, -1]).mean()
    inside = np.abs(np.diff(n, axis=1)).mean()
    assert seam < 2 * inside


def test_severity_reading_keeps_the_paper_numbers():
    cfg = DamageConfig()
    assert cfg.medium_intact == (0.90, 0.99) and cfg.severe_intact == (0.70, 0.90)
    assert cfg.area_range("slight") == (0.0, 0.01)
    assert cfg.area_range("medium") == pytest.approx((0.01, 0.10))
    assert cfg.area_range("severe") == pytest.approx((0.10, 0.30))
    assert cfg.depth_range_m("severe") == pytest.approx((0.02, 0.10))
    with pytest.raises(ValueError, match="severity = 'extreme'"):
        cfg.area_range("extreme")
    with pytest.raises(ValueError, match="damage.stirrup_cover_offset_cm"):
        DamageConfig(axial_cover_cm=(1.0, 2.0))


@pytest.mark.parametrize("fractions", [(1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0),
                                       (0.5, 0.3, 0.2)])
def test_rgb_takes_each_pixel_from_the_image_of_its_damage_class(fractions):
    """No damage, all concrete damage, all rebar, and a mix: every pixel comes from its
    class's image, the inputs are untouched (a tiled view of an image may be passed)."""
    r = rng(9)
    mask = r.choice(np.array([1, 2, 3], np.uint8), size=(64, 64), p=fractions)
    images = [r.integers(0, 256, (64, 64, 3), dtype=np.uint8) for _ in range(3)]
    before = [i.copy() for i in images]
    out = compose_rgb(mask, np.tile(images[0][:32, :32], (2, 2, 1)), images[1], images[2])
    reference = np.where((mask == 1)[..., None], np.tile(images[0][:32, :32], (2, 2, 1)),
                         np.where((mask == 2)[..., None], images[1], images[2]))
    assert np.array_equal(out, reference)
    assert all(np.array_equal(a, b) for a, b in zip(images, before))
