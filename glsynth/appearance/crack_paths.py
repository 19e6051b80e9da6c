"""The path and width of one crack along its length: a self-affine centreline and a width that
fluctuates round the mechanics' width and closes at the tips (issue 39; docs/design.md,
"Crack paths", gives the rules and their sources).

The roughness is fractional-Brownian: the lateral offset between two points a distance x apart
along the crack has variance S(x) = (A xi)^2 (x / xi)^(2H), with H = 0.8 below the coarse
aggregate's size xi (the path wanders within the paste and along grain boundaries) and
H = 0.5 above it (it deflects round whole grains, one independent step per grain). Random
midpoint displacement builds it: the middle of an interval of length x moves by a draw of
variance S(x / 2) - S(x) / 4, the variance of an fBm's midpoint about its chord. The
generators place the vertices this way down to a few centimetres; shaders/cracks.glsl carries
the same refinement on inside each segment down to the pixel, with the same constants, which
are written here once and compiled into the shaders as macros (glsynth.render.gl.programs).
"""

import math

import numpy as np

WIDTH_COV = 0.4
"""Coefficient of variation of a crack's width along its length (log-normal)."""
TIP_SHARE = 0.15
"""The share of a crack's length at each tip over which its width closes to zero."""
TIP_MAX_M = 0.1
"""... but at most this far from the tip."""


SHADER_CONSTANTS: dict[str, float | int] = {
    "CRACK_AGGREGATE_M": 0.016,  # xi: the coarse aggregate's size, where H changes
    "CRACK_ROUGHNESS": 0.25,  # A: the offset's standard deviation over xi, a share of xi
    "CRACK_HURST_FINE": 0.8,
    "CRACK_HURST_COARSE": 0.5,
    "CRACK_REACH_M": 0.03,  # the most a path strays from its segment (the shader's margin)
    "CRACK_LEVELS": 12,  # halvings at most in the shader: 7 cm segments to 17 um
    "CRACK_LIP_M": 3e-4,  # a rough crack's lips: at most this wide each side,
    "CRACK_LIP_SHARE": 0.35,  # darkened by this share of the interior's darkening
    # Chips: small spalls broken out of a rough crack's lips, one chance per side in each
    # cell along the crack (CELL_WIDTHS widths + CELL_M long), a half-ellipse at most half the
    # cell long and MIN..MAX widths deep, darkened by SHARE of the interior's darkening;
    # surface like the lips, so they label nothing (docs/design.md, "Chipped lips").
    "CRACK_CHIP_CELL_WIDTHS": 3.0,
    "CRACK_CHIP_CELL_M": 3e-4,
    "CRACK_CHIP_CHANCE": 0.3,
    "CRACK_CHIP_MIN": 0.3,
    "CRACK_CHIP_MAX": 1.2,
    "CRACK_CHIP_SHARE": 0.6,
}
"""The crack paths' constants, shared with shaders/cracks.glsl (each a #define there)."""


# structure and midpoint_sd take an array (the shader's twin below, per pixel) or one float
# (the generators, per level of a crack: 800,000 calls in the test suite). A float is worked
# in Python's math, 18x faster than through 0-d arrays and with their bits: arithmetic on 0-d
# arrays gives numpy scalars, whose power is the C library's pow, as math.pow is (np.power,
# the ufunc, is vectorised and differs in the last bit for 3 % of lengths on a CPU with
# AVX-512), and a square root is correctly rounded everywhere. An array's power is the
# ufunc's, as it always was.


def structure(x: np.ndarray | float) -> np.ndarray | float:
    """S(x): the variance (m^2) of the lateral offset between two points x metres apart."""
    c = SHADER_CONSTANTS
    xi, amplitude = c["CRACK_AGGREGATE_M"], c["CRACK_ROUGHNESS"]
    fine, coarse = c["CRACK_HURST_FINE"], c["CRACK_HURST_COARSE"]
    if isinstance(x, float):
        return (amplitude * xi) ** 2 * math.pow(x / xi, 2 * (fine if x < xi else coarse))
    x = np.asarray(x, np.float64)
    return (amplitude * xi) ** 2 * (x / xi) ** (2 * np.where(x < xi, fine, coarse))


def midpoint_sd(interval_m: np.ndarray | float) -> np.ndarray | float:
    """The standard deviation of the midpoint's draw when an interval of this length is split."""
    if isinstance(interval_m, float):
        x, sqrt, maximum = interval_m, math.sqrt, max
    else:
        x, sqrt, maximum = np.asarray(interval_m, np.float64), np.sqrt, np.maximum
    return sqrt(maximum(structure(x / 2) - structure(x) / 4, 0.0))


