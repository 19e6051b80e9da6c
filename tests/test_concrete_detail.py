"""Concrete detail (shaders/concrete_detail.glsl): deterministic, non-repeating, contrast at
the pixel scale that fades with distance; drawn in flights only by default, so the paper
preset's dressing is unchanged. A flight's metered exposure; and COLMAP finds more features
on a tiny flight with both."""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from glhelpers import camera, pixel_plate, render_config, render_once, scene_of
from PIL import Image
from shader_harness import WIDTH, GlslHarness

from glsynth.appearance.damage_bank import DamageBank
from glsynth.appearance.dressing import dress, open_repository
from glsynth.appearance.materials import Assignment, Material, srgb_decode
from glsynth.appearance.texgen import concrete
from glsynth.cli import main
from glsynth.core.config import Config, DamageConfig, MaterialsConfig, load_config
from glsynth.core.labels import Component
from glsynth.core.seeding import Stream, make_rng
from glsynth.data.flight import MID_GREY, flight_materials
from glsynth.world.environment import PartKind, build_environment
from glsynth.world.lighting import LUMINANCE


@pytest.fixture(scope="module")
def harness():
    with GlslHarness("concrete_detail.glsl") as h:
        yield h


def detail_field(harness: GlslHarness, origin: tuple[float, float], step_m: float,
                 seed: int = 7, rows: int = WIDTH) -> np.ndarray:
    """The detail factor on a face whose normal is +z, over a rows x WIDTH grid of points
    step_m apart from ``origin``: neighbouring pixels of the harness are neighbouring points,
    so the shader's footprint is step_m."""
    r, c = np.mgrid[0:rows, 0:WIDTH]
    pos = np.zeros((rows * WIDTH, 4), np.float32)
    pos[:, 0] = origin[0] + c.ravel() * step_m
    pos[:, 1] = origin[1] + r.ravel() * step_m
    out = harness.run(f"vec4(concrete_detail(in0.xyz, vec3(0.0, 0.0, 1.0), {seed}u))", pos)
    return out[:, 0].reshape(rows, WIDTH)


def correlation(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.corrcoef(a.ravel(), b.ravel())[0, 1])


def high_pass(field: np.ndarray) -> np.ndarray:
    """The field less its 3x3 mean: what SIFT's finest scales respond to."""
    pad = np.pad(field, 1, mode="edge")
    mean = sum(pad[1 + dy:pad.shape[0] - 1 + dy, 1 + dx:pad.shape[1] - 1 + dx]
               for dy in (-1, 0, 1) for dx in (-1, 0, 1)) / 9.0
    return field - mean


def test_detail_is_deterministic_and_follows_the_seed(harness):
    a = detail_field(harness, (0.3, 0.2), 0.0015)
    assert np.array_equal(a, detail_field(harness, (0.3, 0.2), 0.0015))
    assert abs(correlation(a, detail_field(harness, (0.3, 0.2), 0.0015, seed=8))) < 0.3


def test_detail_does_not_repeat_at_texture_tile_periods(harness):
    """A repository image repeats every 1 / uv_scale = 1 to 10 m (concrete_scale 0.1-1); the
    detail at those lags is unrelated to itself (formwork ties repeat every 0.6 m, as real
    formwork's do: lags here are no multiple of them)."""
    a = detail_field(harness, (0.3, 0.2), 0.0015)
    for lag in (1.0, 2.5, 10.0):
        shifted = detail_field(harness, (0.3 + lag, 0.2), 0.0015)
        assert abs(correlation(a, shifted)) < 0.2, lag


def test_detail_has_pixel_scale_contrast_near_and_fades_far(harness):
    near = detail_field(harness, (0.3, 0.2), 0.0015)  # a 2 m stand-off at 1.5 mm a pixel
    assert 0.85 < near.mean() < 1.05 and near.min() >= 0.0
    assert high_pass(near).std() > 0.05
    far = detail_field(harness, (0.3, 0.2), 0.05)  # 5 cm a pixel: no speckle left
    assert far.std() < 0.03 and abs(far.mean() - near.mean()) < 0.05


