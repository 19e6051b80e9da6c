"""A crack network packed for the fragment shader (shaders/cracks.glsl): its segments, and a
uniform 3D grid over them so that a fragment tests only the segments that can reach it.

The grid covers the network's box in the mesh frame, grown by half the widest width and two
cell edges on every side. Its cells are cubes of edge ``cell_m``: 5 cm, or larger where the
box would need more than 2^20 cells (the edge then grows by 25 % steps until it fits). The
labelling and coverage rules need cracks up to half a pixel footprint beyond their edge
(docs/design.md, "Cracks"). A cell lists every segment whose centreline comes within the
segment's own reach of the cell's centre (list_reach), so that a fragment anywhere in the cell
finds in its list every crack whose edge lies within ``footprint_m`` of it:
- straight networks: half the segment's widest width plus two cell edges, ``footprint_m`` one
  cell edge (any point of a cell lies within 0.87 cell edges of its centre);
- rough networks: 0.87 cell edges plus how far the crack's edge may lie from its chord: its
  path's stray (crack_paths.path_bounds, a few millimetres for a 4 cm segment), then its
  chipped lips, up to (0.5 + CRACK_CHIP_MAX) widths and CRACK_LIP_M, plus ``footprint_m``
  (ROUGH_FOOTPRINT_M). The shader measures a pixel to the piece of the path beside it
  (crack_piece_distance2), so nothing of a crack lies further from the path than its edge
  (where the path is clamped at CRACK_REACH_M, the piece is flat there). A
  pixel walks 40 % fewer entries than under the rule of straight networks with the shader's
  3 cm margin for every path, which rough networks used before.
A fragment whose half footprint (half of |dp/dx| + |dp/dy|) is at most ``footprint_m`` reads
its own cell alone; one whose half footprint is larger also reads the cells within the rest of
it, at most one more each way (crack_box in shaders/cracks.glsl). That box reaches every point
within the rest of the footprint. The rules then hold exactly while |dp/dx| + |dp/dy| is at
most 2 (``footprint_m`` + one cell edge): 20 cm for a straight network, 14 cm for a rough one
(square pixels of 7 cm: a 1920-pixel-wide view through a 36 mm lens on the 36 mm sensor, 130 m
away). On a rough network, one caveat: the shader draws the rough paths of the two segments
nearest a pixel by their chords among the listed ones within CRACK_REACH_M of their edge and
half footprint (crack_walk): the lists decide which compete, so where three or more paths
meet, the one left out may differ from a search of every segment's.
Beyond the range, a pixel may miss a crack further than the cells it reads: its darkening
there is below w / 7 cm, but its label is lost (docs/results.md, round nineteen: edge-on
pixels). The cost's worst case is the longest cell list times 27 cells (a far fragment), or
one list for every fragment nearer: ``CrackIndex.longest`` reports it.

Every texture is 4096 texels wide (ROW), filled row by row; the shader finds an entry's texel
by a mask and a shift of its index (CRACK_ROW_BITS).

Precision: the segments' end points are stored relative to the grid's lower corner (subtracted
in float64, then rounded to float32), and the vertex shader subtracts the same float32 corner
from each vertex (shaders/mesh.vert), so the shader computes distances between small numbers.
A girder's mesh frame is the world frame: 250 m from its origin a float32 coordinate is good
to 15 um (half its ulp), and interpolating it and differencing it across a pixel lose as much
again, as much as a fifth of the thinnest crack's width (0.05 mm) and, at close range, much
of a pixel's footprint. Relative to the corner only the vertices' own rounding (<= 15 um at
250 m, the same for the drawn surface) remains.
"""

import zlib
from dataclasses import dataclass

import numpy as np

from glsynth.appearance.crack_paths import SHADER_CONSTANTS, path_bounds, segment_seeds
from glsynth.appearance.cracks import CrackNetwork
from glsynth.core.geometry import segment_distance_axes

