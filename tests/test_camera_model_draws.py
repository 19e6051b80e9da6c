"""The camera model's sensor-noise draws (OpenCV's generator seeded from the view's) and its
defocus blend (each level copied where a pixel needs it, blended once) against the plain
per-level weighted sum, on synthetic frames (tests/test_camera_model.py tests both on renders)."""

import numpy as np
import pytest

from glsynth.core.seeding import Stream, make_rng
from glsynth.render import camera_model


def test_noise_seed_is_the_generators_next_draw():
    seeds = {camera_model.noise_seed(make_rng(0, 0, Stream.SENSOR, i)) for i in range(8)}
    assert len(seeds) == 8 and all(1 <= s < 2**31 for s in seeds)
    assert camera_model.noise_seed(make_rng(0, 0, Stream.SENSOR, 3)) == \
        camera_model.noise_seed(make_rng(0, 0, Stream.SENSOR, 3))


def test_standard_normals_are_reproducible_and_standard():
    shape = (540, 960, 3)
    first, again, other = (np.empty(shape, np.float32) for _ in range(3))
    camera_model.fill_standard_normal(first, 12345)
    camera_model.fill_standard_normal(again, 12345)
    camera_model.fill_standard_normal(other, 12346)
    assert np.array_equal(first, again)
    assert np.abs(first - other).mean() > 1.0  # an independent draw: E|x - y| = 2 / sqrt(pi)
    # Each channel standard normal (1.5 M draws: the mean within 0.003, the variance 0.5 %),
    # the channels uncorrelated, and the tails a Gaussian's.
    for channel in range(3):
        values = first[..., channel].ravel().astype(np.float64)
        assert values.mean() == pytest.approx(0.0, abs=0.003)
        assert values.var() == pytest.approx(1.0, rel=0.005)
        assert np.mean(np.abs(values) > 2.0) == pytest.approx(0.0455, abs=0.001)
    red, blue = first[..., 0].ravel(), first[..., 2].ravel()
    assert abs(np.corrcoef(red, blue)[0, 1]) < 0.003


def _weighted_sum(linear: np.ndarray, diameter: np.ndarray) -> np.ndarray:
    """The defocus as its docstring states it: every level's blur times the pixel's weight
    max(0, 1 - |index - level|), summed."""
    index = camera_model.level_index(diameter)
    out = np.zeros_like(linear, dtype=np.float64)
    for level, level_diameter in enumerate(camera_model.DEFOCUS_LEVELS):
        weight = np.maximum(0.0, 1.0 - np.abs(index - level))[..., None]
        if weight.any():
            out += camera_model.disc_blur(linear, level_diameter) * weight
    return out


def test_defocus_is_the_weighted_sum_of_its_levels():
    """A frame whose blur circles ramp across every level, on levels exactly and between them,
    with a jump to the last (a sky edge) and a sharp stretch: the blend equals the per-level
    weighted sum to float32 rounding."""
    rng = make_rng(1, 0, Stream.SENSOR, 0)
    h, w = 200, 320
    linear = rng.random((h, w, 3), dtype=np.float32)
    ramp = np.geomspace(0.5, 80.0, w, dtype=np.float32)
    diameter = np.repeat(ramp[None, :], h, axis=0)
    diameter[:, :40] = 1.0  # sharp
    diameter[60:90] = np.float32(64.0)  # the last level, exactly
    diameter[120:140, 100:180] = np.float32(3.0)  # on a level
    diameter[150:, 200:] = np.float32(1.5)
    blended = camera_model.defocus(linear, diameter)
    assert blended.dtype == np.float32 and blended.shape == linear.shape
    assert np.abs(blended - _weighted_sum(linear, diameter)).max() < 2e-6
    # The sharp stretch away from any blur keeps the frame (weight 1 on level 0).
    sharp = (slice(0, 50), slice(0, 30))
    assert np.abs(blended[sharp] - linear[sharp]).max() < 1e-6


def test_defocus_skips_levels_no_pixel_needs(monkeypatch):
    """Blur circles of 1.5 and 64 px only: the levels between get no pixel, so only the two
    are blurred; the result is still the weighted sum."""
    rng = make_rng(2, 0, Stream.SENSOR, 0)
    linear = rng.random((96, 128, 3), dtype=np.float32)
    diameter = np.full((96, 128), 1.5, np.float32)
    diameter[:, 64:] = 64.0
    blurred: list[float] = []
    original = camera_model.disc_blur

    def counting(image: np.ndarray, diameter_px: float, scale: int | None = None
                 ) -> np.ndarray:
        blurred.append(diameter_px)
        return original(image, diameter_px, scale)

    monkeypatch.setattr(camera_model, "disc_blur", counting)
    blended = camera_model.defocus(linear, diameter)
    assert sorted(blurred) == [1.5, 64.0]
    assert np.abs(blended - _weighted_sum(linear, diameter)).max() < 2e-6


