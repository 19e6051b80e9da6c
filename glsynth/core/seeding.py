"""The one place where random generators are made.

Every random function takes an explicit ``numpy.random.Generator``. Generators come from
``SeedSequence([root_seed, environment, stream, item])`` so that any single item (an environment's
geometry, one camera, one damage texture) is reproducible on its own, whatever else was drawn.
"""

from enum import IntEnum

import numpy as np


class Stream(IntEnum):
    GEOMETRY = 0
    MATERIALS = 1
    DAMAGE = 2
    CAMERAS = 3
    PLATES = 4
    DAMAGE_BANK = 5
    """Damage textures of the bank: shared by all environments of a root seed (env = 0)."""


def make_rng(root_seed: int, env: int, stream: Stream, item: int = 0) -> np.random.Generator:
    """Generator for one (root seed, environment, stream, item); all four must be ints >= 0."""
    for name, value in (("root_seed", root_seed), ("env", env), ("item", item)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
            raise ValueError(f"{name} = {value!r}: must be an integer >= 0")
    if not isinstance(stream, Stream):
        raise TypeError(f"stream = {stream!r}: must be a glsynth.core.seeding.Stream member")
    seq = np.random.SeedSequence([int(root_seed), int(env), int(stream), int(item)])
    return np.random.Generator(np.random.PCG64(seq))