def test_grains_are_particles_set_in_paste_each_inside_its_cell(harness):
    """Sand and aggregate are grains with paste between them, not cells that each fill with
    one shade (a tessellation reads as polygon tiles): most points are paste (0), grains come
    light and dark, and none reaches its cell's border (docs/design.md, "Concrete detail")."""
    step, cell = 0.02, 1.0  # in cells: 50 points across each
    r, c = np.mgrid[0:16 * WIDTH, 0:WIDTH]
    pos = np.zeros((r.size, 4), np.float32)
    pos[:, 0], pos[:, 1] = 0.013 + c.ravel() * step, 0.007 + r.ravel() * step
    out = harness.run(f"vec4(grains(in0.xy, {step}, {cell}, 0.8, 5u))", pos)[:, 0]
    paste = np.mean(out == 0.0)
    assert 0.6 < paste < 0.95, paste  # 0.8 of the cells hold a grain of ~0.2 of its area
    assert out.min() < -0.3 and out.max() > 0.3
    u, v = np.modf(pos[:, 0] / cell)[0], np.modf(pos[:, 1] / cell)[0]
    border = (np.minimum(u, 1 - u) < 0.015) | (np.minimum(v, 1 - v) < 0.015)
    assert border.sum() > 1000 and np.all(out[border] == 0.0)


def _plate_image(detail_seed: int | None) -> np.ndarray:
    """A fronto-parallel plate 1.56 mm a pixel whose built-in concrete texture repeats twice
    across the image (every 64 pixels)."""
    texture = concrete(32, make_rng(0, 0, Stream.MATERIALS))
    cam = camera(128, 64)
    mat = Material(uv_scale=2.0, base_color_map=texture, detail_seed=detail_seed)
    mesh = pixel_plate(cam, 0.2)
    mesh.visual.uv = mesh.visual.uv * np.array([1.0, 0.5])  # square texels
    scene = scene_of(("plate", Component.COLUMN, mesh, mat))
    out = render_once(scene, render_config(128, 64), cam, passes={"color"})
    return out.color.astype(float).mean(2)


def test_rendered_detail_breaks_the_texture_tiles_repetition():
    plain, detailed = _plate_image(None), _plate_image(123)
    lag = 64  # the tile period in pixels
    def tile_correlation(img: np.ndarray) -> float:
        hp = high_pass(img)[2:-2, 2:-2]
        return correlation(hp[:, :-lag], hp[:, lag:])
    assert tile_correlation(plain) > 0.9  # the texture alone repeats
    assert tile_correlation(detailed) < 0.4  # the texture's own share still repeats
    assert np.array_equal(detailed, _plate_image(123))


CONFIG = dataclasses.replace(Config(), damage=DamageConfig(resolution=64),
                             materials=MaterialsConfig(texture_size=32, images_per_category=4))


def _seeds(config: Config, env, visible: set[str]
           ) -> tuple[dict[str, int | None], dict[str, Assignment]]:
    d = dress(env, config, open_repository(config), DamageBank(config.damage, 0), visible)
    seeds = {}
    for part in env.parts:
        seeds[part.name] = d.materials[part.name].detail_seed
        assert d.materials.factors(part.name).detail_seed == seeds[part.name]
    return seeds, d.assignments


def test_detail_is_drawn_in_flights_only_by_default():
    assert load_config("paper").materials.concrete_detail == "flights"
    env = build_environment(CONFIG, 0, 0)
    column = next(p.name for p in env.parts if p.kind is PartKind.COLUMN)
    seeds, _ = _seeds(CONFIG, env, {column})
    assert all(s is None for s in seeds.values())  # generate and render: as before
    flying = dataclasses.replace(CONFIG, materials=flight_materials(CONFIG.materials))
    assert flying.materials.concrete_detail == "on"
    seeds, assignments = _seeds(flying, env, {column})
    concrete = {n for n, a in assignments.items() if a.category == "concrete"}
    assert column in concrete and all(0 <= seeds[n] < 2**32 for n in concrete)
    assert all(seeds[n] is None for n in set(seeds) - concrete)
    assert len({seeds[n] for n in concrete}) == len(concrete)  # each part its own
    assert _seeds(flying, env, {column})[0] == seeds
    off = dataclasses.replace(CONFIG.materials, concrete_detail="off")
    assert flight_materials(off) == off


