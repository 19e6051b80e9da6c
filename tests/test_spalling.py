"""Spalling and exposed bars placed by mechanics (docs/design.md, "Damage by mechanics"): the
Section 3.3 damage texture of a medium or severe column only in its plastic-hinge zones.

Rendered checks look at a column box side-on (camera on +x, image rows along the column's
axis) and map each pixel back to its mesh-frame height through the depth pass; the dressing
checks measure areas on the column's faces."""

import dataclasses
import json

import numpy as np
import pytest
from fixtures_cracks import SMALL
from glhelpers import LIGHT, camera, render_config, scene_of
from test_cracks import table3_column

from glsynth.appearance.cracks import (
    column_cracks,
    column_demand,
    crack_records,
    hinge_zones,
)
from glsynth.appearance.damage import (
    compose_rgb,
    damage_maps,
    metallic_map,
    normal_map,
    sample_params,
)
from glsynth.appearance.damage_bank import DamageBank
from glsynth.appearance.dressing import clear_spans, dress, open_repository
from glsynth.appearance.materials import DamageZones, Material
from glsynth.core.config import DamageConfig
from glsynth.core.fileio import jsonable
from glsynth.core.labels import Component, Damage
from glsynth.core.seeding import Stream, make_rng
from glsynth.render.gl.renderer import Renderer
from glsynth.render.raycast import ray_cast
from glsynth.world.environment import Part, PartKind, build_environment
from glsynth.world.meshes import box

W, H = 128, 256
SECTION, HEIGHT = (0.6, 0.6), 4.0
DISTANCE = 3.2
"""The camera's distance from the column's axis: 4 m of column fill about 220 of 256 rows."""
CFG = DamageConfig(model="mechanics", resolution=128)


def side_camera():
    """On +x, level with the column's centre, looking at it along -x, image up = +z."""
    pose = np.eye(4)
    pose[:3, :3] = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    pose[:3, 3] = (DISTANCE, 0.0, 0.0)
    return camera(W, H, focal_mm=36.0, pose=pose)


def heights(cam, depth: np.ndarray) -> np.ndarray:
    """(H, W) mesh-frame z of each pixel's surface (the part's pose is the identity)."""
    origin, dirs = cam.rays()
    return (origin + dirs * depth[..., None])[..., 2]


def texture(seed: int, severity: str, size: int = 128):
    """A seeded Section 3.3 texture (params, maps) of ``severity`` at ``size`` px."""
    rng = make_rng(seed, 0, Stream.DAMAGE_BANK)
    params = sample_params(CFG, severity, rng, size)
    return params, damage_maps(params, CFG, rng, size)


def images(seed: int, size: int = 128) -> tuple[np.ndarray, ...]:
    """Intact, damaged and steel images: flat mid-grey noise, darker, and light grey."""
    rng = make_rng(seed, 0, Stream.MATERIALS)
    grain = rng.integers(-12, 13, (size, size, 1))
    return tuple(np.clip(level + grain, 0, 255).astype(np.uint8).repeat(3, axis=2)
                 for level in (150, 90, 200))


def spalled(seed: int, severity: str, zones, cracks=None, scale: float = 0.8):
    """A zoned damage material as dressing builds one (spalled_material), and the intact
    concrete material it shows outside the zones."""
    _, maps = texture(seed, severity)
    intact, damaged, steel = images(seed)
    concrete = Material(base_color=(1.0, 1.0, 1.0, 1.0), uv_scale=0.7, base_color_map=intact)
    material = Material(base_color=(1.0, 1.0, 1.0, 1.0), metallic=1.0, uv_scale=scale,
                        base_color_map=compose_rgb(maps.mask, intact, damaged, steel),
                        metallic_map=metallic_map(maps.mask),
                        normal_map=normal_map(maps.displacement_m, 1.0 / 128),
                        damage_mask=maps.mask, cracks=cracks,
                        zones=DamageZones(tuple(zones), intact, 0.7))
    return material, concrete


