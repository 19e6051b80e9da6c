"""The ground's centimetre detail (shaders/ground_detail.glsl; docs/design.md, "The ground up
close"): bare soil through a worn cover, dark brown and damp in patches, clods, stones and
leaves, fading to its mean where a pixel's footprint outgrows them."""

import dataclasses

import cv2
import numpy as np
import pytest
from glhelpers import half_inspection
from shader_harness import GlslHarness

from glsynth.core.labels import Component
from glsynth.core.seeding import Stream, make_rng
from glsynth.render.view import EnvironmentView
from glsynth.world.lighting import LUMINANCE

LUMA = np.array([0.299, 0.587, 0.114])

GRASS = (0.05, 0.12, 0.03)
"""A linear grass green, as the repository's ground images give the cover."""


@pytest.fixture(scope="module")
def harness():
    with GlslHarness("ground_detail.glsl") as h:
        yield h


def ground(harness, x: np.ndarray, y: np.ndarray, footprint: float, seed: int,
           grid: bool = True) -> np.ndarray:
    """Linear colours of the ground of part ``seed``: (len(y), len(x), 3) over the grid of
    ``x`` and ``y``, or (len(x), 3) at the points (x, y) where ``grid`` is False."""
    gx, gy = np.meshgrid(x, y) if grid else (x, y)
    points = np.zeros((gx.size, 4), np.float32)
    points[:, 0], points[:, 1], points[:, 2] = gx.ravel(), gy.ravel(), seed
    expression = f"ground_at(vec3{GRASS}, in0.xy, {footprint}, uint(in0.z)), 0.0"
    colours = harness.run(expression, points)[:, :3]
    return colours.reshape(len(y), len(x), 3) if grid else colours


def test_the_cover_wears_through_to_dark_brown_soil_on_about_half_the_ground(harness):
    """Over 8 parts of 40 x 40 m: bare soil (redder than green, as no grass is) on 50-70 % of
    the ground (the shader's 61 %, less where a stone or leaf covers it), its luminance the
    soil's 6.7-10.9 % albedo times its clods, and half that damp."""
    shares, lum = [], []
    for seed in range(8):
        c = ground(harness, np.arange(0.0, 40.0, 0.5), np.arange(0.0, 40.0, 0.5), 0.01, seed)
        soil = c[..., 0] > c[..., 1]
        shares.append(soil.mean())
        lum.append(c[soil] @ LUMINANCE)
    assert 0.5 <= np.mean(shares) <= 0.7 and min(shares) > 0.1
    lum = np.concatenate(lum)
    assert 0.03 <= np.median(lum) <= 0.14
    assert np.quantile(lum, 0.05) < 0.5 * np.quantile(lum, 0.95)  # damp and dry, clods


@pytest.mark.parametrize("name, mean, expression", [
    ("bare soil", "BARE_MEAN", "bare_soil(in0.xy, 1e-4, uint(in0.z))"),
    ("damp soil", "DAMP_MEAN", "damp_soil(in0.xy, 1e-4, uint(in0.z))"),
    ("voids", "VOID_MEAN", "holes(in0.xy, 1e-4, 0.015, 0.3, 0.001, 0.004, uint(in0.z))")])
def test_each_patchy_feature_fades_to_its_share_of_the_area(harness, name, mean, expression):
    """The share a feature fades to far away is its share up close (over 16 salts of 100 x
    100 m, within 0.01): far ground keeps the near ground's mix."""
    shares = []
    for salt in range(16):
        xy = make_rng(salt, 0, Stream.DETAIL).uniform(0.0, 100.0, (40000, 2))
        points = np.zeros((len(xy), 4), np.float32)
        points[:, :2], points[:, 2] = xy, salt
        shares.append(harness.run(f"vec4({expression}, {mean}, 0.0, 0.0)", points)[:, :2])
    shares = np.concatenate(shares)
    assert shares[:, 0].mean() == pytest.approx(shares[0, 1], abs=0.01), name


