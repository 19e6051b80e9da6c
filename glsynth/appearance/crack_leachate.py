"""What runs out of a crack: which cracks of a network leach, and how (issue 39). Water that
seeps through a crack dissolves calcium hydroxide from the paste and leaves it as white calcite
where it evaporates (efflorescence); where it reaches a corroding bar it carries iron oxides
(rust). Either runs down the face below the crack, and the concrete beside a wet crack stays
damp and dark. Colour only: the renderer draws it (shaders/crack_leachate.glsl); no label,
width or depth changes. docs/design.md, "Cracks", gives the rules and their sources.
"""

import numpy as np

from glsynth.appearance.cracks import CrackNetwork

NONE, EFFLORESCENCE, RUST = 0, 1, 2
"""A crack's leachate kind, column 0 of CrackNetwork.leachate."""
LEACHATE_FIELDS = ("kind", "strength", "streak_m", "damp_m")
"""CrackNetwork.leachate's columns: the kind, how strongly the deposit covers the concrete at
the crack (0-1), how far it runs down the face at most (m), how far the damp band reaches
either side of the crack (m)."""
STRENGTH = (0.45, 0.9)
STREAK_M = (0.05, 0.5)
"""A leachate runs some centimetres to decimetres (log-uniform)."""
DAMP_M = (0.004, 0.025)
"""The damp band reaches a few millimetres to centimetres either side (log-uniform)."""
RUST_SHARE = (0.1, 0.7)
"""The chance that a leaching crack carries rust, not efflorescence: the first on a hairline
crack, rising linearly with its widest width to the second at RUST_WIDTH_MM and wider (a wider
crack lets water and chlorides reach the bar sooner)."""
RUST_WIDTH_MM = 1.0


def with_leachate(net: CrackNetwork, share: float, rng: np.random.Generator) -> CrackNetwork:
    """``net`` with each crack leaching with chance ``share``; the same draws per crack
    whatever the share, so a larger share keeps the cracks a smaller one chose."""
    k = len(net.kinds)
    leaches = rng.random(k) < share
    widest_mm = np.zeros(k)
    np.maximum.at(widest_mm, net.crack, net.widths_m.max(axis=1) * 1e3)
    rust_chance = RUST_SHARE[0] + (RUST_SHARE[1] - RUST_SHARE[0]) * np.minimum(
        widest_mm / RUST_WIDTH_MM, 1.0)
    kind = np.where(rng.random(k) < rust_chance, RUST, EFFLORESCENCE)
    strength = rng.uniform(*STRENGTH, k)
    streak = np.exp(rng.uniform(*np.log(STREAK_M), k))
    damp = np.exp(rng.uniform(*np.log(DAMP_M), k))
    table = np.stack([np.where(leaches, kind, NONE), strength, streak, damp], axis=1)
    return CrackNetwork(net.points, net.widths_m, net.crack, net.kinds, net.rough,
                        table.astype(np.float64))

SHADER_CONSTANTS: dict[str, float] = {
    "LEACH_SPREAD0_M": 0.004,  # a run's half width beyond a crack's end at the crack (m),
    "LEACH_SPREAD": 0.12,  # growing by this much per metre it has run down
    "LEACH_PATH_M": 0.005,  # the crack's path is followed to this scale (or the pixel's)
}
"""The runs' shape, shared with shaders/crack_leachate.glsl (each a #define there) and the
packing's margins (glsynth.render.leachate_index)."""


def reach_m(streak_m: np.ndarray | float) -> np.ndarray:
    """How far beside its crack's ends a run of this length spreads at most (m)."""
    c = SHADER_CONSTANTS
    return c["LEACH_SPREAD0_M"] + c["LEACH_SPREAD"] * np.asarray(streak_m, np.float64)
