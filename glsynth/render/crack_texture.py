"""A member's cracks baked into a sparse coverage texture for the Cycles twin
(render/blender_job.py looks it up in a material): pure numpy, the same geometry and contrast as
the GL crack pass (shaders/cracks.glsl).

Each plane of the member's mesh that carries cracks (a column's lateral face) gets a grid of
square texels in its own 2D frame. A texel holds the share of its area that the cracks cover:
the band of width w(t) around each segment's centreline, w linear along the segment and the
distance measured to the segment, as in the shader; where cracks overlap the largest share, as
the shader takes. Within a texel the share is exact for a straight band (the area of a square
cut by a strip), so the texels' mean over any area is the cracks' mean darkening there, however
thin they are: Cycles' pixel filter then averages texels over the pixel as GL's box filter
averages the band.

Only blocks of BLOCK x BLOCK texels that a crack touches are stored, in an atlas; an
indirection image holds, per block of each plane's grid, the block's place in the atlas (0, an
empty block, elsewhere). Planes lie side by side in the indirection image, each between two
empty columns, so a point clamped to its plane's columns never reads another plane.

Texel size: half the finest pixel footprint of the views being rendered, taken at the
nearest crack point each camera images (``TEXELS_PER_FOOTPRINT``), grown by 25 % steps
together for all of a job's members until their atlases and indirection images hold at most
``MAX_TEXELS``. Beyond the bound a crack is spread over texels wider than half a pixel, but its
mean darkening stays exact.
"""

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import trimesh

from glsynth.appearance.cracks import CrackNetwork
from glsynth.core.arrays import unique_ints
from glsynth.core.geometry import segment_distance, transform_points
from glsynth.world.cameras import Camera
from glsynth.world.visibility import in_frustum

TEXELS_PER_FOOTPRINT = 2
"""Texels across the finest pixel footprint: a crack's position is kept to half a pixel."""
BLOCK = 16
"""Texels along a block's edge: larger blocks waste atlas on thin cracks, smaller ones grow the
indirection image."""
MAX_TEXELS = 1 << 24
"""Texels of all of a job's images: 64 MB in Blender's images and 64 MB in Cycles (4 bytes
each); baking 14.7 M of them took 280 MB more in glsynth (and 14 s)."""
PLANE_TOLERANCE_M = 1e-5
"""A segment lies on a plane of the mesh when both its ends are this close to it."""
LOOKUP_TOLERANCE_M = 1e-3
"""A point reads the texels of the nearest plane facing its way, within this distance: above
the float32 precision of Cycles' positions a kilometre from the origin (0.1 mm). Nearest, not
any: a curved girder's flat pieces are planes a hundredth of a radian apart, several within
a millimetre of a point near their joints."""
ENCODE_STEPS = 255 * 256
"""16 bits over two 8-bit channels: coverage = R + G / 256, block index = 256 R + G (R, G the
bytes)."""
_CHUNK = 1 << 21
"""Lattice points rasterised at once: bounds the bake's memory."""


@dataclass(frozen=True, eq=False)
class PlaneGrid:
    """One plane's grid of blocks, in the member's mesh frame."""

    normal: np.ndarray
    offset: float
    """normal . x on the plane."""
    u_axis: np.ndarray
    v_axis: np.ndarray
    """(3,) unit axes in the plane, u x v = normal: texel columns grow along u, rows along v."""
    corner: np.ndarray
    """(2,) (u, v) metres of the grid's first texel's corner."""
    blocks: tuple[int, int]
    """Blocks along u and v."""
    column: int
    """The indirection image's column of the grid's first block."""


