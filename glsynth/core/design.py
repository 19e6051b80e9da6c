"""The Japanese standard design of Tokaido Shinkansen RC viaducts: pure numbers, no randomness.

Table 3 of the paper gives column and intermediate-beam cross-sections by viaduct height and by
trajectory (straight: radius > 5000 m; curved otherwise). Everything else about the superstructure
is sparse in the literature (paper Section 3.1); those dimensions live in ``StandardDesign`` with
documented defaults, and can be changed in the ``[design]`` config section.

Conventions (docs/design.md, "Reading the paper"):
- Heights in [5.0, 5.5] m use the first row; row upper bounds are inclusive (5.5 < H <= 7 ...).
- A radius of exactly 5000 m is *curved*: the issue defines straight as radius > 5000 m.
- Column sections are (along track, across track): curved viaducts are stiffer transversely, so
  their larger dimension is across the track. Beam sections are (depth, width).
"""

import bisect
import dataclasses
import math
from dataclasses import dataclass

from glsynth.core.checks import check_number, fail

HEIGHT_MIN_M = 5.0
HEIGHT_MAX_M = 14.0
STRAIGHT_RADIUS_M = 5000.0

# Upper bounds of the Table 3 rows (inclusive), and the rows themselves in cm.
_ROW_UPPER_M = (7.0, 8.5, 10.0, 12.0, 14.0)
_COLUMN_STRAIGHT_CM = ((60, 60), (70, 70), (80, 80), (70, 70), (80, 80))
_COLUMN_CURVED_CM = ((60, 70), (70, 80), (80, 90), (70, 85), (80, 95))
_BEAM_CM = (None, None, None, (80, 60), (80, 60))  # same for straight and curved


@dataclass(frozen=True)
class SectionChoice:
    """Table 3 cross-sections of one viaduct."""

    row: int
    straight: bool
    column_cm: tuple[int, int]
    """(along track, across track)."""
    intermediate_beam_cm: tuple[int, int] | None
    """(depth, width), or None where Table 3 has no intermediate beams."""


def is_straight(radius_m: float) -> bool:
    """Straight trajectory: radius > 5000 m (math.inf for a straight track)."""
    if math.isnan(radius_m) or radius_m <= 0:
        raise ValueError(f"radius_m = {radius_m!r}: must be > 0 (math.inf for straight track)")
    return radius_m > STRAIGHT_RADIUS_M


def table3_row(height_m: float) -> int:
    """Row of Table 3 for a viaduct height; heights in [5.0, 5.5] use the first row."""
    if not (HEIGHT_MIN_M <= height_m <= HEIGHT_MAX_M):
        raise ValueError(
            f"height_m = {height_m!r}: Table 3/4 cover {HEIGHT_MIN_M} <= H <= {HEIGHT_MAX_M} m"
        )
    return bisect.bisect_left(_ROW_UPPER_M, height_m)


def cross_sections(height_m: float, radius_m: float) -> SectionChoice:
    row = table3_row(height_m)
    straight = is_straight(radius_m)
    column = (_COLUMN_STRAIGHT_CM if straight else _COLUMN_CURVED_CM)[row]
    return SectionChoice(row, straight, column, _BEAM_CM[row])


@dataclass(frozen=True)
class StandardDesign:
    """Dimensions of one viaduct in metres. Span layout from the paper; the rest assumed."""

    span_m: float = 6.0
    """Central spans (paper: three of 6 m)."""
    n_spans: int = 3
    cantilever_m: float = 3.0
    """Cantilever end spans (paper: 3 m); 3 x 6 + 2 x 3 = 24 m."""
    column_spacing_m: float = 6.0
    """Centre distance between the two columns of a row, across the track (assumed)."""
    deck_width_m: float = 11.0
    slab_thickness_m: float = 0.30
    girder_width_m: float = 1.0
    """Longitudinal beams under the slab along both column lines."""
    girder_depth_m: float = 0.9
    crossbeam_width_m: float = 0.9
    """Transverse beams over each column row (along-track width)."""
    embed_m: float = 0.05
    """How far columns and cross beams reach into the member above, so that a slope of up to
    2 % never opens a visible gap at a horizontal joint."""
    track_spacing_m: float = 4.2
    """Distance between the centres of the two tracks (Shinkansen)."""
    gauge_m: float = 1.435
    rail_height_m: float = 0.174
    rail_head_width_m: float = 0.065
    rail_foot_width_m: float = 0.145
    rail_web_width_m: float = 0.0165
    sleeper_length_m: float = 2.4
    sleeper_width_m: float = 0.25
    sleeper_height_m: float = 0.18
    sleeper_spacing_m: float = 0.6
    fence_height_m: float = 1.5
    fence_thickness_m: float = 0.1
    pole_radius_m: float = 0.2
    pole_height_m: float = 8.5
    """Catenary masts, one pair per viaduct at its centre, with a portal beam at the top."""
    portal_beam_size_m: float = 0.3
    contact_wire_height_m: float = 5.0
    """Above the rail top."""
    messenger_wire_height_m: float = 6.4
    wire_radius_m: float = 0.012

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name == "n_spans":
                check_number("design", f.name, value, 1, 20, integer=True)
            else:
                check_number("design", f.name, value, 0.0, 100.0, lo_open=True)
        if self.column_spacing_m >= self.deck_width_m:
            fail("design", "column_spacing_m", self.column_spacing_m,
                 f"smaller than deck_width_m = {self.deck_width_m}")

    @property
    def length_m(self) -> float:
        return self.n_spans * self.span_m + 2 * self.cantilever_m

    @property
    def column_rows_s(self) -> tuple[float, ...]:
        """Arc-length positions of the column rows from the start of a viaduct."""
        return tuple(self.cantilever_m + k * self.span_m for k in range(self.n_spans + 1))