@pytest.fixture(scope="module")
def renderer():
    with Renderer(render_config(W, H)) as r:
        yield r
        assert r.ctx.error == "GL_NO_ERROR"


def render(renderer, material, height: float = HEIGHT):
    renderer.load(scene_of(("column", Component.COLUMN, box((*SECTION, height)), material)),
                  LIGHT)
    return renderer.render(side_camera())


def margin_m() -> float:
    """Two pixels' height on the column's face: where float32 interpolation and the nearest
    texel may put a boundary pixel on either side."""
    return 2 * (DISTANCE - SECTION[0] / 2) / side_camera().K[0, 0]


@pytest.mark.parametrize("seed", range(6))
def test_rendered_spalling_and_rebar_only_in_the_zones_intact_concrete_outside(renderer, seed):
    severity = ("medium", "severe")[seed % 2]
    # Wider than a 4 m column's hinges (0.35 m), so that every seed's texture shows damage
    # in them; the zones of four spans, one of them touching the next.
    zones = ((-2.0, -1.4), (-1.4, -0.9), (0.3, 0.8), (1.2, 2.0))
    material, concrete = spalled(seed, severity, zones)
    out, base = render(renderer, material), render(renderer, concrete)
    z = heights(side_camera(), out.depth)
    hit = out.component == Component.COLUMN
    near = np.zeros_like(hit)
    inside = np.zeros_like(hit)
    for z0, z1 in zones:
        inside |= (z >= z0) & (z <= z1)
        near |= (np.abs(z - z0) < margin_m()) | (np.abs(z - z1) < margin_m())
    damaged = np.isin(out.damage, (Damage.CONCRETE, Damage.REBAR))
    assert damaged[hit & inside].sum() > 20  # the zones show damage
    assert not damaged[hit & ~inside & ~near].any()
    assert not base.damage[hit].any() or (base.damage[hit] == Damage.NO_DAMAGE).all()
    # Outside the zones the colour is the intact material's, within the pipeline's tolerance
    # (the intact map is looked up at the damage UVs times a ratio on the GPU).
    outside = hit & ~inside & ~near
    diff = np.abs(out.color.astype(int) - base.color.astype(int))[outside]
    assert outside.sum() > 1000 and diff.max() <= 2 and diff.mean() < 0.1
    # Inside, the spalled pixels show the damaged material (a darker concrete, a lighter
    # steel; filtered down to these pixels, so on average).
    change = np.abs(out.color.astype(int) - base.color.astype(int)).max(2)
    assert change[hit & inside & damaged].mean() > 5
    # The label pass agrees with ray casting, which applies the zones in numpy, as well as
    # on any textured part (a texel edge may fall either side of a pixel centre).
    part = Part("column", PartKind.COLUMN, None, box((*SECTION, HEIGHT)), np.eye(4))
    truth = ray_cast([part], {"column": material}, side_camera())
    assert (truth.damage == out.damage)[~near].mean() > 0.999


def test_cracks_still_label_outside_the_zones_rebar_stays_inside(renderer):
    rng = make_rng(3, 0, Stream.CRACKS)
    demand = column_demand(CFG, "severe", rng)
    spans = [(-HEIGHT / 2, HEIGHT / 2)]
    cracks = column_cracks(CFG, SECTION, spans, demand, rng)
    zones = hinge_zones(CFG, spans)
    material, _ = spalled(1, "severe", zones, cracks)
    out = render(renderer, material)
    bare = render(renderer, dataclasses.replace(material, cracks=None))
    crack = out.crack_width > 0
    assert crack.sum() > 50
    # A crack pixel is concrete damage unless the mask makes it rebar; elsewhere the labels
    # are the zoned texture's.
    assert np.all(out.damage[crack] >= Damage.CONCRETE)
    assert np.array_equal(out.damage[crack & (bare.damage == Damage.REBAR)], np.full(
        (crack & (bare.damage == Damage.REBAR)).sum(), Damage.REBAR))
    assert np.array_equal(out.damage[~crack], bare.damage[~crack])


