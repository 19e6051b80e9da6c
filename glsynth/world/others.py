"""Others (class 8): what inspection photographs of viaducts show that is neither bridge nor
background: steel jackets of retrofitted columns, steel X braces between a row's columns,
drainage downpipes, cable troughs under the slab overhang and numbered plates on columns.
Placement rules and their sources: docs/design.md, "Others".

Each viaduct draws its others from its own generator (Stream.OTHERS, item = its index) by the
[environment] *_probability rules, so no rule moves another viaduct's draw or any other
stream's. A viaduct's pieces of one kind are merged into one mesh, one part (few parts, few
draw calls), and the parts come after every other part of the environment: materials are
seeded by a part's ordinal. With every probability 0 (the paper) there are none.
"""

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import trimesh

from glsynth.core.config import Config
from glsynth.core.seeding import Stream, make_rng
from glsynth.world import meshes
from glsynth.world.environment import (
    ColumnInfo,
    Part,
    PartKind,
    ViaductInfo,
    viaduct_samples,
)
from glsynth.world.trajectory import Trajectory

JACKET_OFFSET_M = 0.05
"""The jacket's steel face stands this far outside the column's: a plate of about 9 mm on a
mortar-filled gap."""
JACKET_GAP_M = 0.05
"""Jackets stop this short of the beams they meet, so that they add no bending strength."""
BRACE_SECTION_M = 0.15
"""A brace's square section."""
BRACE_CLEAR_M = (0.5, 0.2)
"""Braces run from this far above the ground to this far below the beam over a panel."""
PIPE_RADIUS_M = 0.075
PIPE_CLEAR_M = 0.03
"""Between a downpipe and the face it runs down."""
TROUGH_SECTION_M = (0.4, 0.25)
"""A cable trough's width and height, hung from the slab's soffit at the deck's edge."""
SIGN_SIZE_M = (0.35, 0.02, 0.35)
"""A plate's width along the track, thickness and height: square, its face showing its image
once (glsynth.appearance.signs)."""
SIGN_HEIGHT_M = 1.8
"""The plate's centre above the ground."""


@dataclass(frozen=True)
class _Site:
    """What one viaduct's others are placed by."""

    config: Config
    trajectory: Trajectory
    viaduct: ViaductInfo
    tie_z: tuple[float, float] | None
    """The z range of the viaduct's tie beams, or None without them."""

    def rows(self) -> list[tuple[ColumnInfo, ColumnInfo]]:
        """Its column rows as (left, right): ViaductInfo.columns holds them row by row, left
        (+ across) first."""
        cols = self.viaduct.columns
        return [(cols[k], cols[k + 1]) for k in range(0, len(cols), 2)]

    def row_s(self, row: int) -> float:
        d = self.config.design
        return self.viaduct.index * d.length_m + d.column_rows_s[row]

    def soffit(self, column: ColumnInfo) -> float:
        """The underside of the beams over ``column``."""
        return column.top_z - self.config.design.embed_m


def build_others(config: Config, trajectory: Trajectory, viaducts: Sequence[ViaductInfo],
                 parts: Sequence[Part], root_seed: int, env_index: int) -> list[Part]:
    """The others of every viaduct, to be appended after ``parts`` (the rest of the
    environment, whose tie beams the braces stop at)."""
    out: list[Part] = []
    for v in viaducts:
        ties = [p.world_vertices()[:, 2] for p in parts
                if p.kind is PartKind.TIE_BEAM and p.viaduct == v.index]
        tie_z = (float(min(z.min() for z in ties)), float(max(z.max() for z in ties))) \
            if ties else None
        site = _Site(config, trajectory, v, tie_z)
        rng = make_rng(root_seed, env_index, Stream.OTHERS, v.index)
        for kind, mesh in _viaduct_others(site, rng):
            out.append(Part(f"other_v{v.index:02d}_{kind.value}", kind, v.index, mesh,
                            np.eye(4)))
    return out