@dataclass(frozen=True, eq=False)
class CrackTexture:
    """A member's crack coverage (module docstring). Images are stored bottom row first, as
    Blender stores them."""

    texel_m: float
    planes: tuple[PlaneGrid, ...]
    indirection: np.ndarray
    """(rows, columns) int32: per block, its index in the atlas; 0 is the empty block."""
    atlas: np.ndarray
    """(A BLOCK, A BLOCK) float32 coverage in [0, 1]: block k's texels at block column k % A,
    block row k // A."""

    @property
    def texels(self) -> int:
        return self.indirection.size + self.atlas.size

    def lookup(self, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """The coverage at mesh-frame ``points`` (n, 3) on faces of ``normals``, computed as
        blender_job.py's nodes compute it."""
        u, v = np.zeros(len(points)), np.zeros(len(points))
        best = np.full(len(points), LOOKUP_TOLERANCE_M)  # the nearest plane within it wins
        for g in self.planes:
            gap = np.abs(points @ g.normal - g.offset)
            mine = (normals @ g.normal > 0.5) & (gap < best)
            scale = BLOCK * self.texel_m
            uu = np.clip((points @ g.u_axis - g.corner[0]) / scale + g.column, g.column - 0.5,
                         g.column + g.blocks[0] + 0.5)
            u = np.where(mine, uu, u)
            v = np.where(mine, (points @ g.v_axis - g.corner[1]) / scale, v)
            best = np.where(mine, gap, best)
        on = best < LOOKUP_TOLERANCE_M
        rows, cols = self.indirection.shape
        inside = (u >= 0) & (u < cols) & (v >= 0) & (v < rows)
        k = np.where(inside, self.indirection[np.clip(v, 0, rows - 1).astype(int),
                                              np.clip(u, 0, cols - 1).astype(int)], 0)
        per_row = self.atlas.shape[0] // BLOCK
        col = ((k % per_row + u % 1) * BLOCK).astype(int)
        row = ((k // per_row + v % 1) * BLOCK).astype(int)
        return np.where(on, self.atlas[row, col], 0.0)


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


def _in_view(points: np.ndarray, cam: Camera) -> np.ndarray:
    """Which world ``points`` (n, 3) ``cam`` images: in front of its near plane and inside its
    frame."""
    local = (points - cam.pose[:3, 3]) @ cam.pose[:3, :3]
    depth = -local[:, 2]
    k = cam.K
    safe = np.where(depth > cam.znear, depth, 1.0)
    x = k[0, 0] * local[:, 0] / safe + k[0, 2]
    y = -k[1, 1] * local[:, 1] / safe + k[1, 2]
    return ((depth > cam.znear) & (np.abs(x - k[0, 2]) <= cam.width / 2)
            & (np.abs(y - k[1, 2]) <= cam.height / 2))


def finest_footprint(network: CrackNetwork, pose: np.ndarray, cameras: Sequence[Camera]
                     ) -> float:
    """The smallest pixel footprint (metres) of ``cameras`` on the cracks: distance times the
    angle of a pixel at the image centre, at the nearest end point each camera images (the
    segments are a few centimetres long); the nearest point of any crack where none images
    one (the cracks are then seen in reflections at most)."""
    world = transform_points(pose, network.points)
    ends = world.reshape(-1, 3)
    seen, anywhere = np.inf, np.inf
    for cam in cameras:
        angle = cam.sensor_mm / (cam.focal_mm * cam.width)
        anywhere = min(anywhere, angle * segment_distance(cam.pose[:3, 3], world[:, 0],
                                                          world[:, 1])[0].min())
        shown = _in_view(ends, cam)
        if shown.any():
            seen = min(seen, angle * np.linalg.norm(ends[shown] - cam.pose[:3, 3],
                                                    axis=1).min())
    return float(seen if np.isfinite(seen) else anywhere)


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
    """(segment, texel (column, row)) pairs, each once, for every texel of the grid (corner
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
    key = unique_ints((owner[inside] << 42) | (texel[inside, 1] << 21) | texel[inside, 0])
    return key >> 42, np.stack([key & (2**21 - 1), (key >> 21) & (2**21 - 1)], 1)


def _chunks(uv: np.ndarray, widths: np.ndarray, texel_m: float) -> list[np.ndarray]:
    """Segments in runs of about _CHUNK lattice points (a longer segment alone)."""
    _, _, _, n_along, n_across = _lattice(uv, widths, texel_m)
    run = np.cumsum(n_along * n_across) // _CHUNK
    return [np.flatnonzero(run == r) for r in unique_ints(run)]


def _rasterise(plane: _PlaneCracks, texel_m: float, lo: np.ndarray, shape: tuple[int, int]
               ) -> tuple[np.ndarray, np.ndarray]:
    """The plane's covered texels on the grid at ``lo`` (rows x columns ``shape``): their
    flat indices (row-major, increasing) and coverage."""
    keys, values = [np.zeros(0, np.int64)], [np.zeros(0)]
    for chunk in _chunks(plane.uv, plane.widths, texel_m):
        uv, widths = plane.uv[chunk], plane.widths[chunk]
        seg, texel = _candidates(uv, widths, texel_m, lo, shape)
        a, b = uv[seg, 0], uv[seg, 1]
        centre = lo + (texel + 0.5) * texel_m
        d, t = segment_distance(centre, a, b)
        t_hat = _lattice(uv, widths, texel_m)[0][seg]
        cover = texel_coverage(d, widths[seg, 0] + (widths[seg, 1] - widths[seg, 0]) * t,
                               texel_m * np.abs(t_hat[:, 1]), texel_m * np.abs(t_hat[:, 0]))
        keys.append(texel[:, 1] * shape[1] + texel[:, 0])
        values.append(cover)
    key, value = np.concatenate(keys), np.concatenate(values)
    order = np.argsort(key, kind="stable")
    key, value = key[order], value[order]
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]]) if len(key) else key
    best = np.maximum.reduceat(value, starts) if len(key) else value
    covered = best > 0
    return key[starts][covered], best[covered]


def _grid(plane: _PlaneCracks, texel_m: float) -> tuple[np.ndarray, tuple[int, int]]:
    """The plane's grid: its corner (u, v) and its blocks along u and v, over the segments'
    reach (half the widest width and two texels)."""
    reach = plane.widths.max() / 2 + 2 * texel_m
    pts = plane.uv.reshape(-1, 2)
    lo, hi = pts.min(0) - reach, pts.max(0) + reach
    nu, nv = np.ceil((hi - lo) / (BLOCK * texel_m)).astype(int)
    return lo, (int(nu), int(nv))


def _atlas(covered: list[tuple[np.ndarray, np.ndarray, np.ndarray]], rows: int, columns: int
           ) -> tuple[np.ndarray, np.ndarray]:
    """The indirection image (rows x columns blocks) and the atlas of the blocks that hold
    ``covered`` texels (per plane: global block row, global block column, texel row and
    column within the plane's grid, coverage; see bake_texture)."""
    block = np.concatenate([br * columns + bc for br, bc, _ in covered])
    used, which = np.unique(block, return_inverse=True)
    indirection = np.zeros((rows, columns), np.int32)
    indirection.flat[used] = np.arange(1, len(used) + 1)
    per_row = int(np.ceil(np.sqrt(len(used) + 1)))
    atlas = np.zeros((per_row * BLOCK, per_row * BLOCK), np.float32)
    k = which + 1
    r, c, value = (np.concatenate([x[2][i] for x in covered]) for i in range(3))
    atlas[(k // per_row) * BLOCK + r % BLOCK, (k % per_row) * BLOCK + c % BLOCK] = value
    return indirection, atlas


def bake_texture(network: CrackNetwork, mesh: trimesh.Trimesh, texel_m: float
                 ) -> CrackTexture:
    """The crack texture of ``network`` on ``mesh`` (its mesh frame) at ``texel_m``."""
    planes, covered, column = [], [], 1  # column 0 is empty
    for plane in _plane_cracks(network, mesh):
        lo, (nu, nv) = _grid(plane, texel_m)
        key, value = _rasterise(plane, texel_m, lo, (nv * BLOCK, nu * BLOCK))
        row, col = key // (nu * BLOCK), key % (nu * BLOCK)
        planes.append(PlaneGrid(plane.normal, plane.offset, *plane.axes, lo, (nu, nv), column))
        covered.append((row // BLOCK, col // BLOCK + column, (row, col, value)))
        column += nu + 1  # and an empty column after each plane
    rows = max([g.blocks[1] for g in planes], default=1)
    if not planes:
        return CrackTexture(texel_m, (), np.zeros((1, 1), np.int32),
                            np.zeros((BLOCK, BLOCK), np.float32))
    return CrackTexture(texel_m, tuple(planes), *_atlas(covered, rows, column))


def _estimate(network: CrackNetwork, mesh: trimesh.Trimesh, texel_m: float) -> int:
    """About the texels bake_texture makes at ``texel_m``: the blocks that points half a
    block apart over each band (its width and two texels) fall in, and the indirection
    images."""
    size, total = BLOCK * texel_m, 0
    for plane in _plane_cracks(network, mesh):
        lo, (nu, nv) = _grid(plane, texel_m)
        t_hat, n_hat, reach, n_along, n_across = _lattice(plane.uv, plane.widths, size)
        reach -= 2 * size - 2 * texel_m  # the band, not _lattice's margin of two blocks
        counts = n_along * n_across
        owner = np.repeat(np.arange(len(plane.uv)), counts)
        local = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
        s = np.minimum((local // n_across[owner]) * size / 2 - reach[owner],
                       np.linalg.norm(plane.uv[:, 1] - plane.uv[:, 0], axis=1)[owner]
                       + reach[owner])
        q = np.minimum((local % n_across[owner]) * size / 2 - reach[owner], reach[owner])
        pts = plane.uv[owner, 0] + s[:, None] * t_hat[owner] + q[:, None] * n_hat[owner]
        block = np.floor((pts - lo) / size).astype(np.int64)
        total += len(unique_ints(block[:, 1] * (nu + 1) + block[:, 0])) * BLOCK ** 2
        total += (nu + 1) * nv
    return total + BLOCK ** 2  # the empty block


def framed(network: CrackNetwork, pose: np.ndarray, cameras: Sequence[Camera]
           ) -> CrackNetwork:
    """The segments of ``network`` (mesh frame; ``pose``: world from mesh) that some camera
    frames (glsynth.world.visibility.in_frustum: the centreline within 2 px of the frame; a
    band reaching in from further out, wider than 2 px there, is left out), as a network of
    their own. The Cycles job
    draws only these: a crack outside every frame shows in no image but through the light
    its sub-millimetre darkening takes from the bounces, far below Cycles' noise, and a
    curved girder's cracks lie on dozens of its flat pieces, each a plane in the material's
    node tree (84 planes a girder made the demo's Cycles job 4x slower)."""
    a = transform_points(pose, network.points[:, 0])
    b = transform_points(pose, network.points[:, 1])
    keep = np.zeros(len(a), bool)
    for cam in cameras:
        keep |= in_frustum(a, b, cam)
    return network.subset(keep)


def bake_for_views(members: Sequence[tuple[CrackNetwork, trimesh.Trimesh, np.ndarray]],
                   cameras: Sequence[Camera]) -> list[CrackTexture]:
    """Per member (network, mesh, pose: world from mesh), its crack texture for ``cameras``
    (module docstring: the finest footprint / TEXELS_PER_FOOTPRINT, grown together by 25 %
    steps until all hold at most MAX_TEXELS)."""
    sizes = [finest_footprint(net, pose, cameras) / TEXELS_PER_FOOTPRINT
             for net, _, pose in members]
    while True:
        if sum(_estimate(n, m, h) for (n, m, _), h in zip(members, sizes)) <= MAX_TEXELS:
            textures = [bake_texture(n, m, h) for (n, m, _), h in zip(members, sizes)]
            if sum(t.texels for t in textures) <= MAX_TEXELS:
                return textures
        sizes = [1.25 * h for h in sizes]


def encode(values: np.ndarray, steps: int = ENCODE_STEPS) -> np.ndarray:
    """An image of values in [0, 1] (coverage; steps 65280) or of integers (block indices;
    steps 1) as 8-bit RGB, top row first (PNG order), holding round(value x steps) as 256 R + G.
    Blender reads R + G / 256 = value back (to 1 / 65280) from its 0..1 channels."""
    q = np.rint(np.asarray(values, np.float64)[::-1] * steps).astype(np.int64)
    if q.min(initial=0) < 0 or q.max(initial=0) >= 1 << 16:
        raise ValueError(f"encode: values {values.min()} .. {values.max()} x {steps} do not "
                         "fit 16 bits")
    rgb = np.zeros(q.shape + (3,), np.uint8)
    rgb[..., 0], rgb[..., 1] = q // 256, q % 256
    return rgb


def decode(rgb: np.ndarray) -> np.ndarray:
    """encode's inverse for coverage, as the Blender material computes it (bottom row
    first)."""
    c = rgb[::-1].astype(np.float64) / 255
    return c[..., 0] + c[..., 1] / 256