def test_a_bad_setting_is_one_line():
    with pytest.raises(ValueError, match="concrete_detail"):
        MaterialsConfig(concrete_detail="always")
    with pytest.raises(ValueError, match="detail_seed"):
        Material(detail_seed=-1)


TINY = """[render]
width = 480
height = 270
msaa = 0
[damage]
resolution = 512
[environment]
n_viaducts = 2
cutoff_factor = 1.0
[flight]
column = 4
standoff_m = 2.0
focal_mm = 50.0
max_frames = 4
"""
"""The paper preset's flight, but for two viaducts and 512 px damage maps (its 2048 px bank
filled the first flight's cache: 25 CPU-s the two flights, 18 now, 11 of them the texture
repository made for the session); metering and detail are the subject, not the damage."""


@pytest.fixture(scope="module")
def tiny_flights(tmp_path_factory):
    """A 4-frame, 2 m orbit at 480x270 (3 mm a pixel), as glsynth flew it before concrete
    detail and metering ("off", "scene") and as it flies now (the defaults)."""
    folder = tmp_path_factory.mktemp("tiny")
    flights = {}
    for name, settings in (("before", 'exposure = "scene"\n[materials]\n'
                                      'concrete_detail = "off"\n'), ("now", "")):
        cfg = folder / f"{name}.toml"
        cfg.write_text(TINY + settings)
        flights[name] = folder / name
        assert main(["fly", "--preset", "paper", "--seed", "0", "--env", "0", "--config",
                     str(cfg), "--out", str(flights[name])]) == 0
    return flights


def _frames(out) -> list[Path]:
    return sorted((out / "frames").iterdir())


def test_a_metered_flight_puts_its_median_pixel_at_mid_grey(tiny_flights):
    scene = load_config("paper").lighting.exposure
    before = [json.loads((f / "camera.json").read_text()) for f in _frames(tiny_flights["before"])]
    now = [json.loads((f / "camera.json").read_text()) for f in _frames(tiny_flights["now"])]
    assert {m["exposure"] for m in before} == {scene}
    assert len({m["exposure"] for m in now}) == 1 and now[0]["exposure"] > scene
    luminance = np.concatenate([
        srgb_decode(np.asarray(Image.open(f / "image.png").convert("RGB"))).reshape(-1, 3)
        @ LUMINANCE for f in _frames(tiny_flights["now"])])  # 4 frames: all are metered
    assert np.median(luminance) == pytest.approx(MID_GREY, abs=0.01)


def _keypoints(tmp_path, out) -> list[int]:
    pycolmap = pytest.importorskip("pycolmap", reason="pycolmap is not installed (the "
                                   "[flights] extra)")
    database = tmp_path / f"{out.name}.db"
    names = [str(f.relative_to(out) / "image.png") for f in _frames(out)]
    pycolmap.extract_features(database, out, image_names=names)
    db = pycolmap.Database.open(database)
    try:
        return [db.read_keypoints(im.image_id).shape[0] for im in db.read_all_images()]
    finally:
        db.close()


def test_colmap_finds_more_features_with_detail_and_metering(tmp_path, tiny_flights):
    """SIFT found 61-123 keypoints a frame on the flight as glsynth flew it before, and finds
    466-550 now (measured; 961-1,128 while sand and aggregate were Voronoi cells, whose
    polygon corners SIFT took for features): the floor and the ratio (4x; measured 6x)."""
    before = _keypoints(tmp_path, tiny_flights["before"])
    now = _keypoints(tmp_path, tiny_flights["now"])
    assert min(now) >= 300, now
    assert np.median(now) >= 4 * np.median(before), (before, now)
