"""A member's cracks baked into coverage tiles for the Cycles twin (render/blender_job.py reads
them): pure numpy, the same geometry and contrast as the GL crack pass (shaders/cracks.glsl).

A tile is a rectangle on one plane of the member's mesh (a column's lateral face), in the mesh
frame, divided into square texels. Each texel holds the share of its area that the cracks
cover: the band of width w(t) around each segment's centreline, w linear along the segment
and the distance measured to the segment, as in the shader; overlapping cracks take the
largest share, as the shader does. Within a texel the share is exact for a straight band (the
area of a square cut by a strip, from the distribution of the square's points across the
crack), so the texels' mean over any area is the crack's mean darkening there, however thin
the crack: Cycles' pixel filter then averages them over the pixel as GL's box filter does.

Texel size: half the finest pixel footprint of the views being rendered, taken at the crack
point nearest each camera (``TEXELS_PER_FOOTPRINT``), grown by 25 % steps until the job's
tiles hold at most ``MAX_TEXELS`` texels. Above the bound a crack is blurred over a texel
wider than half a pixel, but its mean darkening stays exact. Tiles cover only the cracks:
per plane, the bounding rectangle of each crack's bands, rectangles that meet merged.
"""

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import trimesh

from glsynth.appearance.cracks import CrackNetwork
from glsynth.render.cracks_index import segment_distance
from glsynth.world.cameras import Camera

TEXELS_PER_FOOTPRINT = 2
"""Texels across the finest pixel footprint: a crack's position is kept to half a pixel."""
MAX_TEXELS = 1 << 24
"""Texels of all of a job's tiles: 64 MB in Blender's images and 64 MB in Cycles (4 bytes
each), about 200 MB peak while baking."""
PLANE_TOLERANCE_M = 1e-5
"""A segment lies on a plane of the mesh when both its ends are this close to it."""
ENCODE_STEPS = 255 * 256
"""Coverage is stored in 16 bits over two 8-bit channels: value = R + G / 256 (R, G in 0..1)."""
_CHUNK = 1 << 21
"""Candidate (segment, texel) samples rasterised at once: bounds the bake's memory."""


@dataclass(frozen=True, eq=False)
class CrackTile:
    """Crack coverage on a rectangle of one plane of a mesh, in the mesh frame (metres)."""

    origin: np.ndarray
    """(3,): the corner of texel (0, 0), on the plane."""
    u_axis: np.ndarray
    """(3,) unit: along a row of texels (columns grow along it)."""
    v_axis: np.ndarray
    """(3,) unit: across the rows (rows grow along it); normal = u_axis x v_axis."""
    texel_m: float
    coverage: np.ndarray
    """(rows, columns) float32 in [0, 1]: row 0 at ``origin``, i.e. the bottom row as Blender
    stores images."""

    @property
    def normal(self) -> np.ndarray:
        return np.cross(self.u_axis, self.v_axis)