def levels(length_m: float, step_m: float) -> int:
    """How many halvings bring a crack of this length to steps of about ``step_m``."""
    return max(1, int(np.rint(np.log2(max(length_m, step_m) / step_m))))


def lateral_offsets(length_m: float, n_levels: int, rng: np.random.Generator) -> np.ndarray:
    """(2^n_levels + 1,) offsets across a crack of this length at equally spaced points, 0 at
    both ends (the mechanics fix where a crack runs; the roughness is how it wanders about
    that)."""
    offsets = np.zeros(2 ** n_levels + 1)
    draws = rng.standard_normal(2 ** n_levels - 1)  # as drawn level by level: 1, 2, 4, ...
    for level in range(n_levels):
        step = 2 ** (n_levels - level)  # between the points placed so far
        placed = offsets[::step]
        middle = (placed[:-1] + placed[1:]) / 2
        spread = midpoint_sd(length_m / 2 ** level)
        offsets[step // 2::step] = middle + spread * draws[2 ** level - 1:2 ** (level + 1) - 1]
    return offsets


def width_profile(arc_m: np.ndarray, widths_m: np.ndarray, rng: np.random.Generator,
                  first_is_tip: bool = True) -> np.ndarray:
    """The widths at a crack's vertices (arc length ``arc_m`` from its first, increasing):
    the mechanics' ``widths_m`` times a log-normal factor of mean 1 (WIDTH_COV), closing to 0 at
    its tips as the square root of the distance to the tip (the opening near a crack's tip,
    Irwin's near-tip field of linear-elastic fracture mechanics). The last vertex is a tip; the
    first one too unless ``first_is_tip`` is false (a fork leaves its trunk open)."""
    sigma = np.sqrt(np.log1p(WIDTH_COV ** 2))
    factor = np.exp(sigma * rng.standard_normal(len(arc_m)) - sigma ** 2 / 2)
    length = float(arc_m[-1] - arc_m[0])
    tip = min(TIP_SHARE * length, TIP_MAX_M) if first_is_tip else min(2 * TIP_SHARE * length,
                                                                       TIP_MAX_M)
    to_tip = arc_m[-1] - arc_m
    if first_is_tip:
        to_tip = np.minimum(arc_m - arc_m[0], to_tip)
    return widths_m * factor * np.sqrt(np.clip(to_tip / tip, 0.0, 1.0))


def path(lo: float, hi: float, z_at: float, angle_deg: float, step_m: float,
         rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(s, z, arc) of a rough crack on the unrolled surface: its chord runs from s = lo to
    s = hi rising at ``angle_deg`` from the s axis, its vertices about ``step_m`` apart along
    the chord, each moved across the chord by lateral_offsets; shifted so that its middle vertex
    sits at z = z_at. ``arc``: the distance along the chord from the first vertex."""
    slope = np.radians(angle_deg)
    length = abs(hi - lo) / np.cos(slope)
    n = levels(length, step_m)
    arc = np.linspace(0.0, length, 2 ** n + 1)
    offset = lateral_offsets(length, n, rng)
    sense = 1.0 if hi >= lo else -1.0
    s = lo + sense * (arc * np.cos(slope) - offset * np.sin(slope))
    z = arc * np.sin(slope) + offset * np.cos(slope)
    return s, z + z_at - z[len(z) // 2], arc


# --- the shader's refinement below the vertices, in numpy ---------------------------------------
# The meta JSON lists the cracks a view labels by sampling each segment's path and looking for
# labels beside it (glsynth.data.visible_cracks); on a rough crack the labels follow the path
# the shader draws, up to CRACK_REACH_M off the chord, so the samples must follow it too. These
# functions are shaders/cracks.glsl's crack_hash, crack_draw and crack_offset, operation for
# operation (tests/test_crack_shader.py runs both on the same inputs).
_GOLDEN, _MIX = 0x9E3779B9, 0x85EBCA6B
"""crack_draw's multipliers of the level and the interval's index."""


def crack_hash(x: np.ndarray) -> np.ndarray:
    """lowbias32 (Wellons), the shader's crack_hash: uint32 in, uint32 out."""
    x = np.asarray(x, np.uint32).copy()
    x ^= x >> np.uint32(16)
    x *= np.uint32(0x7FEB352D)
    x ^= x >> np.uint32(15)
    x *= np.uint32(0x846CA68B)
    x ^= x >> np.uint32(16)
    return x


def segment_seeds(widths_m: np.ndarray) -> np.ndarray:
    """(N,) uint32: the seed of each segment's path, hashed from the bits of its end widths as
    the renderer uploads them (float32 millimetres; glsynth.render.cracks_index)."""
    bits = (np.asarray(widths_m, np.float64) * 1000.0).astype(np.float32).view(np.uint32)
    return crack_hash(bits[:, 0] ^ crack_hash(bits[:, 1]))


def _draw(seed: np.ndarray, level: int, index: np.ndarray) -> np.ndarray:
    """The shader's crack_draw: mean 0, variance 1, keyed by seed, level and index."""
    key = (seed.astype(np.uint64) + level * _GOLDEN + index.astype(np.uint64) * _MIX)
    h1 = crack_hash((key & 0xFFFFFFFF).astype(np.uint32))
    h2 = crack_hash(h1)
    root6 = np.sqrt(6.0)
    return ((h1 >> np.uint32(8)).astype(np.float64) + (h2 >> np.uint32(8)) + 1.0) \
        / 16777216.0 * root6 - root6


def shader_offsets(t: np.ndarray, length_m: np.ndarray, seed: np.ndarray,
                   finest_m: np.ndarray) -> np.ndarray:
    """The lateral offsets (m) of segments' paths at chord parameters ``t``, as the shader's
    crack_offset draws them for pixels whose footprint is ``finest_m``: random midpoint
    displacement from 0 at both ends, halving while the new points lie at least ``finest_m``
    apart (at most CRACK_LEVELS times), then linear; clamped to CRACK_REACH_M. All arguments
    broadcast to one shape."""
    c = SHADER_CONSTANTS
    t, length, seed, finest = np.broadcast_arrays(np.asarray(t, np.float64), length_m,
                                                  np.asarray(seed, np.uint32), finest_m)
    finest = np.maximum(finest, length * 2.0 ** -c["CRACK_LEVELS"])
    n_levels = np.floor(np.log2(length / finest))
    lo, hi = np.zeros(t.shape), np.zeros(t.shape)
    a, b = np.zeros(t.shape), np.ones(t.shape)
    interval, index = length.astype(np.float64), np.zeros(t.shape, np.uint64)
    for level in range(int(c["CRACK_LEVELS"])):
        active = level < n_levels
        if not active.any():
            break
        mid = (lo + hi) / 2 + midpoint_sd(interval) * _draw(seed, level, index)
        right = active & (t >= (a + b) / 2)
        left = active & ~right
        lo, hi = np.where(right, mid, lo), np.where(left, mid, hi)
        a, b = np.where(right, (a + b) / 2, a), np.where(left, (a + b) / 2, b)
        index = np.where(active, 2 * index + right, index)
        interval = np.where(active, interval / 2, interval)
    reach = c["CRACK_REACH_M"]
    return np.clip(lo + (hi - lo) * (t - a) / (b - a), -reach, reach)


STRAY_EXACT_LEVELS = 5
"""path_bounds draws a path's first this many levels (31 midpoints); below them it adds the
most the rest can add."""
_DRAW_BOUND = math.sqrt(6.0) * (1.0 + 1e-6)
"""|crack_draw| is at most this: the sum of two uniforms, scaled to variance 1 (sqrt(6) at
the ends, and the shader's float32 constant lies one ulp above it)."""


def path_bounds(length_m: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """For each of N segments' paths (shader_offsets): the most (m) it strays from its chord
    at any footprint, (N,).

    A bound: the largest |offset| of its midpoints on the first STRAY_EXACT_LEVELS levels,
    drawn as the shader draws them, plus, for each deeper level, the most one draw can move a
    point (its spread times _DRAW_BOUND); at most CRACK_REACH_M. A path is linear between its
    midpoints, and a midpoint lies between its interval's ends moved by one draw, so no point
    of it strays further (the shader's float32 sums differ from these by under 0.1 um:
    tests/test_crack_shader.py). The cell lists of a rough network reach as far as its
    segments' own paths do (glsynth.render.cracks_index), not the shader's 3 cm margin for
    all: a 4 cm segment strays about 4 mm."""
    c = SHADER_CONSTANTS
    length = np.asarray(length_m, np.float64)
    seed = np.asarray(seed, np.uint32)[:, None]
    nodes = np.zeros((len(length), 2))  # the ends, then each level's midpoints between them
    stray = np.zeros(len(length))
    for level in range(STRAY_EXACT_LEVELS):
        index = np.arange(2 ** level, dtype=np.uint64)[None, :]
        middle = (nodes[:, :-1] + nodes[:, 1:]) / 2 \
            + midpoint_sd(length / 2 ** level)[:, None] * _draw(seed, level, index)
        stray = np.maximum(stray, np.abs(middle).max(1))
        merged = np.empty((len(length), 2 * nodes.shape[1] - 1))
        merged[:, 0::2], merged[:, 1::2] = nodes, middle
        nodes = merged
    for level in range(STRAY_EXACT_LEVELS, int(c["CRACK_LEVELS"])):
        stray = stray + _DRAW_BOUND * midpoint_sd(length / 2 ** level)
    return np.minimum(stray, c["CRACK_REACH_M"])