CELL_M = 0.05
"""The grid's smallest cell edge."""
HALF_DIAGONAL = 0.8661
"""The most any point of a cell lies from its centre, in cell edges (sqrt(3) / 2 rounded up:
3.7 um to spare at 5 cm for the float32 positions)."""
ROUGH_FOOTPRINT_M = 0.02
"""The half footprint up to which a fragment of a rough network reads its own cell alone: the
close views' pixels (under a millimetre) with room to spare, and lists about half as long as a
whole cell edge's (a view's label pass walks every entry of its pixels' lists)."""
MAX_CELLS = 1 << 20
BATCH = 1 << 16
"""The most (cell, segment) pairs tested at once: their temporaries (0.5 MB each) stay in
the cache (docs/design.md, "Packing", gives the speed-up)."""
ROW = 4096
"""Texels a row of every crack texture: a power of two (CRACK_ROW_BITS, the shader's shift,
in glsynth.render.gl.programs)."""
CRACK_CONTRAST = (0.5, 0.9)
"""The range of the share of the surface's reflected light that a crack's interior takes away,
one value per crack network (a member's cracks; crack_contrast): a crack is a cavity much
deeper than wide, which traps most of the light that enters it (an effective albedo of 10 %
of the surface's for a clean, deep opening), but dust, fines and efflorescence settle in
cracks, more in some members' than in others', and give some of it back (at the range's
low end, half)."""


def crack_contrast(network: CrackNetwork) -> float:
    """A network's share in CRACK_CONTRAST's range, from a hash (CRC-32) of its widths (as
    little-endian float64, -0 as 0): drawn from the network itself, with no generator of its
    own that would move any other draw (a change to how widths are drawn draws it anew); GL
    and the Cycles twin read the same value, from the whole network."""
    low, high = CRACK_CONTRAST
    widths = np.ascontiguousarray(network.widths_m, "<f8") + 0.0
    return low + (high - low) * (zlib.crc32(widths.tobytes()) / 2**32)


@dataclass(frozen=True, eq=False)
class CrackIndex:
    """A network's segments and grid, as the shader reads them (rows of ROW texels)."""

    segments: np.ndarray
    """(rows, ROW, 4) float32: texel 2i holds segment i's first end point (mesh frame, m,
    relative to ``origin``) and its width there (mm), texel 2i + 1 the second."""
    cells: np.ndarray
    """(rows, ROW, 2) int32: per cell (x fastest, then y, then z), its first entry in
    ``entries`` and its number of entries."""
    entries: np.ndarray
    """(rows, ROW) int32: segment ids, cell after cell."""
    origin: np.ndarray
    """(3,) float32: the grid's lower corner in the mesh frame."""
    cell_m: float
    dims: tuple[int, int, int]
    longest: int
    """The longest cell list: the most segments one fragment tests."""
    rough: bool = False
    """The network's segments carry their paths on below their ends (CrackNetwork.rough)."""
    footprint_m: float = CELL_M
    """The half footprint up to which a fragment's own cell lists every crack it needs
    (list_reach)."""