def _viaduct_others(site: _Site, rng: np.random.Generator
                    ) -> list[tuple[PartKind, trimesh.Trimesh]]:
    """One viaduct's merged meshes by kind. Every draw is made whatever its outcome, so each
    rule's draws stay where they are when another rule's probability changes."""
    cfg = site.config.environment
    rows = site.rows()
    jacketed = rng.uniform() < cfg.jacket_probability
    braced = rng.uniform() < cfg.brace_probability and not jacketed
    pipe_draws = [(rng.uniform() < cfg.downpipe_probability, int(rng.integers(len(rows))),
                   rng.choice([-1.0, 1.0])) for _ in range(2)]
    troughs = [rng.uniform() < cfg.trough_probability for _ in range(2)]
    sign_draw = (rng.uniform() < cfg.sign_probability, int(rng.integers(2 * len(rows) - 1)))
    offset = JACKET_OFFSET_M if jacketed else 0.0
    pieces: dict[PartKind, list[trimesh.Trimesh]] = {kind: [] for kind in (
        PartKind.JACKET, PartKind.BRACE, PartKind.DOWNPIPE, PartKind.TROUGH, PartKind.SIGN)}
    if jacketed:
        pieces[PartKind.JACKET] = [_jackets(site, c) for c in site.viaduct.columns]
    if braced:
        pieces[PartKind.BRACE] = [_braces(site, left, right) for left, right in rows]
    piped = set()
    for side, (wanted, row, corner) in enumerate(pipe_draws):
        if wanted:
            piped.add(2 * row + side)
            pieces[PartKind.DOWNPIPE].append(_downpipe(site, row, side, corner, offset))
    for side, wanted in enumerate(troughs):
        if wanted:
            pieces[PartKind.TROUGH].append(_trough(site, side))
    if sign_draw[0]:
        # A column without a downpipe: the k-th of them, wrapping.
        free = [k for k in range(2 * len(rows)) if k not in piped]
        k = free[sign_draw[1] % len(free)]
        pieces[PartKind.SIGN].append(_sign(site, k // 2, k % 2, offset))
    return [(kind, trimesh.util.concatenate(found)) for kind, found in pieces.items()
            if found]


def _placed(extents: tuple[float, float, float], pose: np.ndarray) -> trimesh.Trimesh:
    return meshes.boxes(extents, pose[None])


def _jackets(site: _Site, column: ColumnInfo) -> trimesh.Trimesh:
    """A column's steel jacket from below the ground to the beams over it. Tie beams pass
    through it, which draws the cut-outs a real jacket has where they frame in."""
    a, b = column.section_m
    z0, z1 = column.bottom_z - 0.1, site.soffit(column) - JACKET_GAP_M
    x, y = column.center_xy
    return _placed((a + 2 * JACKET_OFFSET_M, b + 2 * JACKET_OFFSET_M, z1 - z0),
                   meshes.pose(column.heading, [x, y, (z0 + z1) / 2]))


def _rotation_x(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    out = np.eye(4)
    out[1:3, 1:3] = [[c, -s], [s, c]]
    return out


def _braces(site: _Site, left: ColumnInfo, right: ColumnInfo) -> trimesh.Trimesh:
    """X braces between a row's two columns, one X per panel (ground to tie beam, tie beam to
    cross beam). The two diagonals of an X lie on either side of the row's plane, as
    back-to-back angles on a gusset do, so no faces of the two coincide."""
    (xl, yl), (xr, yr) = left.center_xy, right.center_xy
    width = float(np.hypot(xl - xr, yl - yr)) - left.section_m[1]
    reach = width + 2 * 0.1  # ends inside the columns' faces
    low = max(left.bottom_z, right.bottom_z) + BRACE_CLEAR_M[0]
    high = min(site.soffit(left), site.soffit(right)) - BRACE_CLEAR_M[1]
    panels = [(low, high)] if site.tie_z is None else [
        (low, site.tie_z[0] - BRACE_CLEAR_M[1]), (site.tie_z[1] + BRACE_CLEAR_M[1], high)]
    row = meshes.pose(left.heading, [(xl + xr) / 2, (yl + yr) / 2, 0.0])
    s = BRACE_SECTION_M
    out = []
    for z0, z1 in panels:
        if z1 - z0 < 1.0:
            continue
        angle = float(np.arctan2(z1 - z0, reach))
        length = float(np.hypot(z1 - z0, reach))
        for along, sign in ((-s / 2, 1.0), (s / 2, -1.0)):
            shift = np.eye(4)
            shift[:3, 3] = [along, 0.0, (z0 + z1) / 2]
            out.append(_placed((s, length, s), row @ shift @ _rotation_x(sign * angle)))
    return trimesh.util.concatenate(out)


def _rounded(points: np.ndarray, radius: float, steps: int = 4) -> np.ndarray:
    """A polyline with each inner corner replaced by a quadratic curve that leaves the corner's
    legs ``radius`` (at most 45 % of each leg) before it."""
    out = [points[0]]
    for k in range(1, len(points) - 1):
        p, c, n = points[k - 1], points[k], points[k + 1]
        r = min(radius, 0.45 * np.linalg.norm(c - p), 0.45 * np.linalg.norm(n - c))
        a = c + r * (p - c) / np.linalg.norm(p - c)
        b = c + r * (n - c) / np.linalg.norm(n - c)
        t = np.linspace(0.0, 1.0, steps + 1)[:, None]
        out.extend((1 - t) ** 2 * a + 2 * t * (1 - t) * c + t ** 2 * b)
    out.append(points[-1])
    return np.array(out)


def _downpipe(site: _Site, row: int, side: int, corner: float, offset: float
              ) -> trimesh.Trimesh:
    """A drainage pipe from the slab's overhang down the outer face of column ``side`` (0:
    left, 1: right) of ``row``, near one corner: it leaves the slab outside the girder, bends
    in to the column under the girder, runs down it and bends out above the ground."""
    d, traj = site.config.design, site.trajectory
    column = site.rows()[row][side]
    a, b = column.section_m
    s = site.row_s(row) + corner * (a / 2 - PIPE_RADIUS_M - 0.1)
    _, tangent, normal = traj.frame(np.array([s]))
    outward = (1.0 if side == 0 else -1.0) * normal[0]
    u_col = b / 2 + offset + PIPE_RADIUS_M + PIPE_CLEAR_M
    u_top = max(u_col, d.girder_width_m / 2 + PIPE_RADIUS_M + PIPE_CLEAR_M) + 0.3
    slab = float(traj.deck_at(np.array([s]))[0]) - d.slab_thickness_m
    ground = float(traj.ground_at(np.array([s]))[0])
    bend = site.soffit(column) - 0.3
    uz = np.array([[u_top, slab + 0.05], [u_top, bend], [u_col, bend - (u_top - u_col)],
                   [u_col, ground + 0.45], [u_col + 0.25, ground + 0.2],
                   [u_col + 0.55, ground + 0.2]])
    uz = _rounded(uz, 0.15)
    base = np.array([*column.center_xy, 0.0]) + (s - site.row_s(row)) * tangent[0]
    path = base + uz[:, :1] * outward + uz[:, 1:] * np.array([0.0, 0.0, 1.0])
    # Sweep frame: across is the along-track axis, normal to the pipe's vertical plane.
    step = np.gradient(path, axis=0)
    step /= np.linalg.norm(step, axis=1, keepdims=True)
    across = np.cross(outward, [0.0, 0.0, 1.0])
    across = np.tile(across / np.linalg.norm(across), (len(path), 1))
    up = np.cross(step, across)
    return meshes.sweep(meshes.circle(PIPE_RADIUS_M, site.config.environment.cylinder_segments),
                        path, across, up, closed=True, smooth=True, caps=True)


def _trough(site: _Site, side: int) -> trimesh.Trimesh:
    """A cable trough the viaduct's length under the slab's overhang at its edge (0: left)."""
    d, traj = site.config.design, site.trajectory
    width, height = TROUGH_SECTION_M
    edge = d.deck_width_m / 2 - 0.1
    lo, hi = (edge - width, edge) if side == 0 else (-edge, -edge + width)
    s = viaduct_samples(site.config, traj, site.viaduct.index)
    path, _, normal = traj.frame(s)
    up = np.tile([0.0, 0.0, 1.0], (len(s), 1))
    # Its top 1 cm inside the slab: no gap along the soffit.
    profile = meshes.rectangle(lo, hi, -d.slab_thickness_m - height,
                               -d.slab_thickness_m + 0.01)
    return meshes.sweep(profile, path, normal, up, closed=True, caps=True)


def _sign(site: _Site, row: int, side: int, offset: float) -> trimesh.Trimesh:
    """A plate on the outer face of column ``side`` of ``row`` (on its jacket if it has one)."""
    column = site.rows()[row][side]
    width, thick, height = SIGN_SIZE_M
    across = (1.0 if side == 0 else -1.0) * (column.section_m[1] / 2 + offset + thick / 2)
    ground = float(site.trajectory.ground_at(np.array([site.row_s(row)]))[0])
    local = np.eye(4)
    local[:3, 3] = [0.0, across, ground + SIGN_HEIGHT_M]
    x, y = column.center_xy
    return _placed((width, thick, height), meshes.pose(column.heading, [x, y, 0.0]) @ local)