def plane_axes(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """In-plane unit axes (u, v) with u x v = normal: u horizontal where the plane is not (v
    then runs up a column's face)."""
    n = normal / np.linalg.norm(normal)
    u = np.cross([0.0, 0.0, 1.0], n)
    if np.linalg.norm(u) < 1e-6:
        u = np.array([1.0, 0.0, 0.0]) - n[0] * n
    u /= np.linalg.norm(u)
    return u, np.cross(n, u)


def segment_planes(network: CrackNetwork, mesh: trimesh.Trimesh
                   ) -> list[tuple[np.ndarray, float, np.ndarray]]:
    """The mesh's face planes that carry segments: (unit normal, offset n . x, which segments
    lie on it); a segment along an edge lies on both faces' planes."""
    normals = np.asarray(mesh.face_normals, np.float64)
    offsets = np.einsum("ij,ij->i", normals, np.asarray(mesh.vertices)[mesh.faces[:, 0]])
    keys = np.round(np.column_stack([normals, offsets]), 6)
    _, first = np.unique(keys, axis=0, return_index=True)
    planes = []
    for face in np.sort(first):
        n, c = normals[face], offsets[face]
        on = np.all(np.abs(network.points @ n - c) <= PLANE_TOLERANCE_M, axis=1)
        if on.any():
            planes.append((n, float(c), on))
    return planes


def _merge(rects: list[np.ndarray]) -> list[np.ndarray]:
    """Rectangles (2, 2) [[u0, v0], [u1, v1]] merged into the bounding rectangle of any that
    meet, until none meet."""
    rects = [r.copy() for r in rects]
    merged = True
    while merged:
        merged = False
        for i in range(len(rects)):
            for j in range(i + 1, len(rects)):
                a, b = rects[i], rects[j]
                if np.all(a[0] <= b[1]) and np.all(b[0] <= a[1]):
                    rects[i] = np.array([np.minimum(a[0], b[0]), np.maximum(a[1], b[1])])
                    del rects[j]
                    merged = True
                    break
            if merged:
                break
    return rects


@dataclass(frozen=True)
class _PlaneCracks:
    """A plane's segments in its own 2D frame."""

    normal: np.ndarray
    offset: float
    axes: tuple[np.ndarray, np.ndarray]
    uv: np.ndarray
    """(n, 2, 2): the end points in (u, v), metres."""
    widths: np.ndarray
    """(n, 2) metres."""
    crack: np.ndarray


def _plane_cracks(network: CrackNetwork, mesh: trimesh.Trimesh) -> list[_PlaneCracks]:
    found = []
    for n, c, on in segment_planes(network, mesh):
        u, v = plane_axes(n)
        pts = network.points[on]
        found.append(_PlaneCracks(n, c, (u, v), np.stack([pts @ u, pts @ v], -1),
                                  network.widths_m[on], network.crack[on]))
    return found


def _rects(plane: _PlaneCracks, texel_m: float) -> list[np.ndarray]:
    """The plane's tiles at ``texel_m``: per crack the bounding rectangle of its bands and
    two texels, merged where they meet."""
    rects = []
    for k in np.unique(plane.crack):
        mine = plane.crack == k
        reach = plane.widths[mine].max() / 2 + 2 * texel_m
        pts = plane.uv[mine].reshape(-1, 2)
        rects.append(np.array([pts.min(0) - reach, pts.max(0) + reach]))
    return _merge(rects)


def _shape(rect: np.ndarray, texel_m: float) -> tuple[int, int]:
    cols, rows = np.ceil((rect[1] - rect[0]) / texel_m).astype(int)
    return int(rows), int(cols)


def finest_footprint(network: CrackNetwork, pose: np.ndarray, cameras: Sequence[Camera]
                     ) -> float:
    """The smallest pixel footprint (metres) of ``cameras`` at the crack point nearest each:
    distance times the angle of a pixel at the image centre."""
    world = network.points @ pose[:3, :3].T + pose[:3, 3]
    best = np.inf
    for cam in cameras:
        distance = segment_distance(cam.pose[:3, 3], world[:, 0], world[:, 1])[0].min()
        best = min(best, distance * cam.sensor_mm / (cam.focal_mm * cam.width))
    return float(best)


def texel_sizes(members: Sequence[tuple[CrackNetwork, trimesh.Trimesh, np.ndarray]],
                cameras: Sequence[Camera]) -> list[float]:
    """Per member (network, mesh, pose: world from mesh), its tiles' texel edge (module
    docstring): the finest footprint / TEXELS_PER_FOOTPRINT, all grown together by 25 %
    steps until the tiles hold at most MAX_TEXELS."""
    planes = [_plane_cracks(net, mesh) for net, mesh, _ in members]
    sizes = [finest_footprint(net, pose, cameras) / TEXELS_PER_FOOTPRINT
             for net, _, pose in members]
    while True:
        total = sum(np.prod(_shape(r, h)) for h, member in zip(sizes, planes)
                    for plane in member for r in _rects(plane, h))
        if total <= MAX_TEXELS:
            return sizes
        sizes = [1.25 * h for h in sizes]


def texel_coverage(d: np.ndarray, width: np.ndarray, a: np.ndarray, b: np.ndarray
                   ) -> np.ndarray:
    """The share of a texel that a band of ``width`` covers, its centre ``d`` from the band's
    centreline: a, b are the texel's two edges projected across the band (h |cos|, h |sin|),
    so a point of the texel lies x across from its centre with x the sum of two uniform
    variables of widths a and b. Exact for a straight band."""
    a, b = np.maximum(a, b), np.minimum(a, b)

    def cdf(x: np.ndarray) -> np.ndarray:
        ramp = np.maximum
        s, t = (a + b) / 2, (a - b) / 2
        safe_b = np.where(b > 1e-4 * a, b, 1.0)
        two = (ramp(x + s, 0) ** 2 - ramp(x + t, 0) ** 2 - ramp(x - t, 0) ** 2
               + ramp(x - s, 0) ** 2) / (2 * a * safe_b)
        return np.where(b > 1e-4 * a, two, np.clip(x / a + 0.5, 0.0, 1.0))

    return np.clip(cdf(width / 2 - d) - cdf(-width / 2 - d), 0.0, 1.0)


def _lattice(uv: np.ndarray, widths: np.ndarray, texel_m: float
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per segment: its unit direction and normal in the plane, how far the lattice reaches
    from the centreline (half the widest width and two texels), and its points along and
    across at half a texel."""
    along = uv[:, 1] - uv[:, 0]
    length = np.linalg.norm(along, axis=1)
    t_hat = np.where(length[:, None] > 0, along / np.maximum(length, 1e-12)[:, None], [1.0, 0])
    reach = widths.max(1) / 2 + 2 * texel_m
    n_along = np.ceil((length + 2 * reach) / (texel_m / 2)).astype(np.int64) + 1
    n_across = np.ceil(2 * reach / (texel_m / 2)).astype(np.int64) + 1
    return t_hat, np.stack([-t_hat[:, 1], t_hat[:, 0]], 1), reach, n_along, n_across


def _candidates(uv: np.ndarray, widths: np.ndarray, texel_m: float, lo: np.ndarray,
                shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(segment, texel (column, row)) pairs, each once, for every texel of the tile (corner
    ``lo``, ``shape`` rows x columns) whose centre lies within a segment's half width plus
    one texel: a lattice of spacing half a texel over the segment's rectangle grown by one
    more texel meets each of them (any square of edge h holds a point of it)."""
    t_hat, n_hat, reach, n_along, n_across = _lattice(uv, widths, texel_m)
    counts = n_along * n_across
    owner = np.repeat(np.arange(len(uv)), counts)
    local = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    s = (local // n_across[owner]) * (texel_m / 2) - reach[owner]
    q = (local % n_across[owner]) * (texel_m / 2) - reach[owner]
    pts = uv[owner, 0] + s[:, None] * t_hat[owner] + q[:, None] * n_hat[owner]
    texel = np.floor((pts - lo) / texel_m).astype(np.int64)
    inside = np.all((texel >= 0) & (texel < [shape[1], shape[0]]), axis=1)
    key = np.unique((owner[inside] << 42) | (texel[inside, 1] << 21) | texel[inside, 0])
    return key >> 42, np.stack([key & (2**21 - 1), (key >> 21) & (2**21 - 1)], 1)


def _chunks(uv: np.ndarray, widths: np.ndarray, texel_m: float) -> list[np.ndarray]:
    """Segments in runs of about _CHUNK lattice points (a longer segment alone)."""
    _, _, _, n_along, n_across = _lattice(uv, widths, texel_m)
    run = np.cumsum(n_along * n_across) // _CHUNK
    return [np.flatnonzero(run == r) for r in np.unique(run)]


def _rasterise(uv: np.ndarray, widths: np.ndarray, texel_m: float, rect: np.ndarray
               ) -> np.ndarray:
    """The coverage (rows, columns) of the tile ``rect`` by segments ``uv`` (module doc)."""
    shape = _shape(rect, texel_m)
    tile = np.zeros(shape[0] * shape[1], np.float32)
    for chunk in _chunks(uv, widths, texel_m):
        seg, texel = _candidates(uv[chunk], widths[chunk], texel_m, rect[0], shape)
        a, b = uv[chunk][seg, 0], uv[chunk][seg, 1]
        centre = rect[0] + (texel + 0.5) * texel_m
        d, t = segment_distance(np.pad(centre, ((0, 0), (0, 1))), np.pad(a, ((0, 0), (0, 1))),
                                np.pad(b, ((0, 0), (0, 1))))
        w = widths[chunk][seg, 0] + (widths[chunk][seg, 1] - widths[chunk][seg, 0]) * t
        t_hat = _lattice(uv[chunk], widths[chunk], texel_m)[0][seg]
        cover = texel_coverage(d, w, texel_m * np.abs(t_hat[:, 1]),
                               texel_m * np.abs(t_hat[:, 0]))
        np.maximum.at(tile, texel[:, 1] * shape[1] + texel[:, 0], cover.astype(np.float32))
    return tile.reshape(shape)


def bake_tiles(network: CrackNetwork, mesh: trimesh.Trimesh, texel_m: float
               ) -> list[CrackTile]:
    """The coverage tiles of ``network`` on ``mesh`` (its mesh frame) at ``texel_m``."""
    tiles = []
    for plane in _plane_cracks(network, mesh):
        u, v = plane.axes
        for rect in _rects(plane, texel_m):
            near = np.all((plane.uv.min(1) >= rect[0]) & (plane.uv.max(1) <= rect[1]), axis=1)
            origin = plane.offset * plane.normal + rect[0, 0] * u + rect[0, 1] * v
            tiles.append(CrackTile(origin, u, v, texel_m,
                                   _rasterise(plane.uv[near], plane.widths[near], texel_m,
                                              rect)))
    return tiles


def encode(coverage: np.ndarray) -> np.ndarray:
    """Coverage (rows, columns) in [0, 1] as an 8-bit RGB image, top row first (PNG order):
    R + G / 256 in Blender's 0..1 channel values gives the coverage back to 1 / 65280."""
    q = np.rint(np.clip(coverage[::-1], 0.0, 1.0) * ENCODE_STEPS).astype(np.int64)
    rgb = np.zeros(coverage.shape + (3,), np.uint8)
    rgb[..., 0], rgb[..., 1] = q // 256, q % 256
    return rgb


def decode(rgb: np.ndarray) -> np.ndarray:
    """encode's inverse, as the Blender material computes it (bottom row first)."""
    c = rgb[::-1].astype(np.float64) / 255
    return c[..., 0] + c[..., 1] / 256
