"""How a depth map is read as surfaces: the steepest view of a surface that still counts as
one. Crack widths (glsynth.assess.cracks), surface areas (glsynth.data.statistics) and the
cameras that look at member faces (glsynth.core.config) share it."""

import math

MAX_SLANT_DEG = 85.0
"""A surface seen more obliquely than this, from its normal, is taken as seen edge-on: its
depth changes by more than tan(85 deg) = 11.4 pixel footprints per pixel, so a larger step in
a depth map is a silhouette (two surfaces) or quantisation, and no image of such a face is
left to inspect."""

MAX_AREA_FACTOR = 1.0 / math.cos(math.radians(MAX_SLANT_DEG))
"""The most a pixel of a surface covers, in units of its fronto-parallel footprint (11.5)."""