def test_a_zone_covering_the_whole_column_and_no_damage(renderer):
    """A very short column: its hinge zones cover the whole span, so the texture shows all
    over it; a texture with no damage labels nothing."""
    height = 0.4  # Lp = 0.08 x 0.2 + 0.19 m exceeds the shear span, 0.2 m
    zones = hinge_zones(CFG, [(-height / 2, height / 2)])
    assert zones == ((-0.2, 0.0), (0.0, 0.2))
    material, _ = spalled(2, "severe", zones, scale=3.0)
    out = render(renderer, material, height)
    unzoned = render(renderer, dataclasses.replace(material, zones=None), height)
    assert np.array_equal(out.damage, unzoned.damage)
    assert (out.damage >= Damage.CONCRETE).sum() > 20
    flat = np.full((128, 128), Damage.NO_DAMAGE, np.uint8)
    intact = images(0)[0]
    clean = Material(base_color_map=intact, damage_mask=flat,
                     zones=DamageZones(zones, intact, 1.0))
    assert (render(renderer, clean).damage == Damage.NO_DAMAGE).all()


def test_zones_validation():
    intact = images(0, 8)[0]
    flat = np.ones((8, 8), np.uint8)
    for bad in ((), ((0.0, 0.0),), ((1.0, 0.0),), ((0.0, np.nan),), ((0.0, 1.0),) * 5):
        with pytest.raises(ValueError, match="intervals"):
            DamageZones(bad, intact, 1.0)
    with pytest.raises(ValueError, match="intact_uv_scale"):
        DamageZones(((0.0, 1.0),), intact, 0.0)
    with pytest.raises(ValueError, match="zones"):
        Material(zones=DamageZones(((0.0, 1.0),), intact, 1.0))
    assert Material(damage_mask=flat, zones=DamageZones(((0.0, 1.0),), intact, 1.0))
    zones = DamageZones(((0.0, 1.0), (2.0, 3.0)), intact, 1.0)
    assert zones.contains(np.array([0.0, 0.5, 1.0, 1.5, 3.0, 3.1])).tolist() == [
        True, True, True, False, True, False]


def test_dressing_spalls_medium_and_severe_seen_columns_in_their_hinge_zones(
        mechanics_dressing):
    mech, env, seen = mechanics_dressing.config, mechanics_dressing.env, mechanics_dressing.seen
    dressing = mechanics_dressing.dressing
    columns = [p for p in env.parts if p.kind is PartKind.COLUMN]
    counts = {"slight": 0, "spalled": 0}
    for part in columns:
        record, materials = dressing.assignments[part.name].damage, dressing.materials
        if not (record["damaged"] and part.name in seen) or record["severity"] == "slight":
            assert not materials.is_deferred(part.name) and "hinge_zones_m" not in record
            assert materials[part.name].damage_mask is None
            counts["slight"] += record.get("severity") == "slight" and part.name in seen
            continue
        counts["spalled"] += 1
        assert materials.is_deferred(part.name)
        built = materials[part.name]
        zones = hinge_zones(mech.damage, clear_spans(env, part))
        assert built.zones.intervals == zones
        assert record["hinge_zones_m"] == [[round(z, 4) for z in zone] for zone in zones]
        assert json.loads(json.dumps(jsonable(record)))["params"]["severity"] \
            == record["severity"]
        assert built.cracks is materials.factors(part.name).cracks
        assert [{"member": part.name, **r} for r in crack_records(built.cracks)] \
            == record["cracks"]
        assert built.damage_mask is not None and built.zones.intact_uv_scale > 0
        assert built.uv_scale == materials.factors(part.name).uv_scale
    assert counts["spalled"] > 3 and counts["slight"] > 0