@pytest.mark.parametrize("diameter", [1.0, 3.0, 8.0, 16.0, 64.0])
def test_a_boxes_blur_is_the_whole_images_there(diameter):
    """Boxes inside, at the edges and at the corners of a frame, at blur scales 1 to 8: the
    crop's blur equals the whole frame's inside the box."""
    rng = make_rng(3, 0, Stream.SENSOR, 0)
    linear = rng.random((216, 384, 3), dtype=np.float32)
    whole = camera_model.disc_blur(linear, diameter)
    for x, y, w, h in ((0, 0, 50, 40), (101, 77, 93, 51), (300, 150, 84, 66), (0, 13, 384, 5),
                       (383, 215, 1, 1)):
        box = camera_model.disc_blur_box(linear, diameter, (x, y, w, h))
        assert box.shape == (h, w, 3)
        assert np.abs(box - whole[y:y + h, x:x + w]).max() < 1e-6, (x, y, w, h)
    assert camera_model.blur_scale(diameter, linear.shape) == (8 if diameter == 64 else
                                                                2 if diameter == 16 else 1)


def test_level_boxes_cover_the_pixels_that_need_the_level():
    """Two patches of one level, far apart in one strip of rows, and a third across the next
    strips' boundary: a box for each patch in each strip (the area between them is not
    blurred), every needed pixel inside one, none beyond the frame; patches within the
    blur's margins share a box; an empty mask has none."""
    strip = camera_model.STRIP_ROWS
    shape = (3 * strip, 640, 3)
    needed = np.zeros(shape[:2], np.uint8)
    needed[10:40, 20:60] = needed[50:90, 500:600] = 255
    needed[2 * strip - 30:2 * strip + 20, 300:330] = 255  # 30 rows above the boundary
    boxes = camera_model.level_boxes(needed, 3.0, shape)
    covered = np.zeros_like(needed)
    for x, y, w, h in boxes:
        assert 0 <= x and 0 <= y and x + w <= shape[1] and y + h <= shape[0]
        covered[y:y + h, x:x + w] = 255
    assert not np.any(needed & ~covered)
    assert sorted(boxes) == [(20, 10, 40, 30), (300, 2 * strip - 30, 30, 30),
                             (300, 2 * strip, 30, 20), (500, 50, 100, 40)]
    # 4 px apart: the 3 px disc reads 3 px around each box, so one box blurs them.
    close = np.zeros(shape[:2], np.uint8)
    close[10:20, 20:30] = close[10:20, 34:40] = 255
    assert camera_model.level_boxes(close, 3.0, shape) == [(20, 10, 20, 10)]
    assert camera_model.level_boxes(np.zeros(shape[:2], np.uint8), 3.0, shape) == []


def test_level_boxes_fall_back_to_one_box_where_the_blur_takes_the_whole_frame():
    """A frame whose sides are not whole pixels of the small image a wide disc is blurred on
    (disc_blur_box then blurs the whole frame): one bounding box, so that it does so once."""
    shape = (100, 200, 3)
    assert camera_model.blur_scale(40.0, shape) == 4 and shape[0] % 4 == 0  # the sides do fit
    odd = (102, 200, 3)
    needed = np.zeros(odd[:2], np.uint8)
    needed[5:10, 5:10] = needed[90:95, 150:160] = 255
    assert camera_model.level_boxes(needed, 40.0, odd) == [(5, 5, 155, 90)]
    assert len(camera_model.level_boxes(needed, 40.0, (104, 200, 3))) == 2


def test_defocus_blurs_each_level_only_where_it_is_needed(monkeypatch):
    """Two patches of strong blur at the sides of a sharp frame, in one strip of rows below
    its top (so the levels' bands start lower): the blend is the weighted sum, and each level
    blurs the patches' boxes, at their rows, not the bounding box between them."""
    rng = make_rng(4, 0, Stream.SENSOR, 0)
    h, w = 2 * camera_model.STRIP_ROWS, 512
    linear = rng.random((h, w, 3), dtype=np.float32)
    diameter = np.ones((h, w), np.float32)
    rows = slice(h // 2, h // 2 + 60)
    diameter[rows, :80] = diameter[rows, -80:] = np.float32(5.0)  # between levels 4 and 6 px
    boxes: list[tuple[int, int, int, int]] = []
    original = camera_model.disc_blur_box

    def recording(image: np.ndarray, diameter_px: float, box: tuple[int, int, int, int]
                  ) -> np.ndarray:
        if diameter_px > 1.0:
            boxes.append(box)
        return original(image, diameter_px, box)

    monkeypatch.setattr(camera_model, "disc_blur_box", recording)
    blended = camera_model.defocus(linear, diameter)
    assert np.abs(blended - _weighted_sum(linear, diameter)).max() < 2e-6
    patches = [(0, rows.start, 80, 60), (w - 80, rows.start, 80, 60)]
    assert sorted(boxes) == sorted(patches * 2)  # two levels, two patches each
