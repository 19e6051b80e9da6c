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
    TRAINING = 6
    """Network training (env = 0): validation split, initial weights, shuffles, flips."""
    LIGHTING = 7
    """The sun and the sky of an environment."""
    CYCLES = 8
    """Cycles' sampling seed of one view (item = camera index; plates: 1,000,000 + N)."""
    CRACKS = 9
    """A damaged column's drift and crack network under [damage] model = "mechanics" (item =
    the part's index in the environment's part list)."""
    DETAIL = 10
    """A concrete part's detail seed (glsynth.appearance.dressing; item = the part's index in
    the environment's part list)."""
    WEATHERING = 11
    """A concrete part's weathered albedo (glsynth.appearance.dressing; item = the part's
    index in the environment's part list)."""
    SENSOR = 12
    """The photograph's draws of one view (glsynth.render.camera_model; item = the camera
    index, a flight's frame index, 0 for a camera given by hand)."""
    OTHERS = 13
    """The "others" of one viaduct (glsynth.world.others: steel jackets, braces, downpipes,
    cable troughs, signs; item = the viaduct's index)."""
    WORLD = 14
    """The town around the viaducts (glsynth.world.surroundings; item = the strip's index:
    viaduct i is i, the lead-in and lead-out n and n + 1, the far hills n + 2), and the town's
    own textures (env = 0; glsynth.appearance.town_textures)."""
    SEVERE = 15
    """A severe column's damage as geometry: its crushed bands, buckled bars and broken hoops
    (glsynth.world.severe; item = the column's index in the environment's part list)."""
    LEACHATE = 16
    """Which of a member's cracks leach, and how (glsynth.appearance.crack_leachate; item =
    the part's index in the environment's part list): drawn apart from the CRACKS stream, so
    the cracks are the same with leachate or without."""
    FOOT_VIEWS = 17
    """Whether a face camera not aimed at a crack aims at a column's foot ([cameras]
    face_foot_share; item = the camera index): drawn apart from CAMERAS, so every other camera
    draws as it does without foot views."""


def _sequence(root_seed: int, env: int, stream: Stream, items: tuple[int, ...]
              ) -> np.random.SeedSequence:
    named = [("root_seed", root_seed), ("env", env)] + [("item", i) for i in items]
    for name, value in named:
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
            raise ValueError(f"{name} = {value!r}: must be an integer >= 0")
    if not isinstance(stream, Stream):
        raise TypeError(f"stream = {stream!r}: must be a glsynth.core.seeding.Stream member")
    return np.random.SeedSequence([int(root_seed), int(env), int(stream), *map(int, items)])


def make_rng(root_seed: int, env: int, stream: Stream, item: int = 0) -> np.random.Generator:
    """Generator for one (root seed, environment, stream, item); all four must be ints >= 0."""
    return np.random.Generator(np.random.PCG64(_sequence(root_seed, env, stream, (item,))))


def child_rng(rng: np.random.Generator) -> np.random.Generator:
    """A generator spawned from ``rng``'s seed sequence, independent of it: drawing from the
    child leaves ``rng``'s own draws as they were, so a feature added on its own stream keeps
    everything else ``rng`` makes (each call spawns the next child, in call order)."""
    return np.random.Generator(np.random.PCG64(rng.bit_generator.seed_seq.spawn(1)[0]))


def make_seed(root_seed: int, env: int, stream: Stream, *items: int) -> int:
    """A 63-bit integer seed from the same sequences, for libraries that take an integer
    (torch generators, DistributedSampler)."""
    state = _sequence(root_seed, env, stream, items).generate_state(2, np.uint32)
    return (int(state[0]) << 31) ^ int(state[1])