@pytest.mark.parametrize("spalling", [("slight",), ()])
def test_spalling_severities_choose_which_columns_spall(tmp_path, spalling):
    """The inspection preset's early spalling: its slight columns, seen, get the bank's slight
    texture confined to their hinge zones; with no spalling severities, none spalls."""
    from glsynth.core.config import load_config
    assert load_config("inspection").damage.spalling_severities == ("slight",)
    assert DamageConfig().spalling_severities == ("medium", "severe")
    cfg = DamageConfig(resolution=64, model="mechanics", severities=("slight",),
                       spalling_severities=spalling, undamaged_probability=0.2)
    config = dataclasses.replace(SMALL, damage=cfg)
    env = build_environment(config, 4, 0)
    columns = [p for p in env.parts if p.kind is PartKind.COLUMN]
    seen = {p.name for p in columns[::2]}
    dressing = dress(env, config, open_repository(config),
                     DamageBank(cfg, 4, cache_dir=tmp_path), seen)
    spalled = 0
    for part in columns:
        record, materials = dressing.assignments[part.name].damage, dressing.materials
        expected = record["damaged"] and part.name in seen and bool(spalling)
        assert materials.is_deferred(part.name) == expected
        if not expected:
            assert materials[part.name].damage_mask is None
            continue
        spalled += 1
        built = materials[part.name]
        assert record["severity"] == "slight" and record["params"].severity == "slight"
        assert built.zones.intervals == hinge_zones(cfg, clear_spans(env, part))
        assert built.cracks is not None and built.damage_mask is not None
    assert spalled > 3 or not spalling


def spalled_area(mask: np.ndarray, section, zones, bottom: float, scale: float,
                 step: float = 0.01) -> float:
    """m^2 of a column's lateral faces, inside ``zones``, whose texel is spalled or rebar by
    the box's UVs (metres per face: u across it, v up it from ``bottom``) at ``scale``; the
    renderer shows none outside the zones (the rendered tests check it)."""
    size = mask.shape[0]
    area = 0.0
    for width in (*section, *section):
        u = np.arange(step / 2, width, step)
        for z0, z1 in zones:
            v = (np.arange(z0 + step / 2, z1, step) - bottom) * scale
            col = np.floor(u * scale * size).astype(int) % size
            row = size - 1 - np.floor(v * size).astype(int) % size
            area += (mask[row[:, None], col[None, :]] >= Damage.CONCRETE).sum() * step * step
    return area


def test_damaged_area_of_flexure_dominated_columns_lies_in_the_hinge_zones():
    """The issue's mechanics goal with spalling included: over 120 medium and severe columns
    of Table 3 sections (flexure-dominated: a / d >= 2.6), the share of the damaged area, crack
    area (length x mean width) plus spalled area, in the hinge zones is at least 70 % for each
    severity (docs/design.md gives the measured shares)."""
    totals = {"medium": np.zeros(3), "severe": np.zeros(3)}  # cracks in, cracks, spalled
    for seed in range(120):
        rng = make_rng(seed, 0, Stream.CRACKS)
        section, spans = table3_column(rng)
        severity = ("medium", "severe")[seed % 2]
        demand = column_demand(CFG, severity, rng)
        net = column_cracks(CFG, section, spans, demand, rng)
        zones = hinge_zones(CFG, spans)
        z = net.points[..., 2].mean(axis=1)
        hinge = DamageZones(zones, np.zeros((1, 1, 3), np.uint8), 1.0).contains(z)
        area = net.lengths_m * net.widths_m.mean(axis=1)
        _, maps = texture(seed, severity, 64)
        spall = spalled_area(maps.mask, section, zones, spans[0][0], rng.uniform(*CFG.scale))
        totals[severity] += [area[hinge].sum(), area.sum(), spall]
    for severity, (crack_in, crack_all, spall) in totals.items():
        share = (crack_in + spall) / (crack_all + spall)
        print(f"{severity}: cracks {crack_in / crack_all:.3f} in the zones, with spalling "
              f"{share:.4f}; spalled {spall:.2f} m2, crack area {crack_all:.3f} m2")
        assert share >= 0.70 and spall > 0
