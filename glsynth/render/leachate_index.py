"""The leaching cracks of a network packed for the colour pass (shaders/crack_leachate.glsl):
their segments with the crack's leachate, and a uniform 3D grid whose cells list every segment
whose run, damp band or deposit can reach the cell, so a fragment reads one list.

A segment's region is its box grown sideways by its damp band (and, at a crack's end, its
run's spread), down by its run's length plus the band and up by the band
(glsynth.appearance.crack_leachate), and on every side by the most its path strays from it
(CRACK_REACH_M); it is listed in every cell its region's box meets. No GL here: the
renderer uploads the arrays. Positions are relative to the crack grid's corner, as the crack
pass's are (glsynth.render.cracks_index, "Precision").
"""

from dataclasses import dataclass

import numpy as np

from glsynth.appearance import crack_paths
from glsynth.appearance.crack_leachate import EFFLORESCENCE, NONE, reach_m
from glsynth.appearance.cracks import CrackNetwork
from glsynth.render.cracks_index import _rows, box_cells

CELL_M = 0.05
"""The grid's smallest cell edge (as the crack grid's): a cell lists the few segments above it
whose runs reach it."""
MAX_CELLS = 1 << 20


@dataclass(frozen=True, eq=False)
class LeachateIndex:
    """Rows of ROW texels, as the shader reads them."""

    items: np.ndarray
    """(rows, ROW, 4) float32 (cracks_index.ROW), four texels per segment: its first end
    point (relative to the crack grid's corner) and the strength, positive for efflorescence,
    negative for rust; its second end point and the run's length (m); the damp band's reach
    (m), a seed (m along the crack), the segment's id in the crack network (its path, from the
    crack textures), 0; its middle, 0 (the nearest middle picks the crack whose path the
    shader follows)."""
    cells: np.ndarray
    """(rows, ROW, 2) int32: per cell (x fastest), its first entry and its count."""
    entries: np.ndarray
    """(rows, ROW) int32: segment ids, cell after cell."""
    origin: np.ndarray
    """(3,) float32: the grid's lower corner, relative to the crack grid's corner."""
    cell_m: float
    dims: tuple[int, int, int]
    longest: int
    """The longest cell list: the most segments one fragment reads."""


def _free_ends(points: np.ndarray, crack: np.ndarray) -> np.ndarray:
    """(n,) whether a segment holds an end of its crack (an end point no other segment of the
    crack shares, to 1 um)."""
    keys = np.concatenate([np.rint(points.reshape(-1, 3) * 1e6).astype(np.int64),
                           np.repeat(crack, 2)[:, None]], 1)
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    return (counts[inverse.ravel()] == 1).reshape(-1, 2).any(1)


def _regions(points: np.ndarray, table: np.ndarray, ends: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) corners (n, 3) of each segment's region (module docstring): a run spreads
    sideways only past its crack's ends (inside, the next segment's run goes on)."""
    streak, damp = table[:, 2], table[:, 3]
    path = crack_paths.SHADER_CONSTANTS["CRACK_REACH_M"]
    side = np.where(ends, reach_m(streak), 0.0) + damp + path
    low = points.min(1) - np.stack([side, side, streak + damp + path], 1)
    high = points.max(1) + np.stack([side, side, damp + path], 1)
    return low, high


def _box_keys(first: np.ndarray, last: np.ndarray, dims: np.ndarray) -> np.ndarray:
    """Sorted keys cell id x n + segment of every cell of each of n segments' boxes
    first..last (cells, inclusive), all at once (cracks_index.box_cells)."""
    segment, (x, y, z) = box_cells(first, last - first + 1)
    return np.sort((x + dims[0] * (y + dims[1] * z)) * len(first) + segment)


def pack_leachate(network: CrackNetwork, crack_origin: np.ndarray) -> LeachateIndex | None:
    """The leaching segments of ``network`` and their grid; None where none leaches."""
    if network.leachate is None:
        return None
    table = network.leachate[network.crack]
    leaching = np.flatnonzero(table[:, 0] != NONE)
    if not len(leaching):
        return None
    points = network.points[leaching] - np.asarray(crack_origin, np.float64)
    table = table[leaching]
    low, high = _regions(points, table, _free_ends(points, network.crack[leaching]))
    cell = CELL_M
    while True:
        origin = low.min(0)
        dims = np.floor((high.max(0) - origin) / cell).astype(np.int64) + 1
        if np.prod(dims) <= MAX_CELLS:
            break
        cell *= 1.25
    first = np.floor((low - origin) / cell).astype(np.int64)
    last = np.minimum(np.floor((high - origin) / cell).astype(np.int64), dims - 1)
    keys = _box_keys(first, last, dims)
    counts = np.bincount(keys // len(points), minlength=int(np.prod(dims)))
    starts = np.cumsum(counts) - counts
    signed = np.where(table[:, 0] == EFFLORESCENCE, table[:, 1], -table[:, 1])
    along = np.linalg.norm(points[:, 1] - points[:, 0], axis=1)
    seed = np.cumsum(along) - along  # where the segment starts along the network's run
    items = np.stack([np.c_[points[:, 0], signed], np.c_[points[:, 1], table[:, 2]],
                      np.c_[table[:, 3], seed, leaching, np.zeros(len(points))],
                      np.c_[points.mean(1), np.zeros(len(points))]], 1)
    return LeachateIndex(_rows(items.reshape(-1, 4).astype(np.float32)),
                         _rows(np.stack([starts, counts], 1).astype(np.int32)),
                         _rows((keys % len(points)).astype(np.int32)),
                         origin.astype(np.float32), cell, tuple(int(d) for d in dims),
                         int(counts.max()))