def test_centimetre_detail_shows_up_close_and_fades_to_its_mean_far_away(harness):
    """At 1 mm a pixel, samples 2 mm apart differ by 1 % of the luminance or more on average
    (clods, voids, stones, leaves); at 0.5 m a pixel by a tenth of that at most; at 1 and 5 m
    a pixel, samples a pixel apart by under 1 %: the features fade rather than alias. Over
    200 x 200 m the mean luminance stays within 1 %."""
    x = np.arange(0.0, 0.4, 0.002)
    for seed in range(1, 9):
        near = ground(harness, x + 5.0 * seed, x, 0.001, seed) @ LUMINANCE
        far = ground(harness, x + 5.0 * seed, x, 0.5, seed) @ LUMINANCE
        step_near = np.abs(np.diff(near, axis=1)).mean() / near.mean()
        step_far = np.abs(np.diff(far, axis=1)).mean() / far.mean()
        assert step_near > 0.01 and step_far < 0.1 * step_near
        for footprint in (1.0, 5.0):  # distant ground: a pixel apart
            apart = np.arange(0.0, 200.0 * footprint, footprint)
            row = ground(harness, apart, apart[:1], footprint, seed)[0] @ LUMINANCE
            assert np.abs(np.diff(row)).mean() / row.mean() < 0.01
        xy = make_rng(seed, 0, Stream.DETAIL).uniform(0.0, 200.0, (40000, 2))
        means = [(ground(harness, xy[:, 0], xy[:, 1], fp, seed, grid=False) @ LUMINANCE).mean()
                 for fp in (0.001, 0.5)]
        assert abs(means[1] / means[0] - 1.0) < 0.01


def test_the_detail_is_a_function_of_position_and_seed(harness):
    x = np.arange(0.0, 1.0, 0.01)
    a, b = (ground(harness, x, x, 0.002, 7) for _ in range(2))
    assert a.tobytes() == b.tobytes()
    assert not np.array_equal(a, ground(harness, x, x, 0.002, 8))


FOOT_VIEW = (11, 0, 7)
"""Seed, environment and camera of an inspection view that, with every camera not aimed at a
crack made a foot view, looks at a column's foot and the ground before it."""


@pytest.fixture(scope="module")
def foot_views():
    """The foot view rendered (half size, no MSAA) with and without the ground's detail."""
    outputs = {}
    for detail in (True, False):
        config = half_inspection()
        config = dataclasses.replace(
            config, cameras=dataclasses.replace(config.cameras, face_foot_share=1.0),
            materials=dataclasses.replace(config.materials, ground_detail=detail))
        seed, env, camera = FOOT_VIEW
        view = EnvironmentView.open(config, seed, env, rendering=(camera,))
        with view.renderer:
            outputs[detail] = view.render(camera, frozenset({"color", "component", "depth"}),
                                          photo=False)[1]
    return outputs


def test_a_foot_view_shows_the_grounds_detail_and_nothing_else_changes(foot_views):
    """In a rendered foot view the near ground (non-bridge, within 4 m) shows its clods and
    stones: neighbouring pixels differ 4 times as much as on the image's ground alone (7.8
    times when written); every
    pixel of the column is the same byte for byte (the ground's variant draws the ground
    alone)."""
    on, off = foot_views[True], foot_views[False]
    size = on.color.shape[1::-1]
    component = cv2.resize(on.component, size, interpolation=cv2.INTER_NEAREST)
    depth = cv2.resize(on.depth, size, interpolation=cv2.INTER_NEAREST)
    near_ground = (component == Component.NONBRIDGE) & (depth < 4.0)
    assert near_ground.mean() > 0.05
    steps = {}
    for detail, output in foot_views.items():
        luma = output.color.astype(float) @ LUMA
        step = np.abs(np.diff(luma, axis=1))
        steps[detail] = step[near_ground[:, 1:] & near_ground[:, :-1]].mean()
    assert steps[True] > 4.0 * steps[False]
    column = cv2.erode((component == Component.COLUMN).astype(np.uint8), np.ones((3, 3)))
    assert column.sum() > 1000
    assert np.array_equal(on.color[column > 0], off.color[column > 0])