def _rows(flat: np.ndarray) -> np.ndarray:
    """``flat`` (n, ...) padded with zeros to whole rows of ROW: (rows, ROW, ...)."""
    rows = max(1, -(-len(flat) // ROW))
    out = np.zeros((rows * ROW,) + flat.shape[1:], flat.dtype)
    out[:len(flat)] = flat
    return out.reshape((rows, ROW) + flat.shape[1:])


def _grid(points: np.ndarray, half_width: float) -> tuple[np.ndarray, float, np.ndarray]:
    """(origin, cell edge, cells along x, y, z) of the grid over ``points`` (n, 3) grown by
    ``half_width`` plus two cell edges on every side."""
    lo, hi = points.min(0), points.max(0)
    cell = CELL_M
    while True:
        origin = lo - half_width - 2 * cell
        dims = np.floor((hi + half_width + 2 * cell - origin) / cell).astype(np.int64) + 1
        if np.prod(dims) <= MAX_CELLS:
            return origin, cell, dims
        cell *= 1.25


def box_cells(first: np.ndarray, size: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """Every cell of n boxes, ``size`` (n, 3) cells from their lower corner cells ``first``
    (n, 3): the box each cell belongs to (boxes in order) and its cell indices along x, y and
    z (three arrays; x fastest within a box, then y, then z). All boxes at once, each cell's
    place in its box taken apart by its box's shape: grouping the boxes by shape cost a
    Python loop over hundreds of shapes per network."""
    count = size.prod(1)
    box = np.repeat(np.arange(len(size)), count)
    place = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
    # Each box's sides repeated to its cells (not gathered through ``box``), and the place
    # taken apart by two divisions, not three: half the time.
    nx, nxy = np.repeat(size[:, 0], count), np.repeat(size[:, 0] * size[:, 1], count)
    z = place // nxy
    place -= z * nxy
    y = place // nx
    place -= y * nx
    return box, [np.repeat(first[:, 0], count) + place, np.repeat(first[:, 1], count) + y,
                 np.repeat(first[:, 2], count) + z]


def batches(count: np.ndarray, most: int) -> list[slice]:
    """Runs of consecutive items of ``count`` (n,) cells each, at most ``most`` cells a run
    (an item of more stands alone): boxes' cells in batches of bounded temporaries."""
    ends = np.cumsum(count)
    runs: list[slice] = []
    start = 0
    while start < len(count):
        # The first item past the budget that the run's cells up to it leave.
        stop = int(np.searchsorted(ends, ends[start] - count[start] + most, side="right"))
        stop = max(stop, start + 1)
        runs.append(slice(start, stop))
        start = stop
    return runs


def _near_pairs(points: np.ndarray, reach: np.ndarray, origin: np.ndarray, cell: float,
                dims: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """Sorted keys cell id x segments + segment of every (cell, segment) pair whose cell
    centre lies within the segment's ``reach``, among the cells of the segment's box
    low..high (inclusive, clipped to the grid). Segments in batches of about BATCH pairs,
    bounding the temporaries."""
    lo = np.clip(low, 0, dims - 1)
    size = np.clip(high, 0, dims - 1) - lo + 1
    a, ab = points[:, 0], points[:, 1] - points[:, 0]
    keys = []
    for run in batches(size.prod(1), BATCH):
        box, ijk = box_cells(lo[run], size[run])
        seg = box + run.start
        gap, _ = segment_distance_axes([origin[q] + (ijk[q] + 0.5) * cell for q in range(3)],
                                       [a[seg, q] for q in range(3)],
                                       [ab[seg, q] for q in range(3)])
        near = gap <= reach[seg]
        i, j, k = (v[near] for v in ijk)
        keys.append((i + dims[0] * (j + dims[1] * k)) * len(points) + seg[near])
    return np.sort(np.concatenate(keys))


def list_reach(network: CrackNetwork, cell: float) -> tuple[np.ndarray, float]:
    """(N,) how far from a cell's centre each segment's centreline may lie and still be in the
    cell's list, and the half footprint that a fragment's own cell then serves (this module's
    docstring)."""
    half = network.widths_m.max(1) / 2
    if not network.rough:
        return half + 2 * cell, cell
    c = SHADER_CONSTANTS
    length = np.linalg.norm(network.points[:, 1] - network.points[:, 0], axis=1)
    stray = path_bounds(length, segment_seeds(network.widths_m))
    # crack_rough measures a pixel to the piece of the path it lies beside, so a pixel of half
    # footprint up to ROUGH_FOOTPRINT_M is labelled and darkened only within its edge and that
    # footprint of the path; a larger one reads the cells within the rest of its footprint
    # (crack_box).
    edge = (1 + 2 * c["CRACK_CHIP_MAX"]) * half + c["CRACK_LIP_M"]
    return HALF_DIAGONAL * cell + stray + edge + ROUGH_FOOTPRINT_M, ROUGH_FOOTPRINT_M


def pack_cracks(network: CrackNetwork) -> CrackIndex:
    """The textures and grid of ``network`` (docstring of this module)."""
    points, widths = network.points, network.widths_m
    if not len(points):
        empty = np.zeros((1, 3))
        origin, cell, dims = _grid(empty, 0.0)
        return CrackIndex(_rows(np.zeros((0, 4), np.float32)),
                          _rows(np.zeros((int(np.prod(dims)), 2), np.int32)),
                          _rows(np.zeros(0, np.int32)), origin.astype(np.float32), cell,
                          tuple(int(d) for d in dims), 0, network.rough)
    half = widths.max(1) / 2
    origin, cell, dims = _grid(points.reshape(-1, 3), float(half.max()))
    origin = origin.astype(np.float32).astype(np.float64)  # the corner the shader subtracts
    reach, footprint = list_reach(network, cell)
    low = np.floor((points.min(1) - reach[:, None] - origin) / cell).astype(np.int64)
    high = np.floor((points.max(1) + reach[:, None] - origin) / cell).astype(np.int64)
    keys = _near_pairs(points, reach, origin, cell, dims, low, high)
    counts = np.bincount(keys // len(points), minlength=int(np.prod(dims)))
    starts = np.cumsum(counts) - counts
    segments = np.concatenate([points - origin, widths[..., None] * 1000.0], -1).reshape(-1, 4)
    entries = (keys % len(points)).astype(np.int32)
    return CrackIndex(_rows(segments.astype(np.float32)),
                      _rows(np.stack([starts, counts], 1).astype(np.int32)), _rows(entries),
                      origin.astype(np.float32), cell, tuple(int(d) for d in dims),
                      int(counts.max()), network.rough, footprint)
