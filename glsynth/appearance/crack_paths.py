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
}
"""The crack paths' constants, shared with shaders/cracks.glsl (each a #define there)."""


def structure(x: np.ndarray | float) -> np.ndarray:
    """S(x): the variance (m^2) of the lateral offset between two points x metres apart."""
    c = SHADER_CONSTANTS
    xi, amplitude = c["CRACK_AGGREGATE_M"], c["CRACK_ROUGHNESS"]
    x = np.asarray(x, np.float64)
    hurst = np.where(x < xi, c["CRACK_HURST_FINE"], c["CRACK_HURST_COARSE"])
    return (amplitude * xi) ** 2 * (x / xi) ** (2 * hurst)


def midpoint_sd(interval_m: np.ndarray | float) -> np.ndarray:
    """The standard deviation of the midpoint's draw when an interval of this length is split."""
    x = np.asarray(interval_m, np.float64)
    return np.sqrt(np.maximum(structure(x / 2) - structure(x) / 4, 0.0))


def levels(length_m: float, step_m: float) -> int:
    """How many halvings bring a crack of this length to steps of about ``step_m``."""
    return max(1, int(np.rint(np.log2(max(length_m, step_m) / step_m))))


def lateral_offsets(length_m: float, n_levels: int, rng: np.random.Generator) -> np.ndarray:
    """(2^n_levels + 1,) offsets across a crack of this length at equally spaced points, 0 at
    both ends (the mechanics fix where a crack runs; the roughness is how it wanders about
    that)."""
    offsets = np.zeros(2)
    for level in range(n_levels):
        interval = length_m / 2 ** level
        middle = (offsets[:-1] + offsets[1:]) / 2
        middle = middle + midpoint_sd(interval) * rng.standard_normal(len(middle))
        out = np.empty(2 * len(offsets) - 1)
        out[0::2], out[1::2] = offsets, middle
        offsets = out
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
