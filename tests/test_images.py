"""The one nearest-resize convention (pixel centres), shared by labels, predictions and the
dataset's 3x downsampling."""

import numpy as np
import pytest
from PIL import Image

from glsynth.core.images import nearest_indices, nearest_resize
from glsynth.data.tokaido import downsample_labels


def test_centres_not_corners():
    assert nearest_indices(6, 2).tolist() == [1, 4]  # the top-left convention gives [0, 3]
    assert nearest_indices(2, 6).tolist() == [0, 0, 0, 1, 1, 1]
    assert nearest_indices(5, 5).tolist() == [0, 1, 2, 3, 4]


@pytest.mark.parametrize("n_in, n_out", [(6, 2), (1080, 360), (7, 3), (3, 7), (1920, 641),
                                         (100, 33), (33, 100), (1, 4)])
def test_agrees_with_pillow_nearest(n_in, n_out):
    values = np.arange(n_in, dtype=np.int32)[None, :]
    pillow = np.asarray(Image.fromarray(values).resize((n_out, 1), Image.Resampling.NEAREST))
    assert np.array_equal(nearest_resize(values, (1, n_out)), pillow)


def test_the_dataset_downsampling_is_the_same_helper():
    labels = np.arange(9 * 12, dtype=np.uint8).reshape(9, 12)
    assert np.array_equal(downsample_labels(labels), labels[1::3, 1::3])
    assert np.array_equal(downsample_labels(labels), nearest_resize(labels, (3, 4)))


def test_ids_never_blend_and_same_size_is_untouched():
    ids = np.array([[1, 2], [3, 4]], np.uint8)
    up = nearest_resize(ids, (5, 7))
    assert set(np.unique(up)) == {1, 2, 3, 4} and up.dtype == np.uint8
    assert nearest_resize(ids, (2, 2)) is ids
