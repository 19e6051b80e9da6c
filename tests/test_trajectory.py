import math

import numpy as np
import pytest

from glsynth.core.config import EnvironmentConfig
from glsynth.core.seeding import Stream, make_rng
from glsynth.world.trajectory import band_limited_noise, enforce_constraints, generate_trajectory

L = 24.0


def trajectory(env: int = 0, **cfg):
    return generate_trajectory(EnvironmentConfig(**cfg), L, make_rng(0, env, Stream.GEOMETRY))


def test_noise_has_a_rectangular_spectrum_below_the_cutoff():
    n, cutoff = 64, 2 / 10
    x = band_limited_noise(n, cutoff, 0.7, make_rng(1, 0, Stream.GEOMETRY))
    spectrum = np.abs(np.fft.rfft(x, norm="ortho"))
    freqs = np.fft.rfftfreq(n)
    inside = (freqs <= cutoff) & (freqs > 0)
    assert np.allclose(spectrum[inside], 0.7)
    assert np.allclose(spectrum[freqs > cutoff], 0.0, atol=1e-12)
    assert spectrum[0] <= 0.7 + 1e-12  # DC: amplitude times cos(phase)


def test_table4_and_radius_range_hold_over_many_seeds():
    heights, slopes, first = [], [], []
    for env in range(400):
        t = trajectory(env)
        assert np.all(np.isfinite(t.curvature)) and np.all(np.isfinite(t.deck_m))
        heights.append(t.heights_m)
        slopes.append(t.slopes)
        first.append(t.heights_m[0])
        assert 500.0 <= t.min_radius_m <= 5000.0
        # The scaling makes the sampled minimum radius the actual smallest radius.
        assert np.isclose(t.radii_m.min(), t.min_radius_m, rtol=1e-12)
    heights, slopes = np.concatenate(heights), np.concatenate(slopes)
    assert heights.min() >= 5.0 and heights.max() <= 14.0
    assert np.abs(slopes).max() < 0.02
    assert 6.5 <= min(first) and max(first) <= 12.0
    # The constraints bind (the heights spread to the Table 4 limits) without pinning everything.
    assert heights.min() < 5.5 and heights.max() > 13.0
    assert np.mean((heights > 5.0) & (heights < 14.0)) > 0.95


def test_constraints_hold_for_violent_increments():
    rng = make_rng(3, 0, Stream.GEOMETRY)
    g, h = rng.normal(0, 50, 200), rng.normal(0, 20, 200)
    ground, height = enforce_constraints(g, h, 6.5, L, (5.0, 14.0), 0.02)
    deck = ground + height
    assert height.min() >= 5.0 and height.max() <= 14.0
    assert np.abs(np.diff(deck) / L).max() < 0.02


def test_straight_track_has_infinite_radius_and_no_nan():
    t = trajectory(min_radius_m=(math.inf, math.inf))
    assert np.all(t.curvature == 0.0)
    assert np.all(np.isinf(t.radii_m))
    s = np.linspace(-30, t.total_length_m + 30, 1001)
    points, tangent, normal = t.frame(s)
    assert np.all(np.isfinite(points))
    assert np.allclose(points[:, 0], s) and np.allclose(points[:, 1], 0.0)
    assert np.allclose(tangent, [1, 0, 0]) and np.allclose(normal, [0, 1, 0])


def test_tightest_curve_follows_exact_arcs():
    t = trajectory(min_radius_m=(500.0, 500.0))
    assert np.isclose(t.radii_m.min(), 500.0)
    i = int(np.argmax(np.abs(t.curvature)))
    s = i * L + np.linspace(0.0, L, 200)
    points, tangent, normal = t.frame(s)
    # Points of viaduct i lie on a circle of radius 1/|k| around the centre of curvature.
    k = t.curvature[i]
    centre = points[0, :2] + normal[0, :2] / k
    assert np.allclose(np.linalg.norm(points[:, :2] - centre, axis=1), 1 / abs(k), rtol=1e-12)
    # Arc-length parameterisation and unit frames.
    steps = np.linalg.norm(np.diff(points[:, :2], axis=0), axis=1)
    assert np.allclose(steps.sum(), L, rtol=1e-5)
    assert np.allclose(np.linalg.norm(tangent, axis=1), 1) and np.allclose(
        np.einsum("ij,ij->i", tangent, normal), 0)


def test_centre_line_is_continuous_at_viaduct_joints():
    t = trajectory(min_radius_m=(500.0, 500.0))
    joints = np.arange(1, t.n) * L
    before, tb, _ = t.frame(joints - 1e-9)
    after, ta, _ = t.frame(joints + 1e-9)
    assert np.allclose(before, after, atol=1e-6) and np.allclose(tb, ta, atol=1e-9)


def test_zero_curvature_limit_matches_small_curvature():
    # The sinc chord is continuous at curvature 0: a 1e9 m radius is indistinguishable.
    straight = trajectory(min_radius_m=(math.inf, math.inf))
    nearly = trajectory(min_radius_m=(1e12, 1e12))
    s = np.linspace(0, 240, 50)
    assert np.allclose(straight.frame(s)[0][:, :2], nearly.frame(s)[0][:, :2], atol=1e-6)


def test_same_seed_same_trajectory_other_env_differs():
    a, b, c = trajectory(5), trajectory(5), trajectory(6)
    assert np.array_equal(a.curvature, b.curvature) and np.array_equal(a.deck_m, b.deck_m)
    assert not np.array_equal(a.curvature, c.curvature)


def test_arrays_are_read_only():
    with pytest.raises(ValueError):
        trajectory().heights_m[0] = 1.0
