"""A kept view's label maps (glsynth.data.dataset._label_maps), which mask and encode at the
sampled block centres only: the same maps as masking and encoding the whole render first."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from glsynth.core.config import FiltersConfig
from glsynth.core.filters import mask_damage, view_rrdr
from glsynth.core.labels import Damage
from glsynth.core.seeding import Stream, make_rng
from glsynth.data.dataset import _label_maps
from glsynth.data.tokaido import (
    downsample_crack_width,
    downsample_damage,
    downsample_labels,
    encode_crack_width,
    encode_depth,
    mark_cracked_blocks,
)
from glsynth.render.gl.renderer import RenderOutput
from glsynth.world.cameras import Camera

FILTERS = (FiltersConfig(), FiltersConfig(rrdr_crack_mm=0.2))
"""The paper's RRDR and the one for cracks."""


def whole_image_maps(output: RenderOutput, camera: Camera, filters: FiltersConfig):
    """The maps as generate made them before: the RRDR mask and the depth code over the whole
    render, then downsampled."""
    reliable = view_rrdr(filters, output.depth, camera.fx)
    widths = np.where(reliable, output.crack_width, np.float32(0))
    blocks = downsample_crack_width(widths)
    maps = {"component": downsample_labels(output.component),
            "damage": downsample_damage(mask_damage(output.damage, reliable), blocks),
            "depth": downsample_labels(encode_depth(output.depth)),
            "crackwidth": encode_crack_width(blocks)}
    return maps, bool(np.any(maps["damage"] >= Damage.CONCRETE)), widths


def random_output(seed: int, cracks: bool) -> RenderOutput:
    """A 36 x 48 render: depths from 0.2 m to beyond 30 m (and the far plane), ids of every
    kind, thin cracks in places."""
    rng = make_rng(seed, 0, Stream.GEOMETRY)
    h, w = 36, 48
    depth = rng.uniform(0.2, 40.0, (h, w)).astype(np.float32)
    depth[rng.random((h, w)) < 0.2] = 2000.0
    widths = np.zeros((h, w), np.float32)
    if cracks:
        widths = np.where(rng.random((h, w)) < 0.1, rng.uniform(0.05, 3.0, (h, w)),
                          0).astype(np.float32)
    return RenderOutput(component=rng.integers(1, 9, (h, w), dtype=np.uint8),
                        damage=rng.integers(0, 4, (h, w), dtype=np.uint8), depth=depth,
                        crack_width=widths)


@pytest.mark.parametrize("filters", FILTERS)
@given(seed=st.integers(0, 2**32 - 1), cracks=st.booleans(),
       focal_mm=st.floats(15.0, 55.0))
def test_label_maps_at_the_sampled_pixels_are_the_whole_images(filters, seed, cracks,
                                                                focal_mm):
    output = random_output(seed, cracks)
    camera = Camera(48, 36, focal_mm, 36.0 / 40.0, np.eye(4), 0.05, 2000.0)
    maps, flag, widths = _label_maps(output, camera, filters)
    want_maps, want_flag, want_widths = whole_image_maps(output, camera, filters)
    assert flag == want_flag
    assert np.array_equal(widths, want_widths)
    for name, want in want_maps.items():
        assert maps[name].dtype == want.dtype, name
        assert np.array_equal(maps[name], want), name


def test_mark_cracked_blocks_marks_concrete_and_keeps_rebar():
    blocks = np.array([[0, 1, 2, 3]], np.uint8)
    widths = np.array([[0.3, 0.3, 0.3, 0.3]], np.float32)
    assert mark_cracked_blocks(blocks, widths).tolist() == [[2, 2, 2, 3]]
    assert mark_cracked_blocks(blocks, np.zeros((1, 4), np.float32)).tolist() == [[0, 1, 2, 3]]
    with pytest.raises(ValueError, match="differ in size"):
        mark_cracked_blocks(blocks, np.zeros((2, 4), np.float32))
