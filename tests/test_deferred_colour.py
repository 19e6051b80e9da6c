"""The colour deferred past the filters (Renderer.render(defer_colour=True), deferred_colour,
glsynth.core.filters.removal_before_resolve, glsynth.data.dataset._filtered): the MSAA pass
runs only for views the single-sample colour cannot decide, and every decision is
removal_reason's on the resolved colour."""

import dataclasses

import cv2
import numpy as np
import pytest
from glhelpers import loaded_renderer, render_config
from hypothesis import given
from hypothesis import strategies as st

from glsynth.core.config import Config, FiltersConfig
from glsynth.core.filters import (
    label_reason,
    removal_before_resolve,
    removal_reason,
)
from glsynth.core.seeding import Stream, make_rng
from glsynth.data.dataset import _filtered
from glsynth.render.gl.renderer import Renderer
from glsynth.render.view import EnvironmentView, preview_config
from glsynth.world.cameras import environment_camera

CROSS = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
RC = render_config(160, 90, msaa=4)


def cam(env0, index):
    return environment_camera(env0.trajectory, Config().cameras, RC, 0, 0, index).camera


@pytest.fixture(scope="module")
def loaded(env0):
    with loaded_renderer(env0, RC) as r:
        yield r


@pytest.mark.parametrize("index", [0, 30, 55, 90])
def test_a_deferred_colour_is_the_renders_and_lies_within_each_pixels_cross(env0, loaded,
                                                                            index):
    """What removal_before_resolve relies on: each resolved channel lies between the minimum
    and the maximum of the single-sample colour over the pixel and its four neighbours."""
    camera = cam(env0, index)
    plain = loaded.render(camera)
    deferred = loaded.render(camera, defer_colour=True)
    assert deferred.color is None
    for name in ("component", "damage", "depth", "crack_width"):
        assert np.array_equal(getattr(deferred, name), getattr(plain, name)), name
    single = loaded.deferred_colour(resolved=False)
    resolved = loaded.deferred_colour()
    assert np.array_equal(resolved, plain.color)
    assert (resolved != single).any(axis=2).any()  # edges the resolve changed
    assert (cv2.erode(single, CROSS) <= resolved).all()
    assert (resolved <= cv2.dilate(single, CROSS)).all()


def test_deferred_colour_needs_a_deferred_render_and_resolves_once(env0, loaded):
    camera = cam(env0, 0)
    loaded.render(camera)
    with pytest.raises(ValueError, match="defer_colour=True"):
        loaded.deferred_colour()
    loaded.render(camera, defer_colour=True)
    loaded.deferred_colour()
    with pytest.raises(ValueError, match="defer_colour=True"):
        loaded.deferred_colour(resolved=False)


def test_without_msaa_the_deferred_colour_is_the_renders_either_way(env0):
    config = render_config(160, 90, msaa=0)
    with loaded_renderer(env0, config) as r:
        camera = environment_camera(env0.trajectory, Config().cameras, config, 0, 0, 30).camera
        plain = r.render(camera).color
        r.render(camera, defer_colour=True)
        single = r.deferred_colour(resolved=False)
        assert np.array_equal(single, plain)
        assert r.deferred_colour() is single  # read back once


def test_label_reason_is_removal_reason_after_the_dark_filter():
    far, near = np.full((4, 4), 5.0, np.float32), np.full((4, 4), 0.3, np.float32)
    bright = np.full((4, 4, 3), 200, np.uint8)
    for component in (np.full((4, 4), 3, np.uint8), np.arange(16, dtype=np.uint8).reshape(4, 4),
                      np.arange(16, dtype=np.int32).reshape(4, 4) % 2,
                      np.full((4, 4), 7, np.int64)):
        for depth in (far, near):
            assert label_reason(component, depth) == removal_reason(bright, component, depth)
    assert label_reason(np.full((4, 4), 3, np.uint8), far) == "single_component"
    assert label_reason(np.arange(16, dtype=np.uint8).reshape(4, 4), near) == "too_close"


