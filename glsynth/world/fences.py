"""See-through deck-edge fences ([environment] fences = "open"): a railing of posts, a bottom
and a top rail and vertical bars, merged into one mesh per fence, so that what lies behind it
shows through the openings between the bars (docs/design.md, "Open fences").

The railing fills the band of the solid fence it replaces: across [lo, hi] from the track's
centre line, from the deck top up to the fence height. Rails are swept along the deck's curve;
posts and bars are upright boxes placed along it (as sleepers are), each reaching a little into
both rails so that the deck's slope never opens a gap at a joint. Regular: no randomness.
"""

from collections.abc import Callable

import numpy as np
import trimesh

from glsynth.core.design import StandardDesign
from glsynth.world import meshes
from glsynth.world.trajectory import Trajectory

POST_SPACING_M = 2.0
"""Largest distance between neighbouring posts (a post stands at each end of a viaduct)."""
POST_WIDTH_M = 0.08
"""Along the track; across, a post is as thick as the fence."""
BAR_SPACING_M = 0.15
"""Centre to centre of the vertical bars: openings of 12.5 cm between 2.5 cm bars."""
BAR_WIDTH_M = 0.025
BOTTOM_RAIL_M = 0.15
"""Height of the bottom rail (a kerb on the deck edge)."""
TOP_RAIL_M = 0.08
"""Depth of the top rail (hand rail)."""
OVERLAP_M = 0.01
"""How far posts and bars reach into the rails."""


def _uprights(traj: Trajectory, s: np.ndarray, u: float, z0: float, z1: float,
              width: float, thickness: float) -> trimesh.Trimesh:
    """Upright boxes at arc lengths ``s``, centred at lateral offset ``u`` on the deck,
    from z0 to z1 above the deck top, ``width`` along the track, ``thickness`` across."""
    points, _, normal = traj.frame(s)
    heading = traj.heading(s)
    centre = points + u * normal
    centre[:, 2] += (z0 + z1) / 2
    poses = np.stack([meshes.pose(h, c) for h, c in zip(heading, centre)])
    return meshes.boxes((width, thickness, z1 - z0), poses)


def _positions(s0: float, s1: float) -> tuple[np.ndarray, np.ndarray]:
    """Arc lengths of the posts and of the bars between them, for a fence from s0 to s1."""
    inner0, inner1 = s0 + POST_WIDTH_M / 2, s1 - POST_WIDTH_M / 2
    n_gaps = max(1, int(np.ceil((inner1 - inner0) / POST_SPACING_M - 1e-9)))
    posts = np.linspace(inner0, inner1, n_gaps + 1)
    bars = []
    for a, b in zip(posts[:-1], posts[1:]):
        # Bars evenly spread between two posts, no opening wider than BAR_SPACING_M allows.
        clear = b - a - POST_WIDTH_M
        n = max(1, int(np.floor(clear / BAR_SPACING_M)))
        bars.append(a + POST_WIDTH_M / 2 + clear * (np.arange(n) + 0.5) / n)
    return posts, np.concatenate(bars)


def open_fence(traj: Trajectory, d: StandardDesign, s: np.ndarray, lo: float, hi: float,
               deck_sweep: Callable[[np.ndarray, np.ndarray], trimesh.Trimesh]
               ) -> trimesh.Trimesh:
    """The railing over arc lengths ``s`` (the viaduct's sweep samples) in the band [lo, hi]
    across the deck, as one mesh in world coordinates; ``deck_sweep`` sweeps a profile along
    the deck top (the environment's own)."""
    height, thickness = d.fence_height_m, hi - lo
    u = (lo + hi) / 2
    posts, bars = _positions(float(s[0]), float(s[-1]))
    low, high = BOTTOM_RAIL_M - OVERLAP_M, height - TOP_RAIL_M + OVERLAP_M
    pieces = [deck_sweep(s, meshes.rectangle(lo, hi, 0.0, BOTTOM_RAIL_M)),
              deck_sweep(s, meshes.rectangle(lo, hi, height - TOP_RAIL_M, height)),
              _uprights(traj, posts, u, low, high, POST_WIDTH_M, thickness),
              _uprights(traj, bars, u, low, high, BAR_WIDTH_M, BAR_WIDTH_M)]
    return trimesh.util.concatenate(pieces)
