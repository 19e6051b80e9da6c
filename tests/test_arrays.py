"""glsynth.core.arrays: unique_ints is np.unique for integer arrays, at the edges too."""

import numpy as np
import pytest

from glsynth.core.arrays import unique_ints
from glsynth.core.seeding import Stream, make_rng


@pytest.mark.parametrize("values", [
    np.zeros(0, np.int64), np.array([7]), np.full(50, -3, np.int32),
    np.array([2**62, -2**62, 0, 2**62], np.int64), np.arange(10, dtype=np.uint8)[::-1],
    make_rng(0, 0, Stream.GEOMETRY).integers(-1000, 1000, (40, 30)),
    make_rng(0, 1, Stream.GEOMETRY).integers(0, 2**40, 100_000)])
def test_unique_ints_is_np_unique(values):
    got = unique_ints(values)
    expected = np.unique(values)
    assert got.dtype == expected.dtype and np.array_equal(got, expected)


def test_unique_ints_refuses_floats():
    with pytest.raises(TypeError, match="integers only"):
        unique_ints(np.array([np.nan, np.nan]))