def _resolve(single: np.ndarray, picks: np.ndarray) -> np.ndarray:
    """A resolve as msaa_resolve.frag makes one: each of a pixel's four samples takes the
    colour of the pixel or of one of its four neighbours (``picks``: (H, W, 4) in 0-4, a
    neighbour beyond the image being the pixel itself), and the pixel their rounded mean."""
    h, w = single.shape[:2]
    rows, cols = np.mgrid[0:h, 0:w]
    offsets = np.array([(0, 0), (0, 1), (0, -1), (1, 0), (-1, 0)])
    total = np.zeros(single.shape, np.float64)
    for s in range(4):
        dr, dc = offsets[picks[..., s]].transpose(2, 0, 1)
        total += single[np.clip(rows + dr, 0, h - 1), np.clip(cols + dc, 0, w - 1)]
    return np.floor(total / 4 + 0.5).astype(np.uint8)


@given(st.integers(0, 2**32 - 1), st.integers(0, 60), st.integers(1, 80),
       st.sampled_from([None, "single_component", "too_close"]))
def test_a_decision_before_the_resolve_is_removal_reasons_after_any_resolve(seed, low, spread,
                                                                             by_labels):
    rng = make_rng(seed, 0, Stream.GEOMETRY)
    single = rng.integers(low, min(255, low + spread), (12, 16, 3), endpoint=True,
                          dtype=np.uint8)
    decided = removal_before_resolve(single, by_labels)
    for _ in range(5):
        resolved = _resolve(single, rng.integers(0, 5, (12, 16, 4)))
        dark = float(resolved.mean()) < FiltersConfig().min_intensity
        if decided is not None:
            assert decided == ("dark" if dark else by_labels)


def test_removal_before_resolve_decides_clear_views_and_leaves_the_rest():
    dim, bright = np.full((8, 8, 3), 12, np.uint8), np.full((8, 8, 3), 90, np.uint8)
    assert removal_before_resolve(dim, None) == "dark"
    assert removal_before_resolve(dim, "too_close") == "dark"
    assert removal_before_resolve(bright, "single_component") == "single_component"
    assert removal_before_resolve(bright, None) is None  # kept: the image needs the resolve
    # Half the pixels at 0, half at 60: a mean of 30 that a resolve can move either way.
    edge = np.zeros((8, 8, 3), np.uint8)
    edge[:, ::2] = 60
    assert removal_before_resolve(edge, "too_close") is None
    assert removal_before_resolve(edge[:, :7], "too_close") is None  # mean just under 30
    lenient = FiltersConfig(min_intensity=0.0)
    assert removal_before_resolve(np.zeros((8, 8, 3), np.uint8), "too_close",
                                  lenient) == "too_close"


def test_generate_filters_a_real_environment_as_before_and_skips_msaa_where_it_can(
        monkeypatch):
    """_filtered on real views at MSAA 4 (regular and close-up cameras of environment 0, a
    third of them removed): removal_reason's answer on the resolved colour, the same colour for
    the kept views, and fewer MSAA passes than views."""
    base = preview_config(Config(), 320)
    config = dataclasses.replace(base, render=dataclasses.replace(base.render, msaa=4))
    indices = list(range(0, config.cameras.total, 3))
    with Renderer(config.render) as renderer:
        # Culled for these views (the same bytes as for all: tests/test_render_viaduct.py).
        view = EnvironmentView.open(config, 0, 0, renderer, rendering=indices)
        expected = []
        for index in indices:
            _, out = view.render(index, photo=False)
            expected.append((removal_reason(out.color, out.component, out.depth), out.color))
        passes = []
        original = renderer._msaa_pass
        monkeypatch.setattr(renderer, "_msaa_pass", lambda *a: passes.append(1) or original(*a))
        for index, (reason, colour) in zip(indices, expected, strict=True):
            _, deferred = view.render(index, photo=False, defer_colour=True)
            got, out = _filtered(renderer, deferred, config.filters)
            assert got == reason, index
            if reason is None:
                assert np.array_equal(out.color, colour), index
        # A deferred colour cannot be photographed in the same call: refused, not skipped.
        with pytest.raises(ValueError, match="photo=False"):
            view.render(indices[0], defer_colour=True)
    removed = sum(reason is not None for reason, _ in expected)
    assert removed >= 3
    assert len(passes) <= len(indices) - 2  # removed views decided without the resolve
