import numpy as np
import pytest

from glsynth.core.seeding import Stream, make_rng


def test_same_inputs_same_stream_and_independent_items():
    a = make_rng(7, 3, Stream.GEOMETRY, 1).random(5)
    assert np.array_equal(a, make_rng(7, 3, Stream.GEOMETRY, 1).random(5))
    others = [make_rng(8, 3, Stream.GEOMETRY, 1), make_rng(7, 4, Stream.GEOMETRY, 1),
              make_rng(7, 3, Stream.CAMERAS, 1), make_rng(7, 3, Stream.GEOMETRY, 2)]
    for rng in others:
        assert not np.array_equal(a, rng.random(5))


@pytest.mark.parametrize("args", [(-1, 0, Stream.GEOMETRY), (0, 1.5, Stream.GEOMETRY),
                                  (0, True, Stream.GEOMETRY), (None, 0, Stream.GEOMETRY)])
def test_bad_seeds_are_rejected(args):
    with pytest.raises(ValueError, match="must be an integer >= 0"):
        make_rng(*args)


def test_stream_must_be_a_stream():
    with pytest.raises(TypeError, match="Stream"):
        make_rng(0, 0, 3)
