"""What surrounds the viaducts: the paper's photo panels, or a 3-D town under the sky.

[environment] world picks one. "panels" (the paper, Section 3.1): a ground strip and a photo
panel on each side of every viaduct and across both ends. "town" (issue 40; docs/design.md,
"A town around the viaduct"): a wider ground strip, a paved strip under each deck, a road on
each side with cars, vans and trucks, utility poles with wires, sound barriers and hedges, then
houses, mid-rise blocks and warehouses among trees, all on the land of a terrain that rises to
a ring of low hills far away, beyond which the renderer's sky shows. Every town piece keeps
clear of the deck footprint and the columns. The pieces of one kind on one side of one strip
(a viaduct, or a lead-in or lead-out margin) are merged into one part, so a strip adds at most
one part per kind and side. The town draws from its own stream (Stream.WORLD), one generator
per strip, so it never moves the viaducts, materials or cameras.
"""

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import trimesh

from glsynth.core.labels import Component
from glsynth.core.seeding import Stream, make_rng
from glsynth.world import meshes
from glsynth.world.environment import PartKind, _samples

if TYPE_CHECKING:
    from glsynth.world.environment import _Builder

TOWN_HALF_WIDTH_M = 75.0
"""The town's ground strip reaches this far from the centre line on each side."""
DECK_CLEARANCE_M = 2.5
"""Road surfaces and vehicles beside a viaduct keep this far outside its deck edge."""
COLUMN_CLEARANCE_M = 0.5
"""The paved strip and parked cars under a deck keep this far from the column faces and
below the beams."""
ROAD_M = (8.0, 15.0)
"""A two-lane road's edges as offsets from the centre line (the standard deck's edge is at
5.5 m); build_surroundings moves the town out where a deck is wider."""
LANES_M = (9.75, 13.25)
"""Lane centres on the road: vehicles drive along the track."""
POLE_U_M = 16.0
BARRIER_U_M = 16.8
HEDGE_U_M = 17.6
LOT_ROWS_M = ((20.0, 36.0), (40.0, 68.0))
"""The two rows of building lots, as offsets from the centre line."""
TERRAIN_DROP_M = 1.0
"""The terrain runs this far below the town's ground strip, which hides it."""
HILLS_M = (250.0, 450.0, 700.0)
"""Beyond the town's farthest point: where the hills start rising, their crest, the
terrain's outer edge (a plateau at the crest's height)."""
HILL_HEIGHT_M = (15.0, 60.0)
"""Crest height above the ground, varying round the ring."""
TOWN_KINDS = frozenset({PartKind.BUILDING, PartKind.ROOF, PartKind.ROAD, PartKind.VEHICLE,
                        PartKind.TREE, PartKind.BARRIER, PartKind.UTILITY, PartKind.TERRAIN})
_WORD = {Component.NONBRIDGE: "nonbridge", Component.NONSTRUCTURAL: "nonstructural"}
"""A town part's name starts with its component's word, as the viaduct's fences do."""


@dataclass
class _Pieces:
    """Mesh pieces of one part in world coordinates, merged when the strip is done."""

    arrays: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=list)
    """(vertices, faces, uv) of each piece."""

    def merged(self) -> trimesh.Trimesh:
        verts, faces, uvs, base = [], [], [], 0
        for v, f, uv in self.arrays:
            verts.append(v)
            faces.append(f + base)
            uvs.append(uv)
            base += len(v)
        return meshes._mesh(np.concatenate(verts), np.concatenate(faces), np.concatenate(uvs))


def build_surroundings(b: "_Builder", root_seed: int, env_index: int) -> None:
    """Append the world of [environment] world to the builder's parts."""
    if b.cfg.world == "panels":
        panels(b)
    else:
        town(b, root_seed, env_index)


def _strips(b: "_Builder") -> list[tuple[float, float, str]]:
    """(s0, s1, tag) of the lead-in margin, each viaduct and the lead-out margin."""
    L, n, margin = b.d.length_m, b.traj.n, b.cfg.end_margin_m
    bounds = [(-margin, 0.0, "start")] if margin > 0 else []
    bounds += [(i * L, (i + 1) * L, f"v{i:02d}") for i in range(n)]
    bounds += [(n * L, n * L + margin, "end")] if margin > 0 else []
    return bounds


def _viaduct_of(tag: str) -> int | None:
    return int(tag[1:]) if tag.startswith("v") else None


def _ground_strip(b: "_Builder", s0: float, s1: float, tag: str, half_width: float) -> None:
    s = _samples(s0, s1, b.cfg.sweep_step_m, b.traj.centres_s)
    path, across, up = b.along(s, base="ground")
    b.add(f"ground_{tag}", PartKind.GROUND, _viaduct_of(tag), meshes.sweep(
        np.array([[half_width, 0.0], [-half_width, 0.0]]), path, across, up, closed=False))


# --- panels (the paper) ---------------------------------------------------------------------
def _photo_uv(mesh: trimesh.Trimesh, mirror: bool) -> trimesh.Trimesh:
    """A scene panel shows one photo: UVs normalised to [0, 1] over the panel (an exception to
    UVs in metres), v = 1 at the top, u left to right as seen from the track (``mirror`` when
    the sweep runs right to left for that viewer)."""
    uv = mesh.visual.uv / mesh.visual.uv.max(axis=0)
    if np.corrcoef(uv[:, 1], mesh.vertices[:, 2])[0, 1] < 0:
        uv[:, 1] = 1.0 - uv[:, 1]
    if mirror:
        uv[:, 0] = 1.0 - uv[:, 0]
    mesh.visual.uv = uv
    return mesh


def panels(b: "_Builder") -> None:
    """Section 3.1's world: ground and photo panels at panel_distance_m, in pieces (the two
    lead-in/out margins and one per viaduct), and a panel across each end."""
    cfg, traj = b.cfg, b.traj
    D = cfg.panel_distance_m
    for s0, s1, tag in _strips(b):
        _ground_strip(b, s0, s1, tag, D + 1.0)
        s = _samples(s0, s1, cfg.sweep_step_m, traj.centres_s)
        path, across, up = b.along(s, base="ground")
        for side, u in (("l", D), ("r", -D)):
            # Open profile facing the centre line (its left side when walking it).
            top_bottom = [[u, cfg.panel_height_m], [u, -1.0]]
            profile = np.array(top_bottom if u > 0 else top_bottom[::-1])
            b.add(f"scene_{tag}_{side}", PartKind.SCENE, _viaduct_of(tag),
                  _photo_uv(meshes.sweep(profile, path, across, up, closed=False),
                            mirror=u < 0), side=side)
    margin, end_s = cfg.end_margin_m, b.d.length_m * traj.n + cfg.end_margin_m
    for tag, s_end, facing in (("start", -margin, 1.0), ("end", end_s, -1.0)):
        point, tangent, normal = traj.frame(np.array([s_end]))
        base = point[0].copy()
        base[2] = traj.ground_at(np.array([s_end]))[0]
        ends = np.array([base - D * normal[0], base + D * normal[0]])
        if facing < 0:
            ends = ends[::-1]
        # A path across the track, swept with the panel as an open vertical profile.
        direction = (ends[1] - ends[0]) / np.linalg.norm(ends[1] - ends[0])
        across = np.tile(np.cross(direction, b.up), (2, 1))
        up = np.tile(b.up, (2, 1))
        profile = np.array([[0.0, cfg.panel_height_m], [0.0, -1.0]])
        b.add(f"scene_{tag}_across", PartKind.SCENE, None,
              _photo_uv(meshes.sweep(profile, ends, -across, up, closed=False), mirror=False))


# --- town -------------------------------------------------------------------------------------
class _Strip:
    """One strip's town in the making: its generator, local frame and merged pieces."""

    def __init__(self, b: "_Builder", s0: float, s1: float, tag: str, shift: float,
                 rng: np.random.Generator) -> None:
        self.b, self.s0, self.s1, self.tag, self.shift, self.rng = b, s0, s1, tag, shift, rng
        self.pieces: dict[tuple[PartKind, str | None], _Pieces] = {}
        # The centre line tabulated every 0.25 m (chord error under 0.1 mm at R >= 100 m):
        # placing a piece then interpolates instead of walking the trajectory's arcs.
        self.table_s = np.arange(s0 - 8.0, s1 + 8.0, 0.25)
        points, tangent, self.table_normal = b.traj.frame(self.table_s)
        self.table_xy = points[:, :2]
        self.table_heading = np.unwrap(np.arctan2(tangent[:, 1], tangent[:, 0]))
        self.table_ground = b.traj.ground_at(self.table_s)

    def put(self, kind: PartKind, side: str | None, mesh: trimesh.Trimesh) -> None:
        self.put_arrays(kind, side, mesh.vertices, mesh.faces, mesh.visual.uv)

    def put_arrays(self, kind: PartKind, side: str | None, vertices: np.ndarray,
                   faces: np.ndarray, uv: np.ndarray) -> None:
        self.pieces.setdefault((kind, side), _Pieces()).arrays.append((vertices, faces, uv))

    def place(self, s: float, u: float) -> tuple[np.ndarray, float]:
        """World xy and ground z at arc length s, offset u (shifted outwards), and heading."""
        at = [np.interp(s, self.table_s, col) for col in
              (*self.table_xy.T, *self.table_normal[:, :2].T, self.table_ground,
               self.table_heading)]
        u = u + np.sign(u) * self.shift
        xyz = np.array([at[0] + u * at[2], at[1] + u * at[3], at[4]])
        return xyz, float(at[5])

    def box(self, kind: PartKind, side: str | None, s: float, u: float,
            extents: tuple[float, float, float], z0: float, turn: float = 0.0) -> float:
        """A box (along, across, up) standing from ground + z0 at (s, u); its top z."""
        xyz, heading = self.place(s, u)
        xyz[2] += z0 + extents[2] / 2
        vertices, faces, uv = meshes._box_arrays(np.asarray(extents, dtype=float))
        pose = meshes.pose(heading + turn, xyz)
        self.put_arrays(kind, side, vertices @ pose[:3, :3].T + pose[:3, 3], faces, uv)
        return float(xyz[2] + extents[2] / 2)

    def sweep(self, kind: PartKind, side: str | None, s0: float, s1: float,
              profile: np.ndarray, closed: bool) -> None:
        """A profile (across, up above the ground) swept along the ground from s0 to s1."""
        b = self.b
        s = _samples(s0, s1, b.cfg.sweep_step_m, b.traj.centres_s)
        path, across, up = b.along(s, base="ground")
        shifted = profile.copy()
        shifted[:, 0] += np.sign(shifted[:, 0]) * self.shift
        self.put(kind, side, meshes.sweep(shifted, path, across, up, closed=closed,
                                          caps=closed))

    def add_parts(self) -> None:
        viaduct = _viaduct_of(self.tag)
        for (kind, side), pieces in self.pieces.items():
            name = f"{_WORD[kind.component]}_{self.tag}_{kind.value}" + (f"_{side}" if side
                                                                         else "")
            self.b.add(name, kind, viaduct, pieces.merged(), side=side)


def _under_deck(st: _Strip, viaduct: int) -> None:
    """A paved strip under the deck, between the column lines, clear of the column faces."""
    b = st.b
    across = max(p.mesh.extents[1] for p in b.parts
                 if p.viaduct == viaduct and p.kind is PartKind.COLUMN)
    half = b.d.column_spacing_m / 2 - across / 2 - COLUMN_CLEARANCE_M
    if half > 0.5:
        st.sweep(PartKind.ROAD, None, st.s0, st.s1, np.array([[half, 0.03], [-half, 0.03]]),
                 closed=False)


VEHICLES = {"car": ((4.3, 1.75, 0.8, 0.25), (2.3, 1.55, 0.6, 1.05)),
            "van": ((4.8, 1.9, 1.85, 0.2),),
            "truck": ((1.8, 2.3, 2.3, 0.4), (5.6, 2.45, 3.0, 0.6))}
"""Boxes (along, across, height, bottom above the road) of each vehicle, front first: a box's
centre is placed by the running length of the boxes before it."""


def _vehicles(st: _Strip, side: str, sign: float) -> None:
    """Vehicles in the lanes outside the cameras' reach (regular_distance_m + 1 m), in
    driving order without overlap."""
    reach = st.b.config.cameras.regular_distance_m + 1.0
    for lane_u in LANES_M:
        if lane_u - 1.3 + st.shift < reach:
            continue
        s = st.s0 + st.rng.uniform(0.5, 4.0)
        while True:
            kind = ("car", "car", "van", "truck")[int(st.rng.integers(4))]
            boxes = VEHICLES[kind]
            length = sum(x[0] for x in boxes)
            if s + length > st.s1 - 0.5:
                break
            turn = 0.0 if sign > 0 else np.pi  # drive on the left
            at = s if sign > 0 else s + length
            for along, across, height, bottom in boxes:
                centre = at + sign * along / 2
                st.box(PartKind.VEHICLE, side, centre, sign * lane_u, (along, across, height),
                       bottom, turn)
                at += sign * along
            s += length + st.rng.uniform(2.0, 12.0)


def _poles_and_wires(st: _Strip, side: str, sign: float, last: bool) -> None:
    """A pole at the strip's start; two wires to the next strip's pole, sagging 0.3 m."""
    height = 10.0
    u = sign * POLE_U_M
    base, _ = st.place(st.s0 + 2.0, u)
    vertical = np.array([[0.0, 0.0, -0.5], [0.0, 0.0, height]])
    x_axis, y_axis = np.tile([1.0, 0, 0], (2, 1)), np.tile([0, 1.0, 0], (2, 1))
    pole = meshes.sweep(meshes.circle(0.15, 8), vertical + base, x_axis, y_axis,
                        closed=True, smooth=True, caps=True)
    st.put(PartKind.UTILITY, side, pole)
    if last:
        return
    t = np.linspace(0.0, 1.0, 7)
    s = st.s0 + 2.0 + t * (st.s1 - st.s0)
    for du in (-0.3, 0.3):
        points = np.stack([st.place(float(si), u + du)[0] for si in s])
        points[:, 2] += height - 0.3 - 1.2 * t * (1 - t)
        st.put(PartKind.UTILITY, side, _tube(points, 0.015))


def _tube(points: np.ndarray, radius: float) -> trimesh.Trimesh:
    """A thin tube of four facets through ``points``: wires."""
    tangent = np.gradient(points, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    across = np.cross([0.0, 0.0, 1.0], tangent)
    across /= np.linalg.norm(across, axis=1, keepdims=True)
    up = np.cross(tangent, across)
    return meshes.sweep(meshes.circle(radius, 4), points, across, up, closed=True,
                        smooth=True, caps=True)


def _on_side(profile: np.ndarray, sign: float) -> np.ndarray:
    """A profile drawn for the left side (+ across), mirrored to the right for sign < 0 and
    reversed, so a closed one stays counter-clockwise and an open one keeps facing up."""
    return profile if sign > 0 else (profile * [-1.0, 1.0])[::-1]


def _roadside(st: _Strip, side: str, sign: float) -> None:
    """The road, and on some strips a sound barrier or a hedge along its outer edge."""
    lo, hi = ROAD_M
    st.sweep(PartKind.ROAD, side, st.s0, st.s1,
             _on_side(np.array([[hi, 0.03], [lo, 0.03]]), sign), closed=False)
    if st.rng.random() < 0.3:
        wall = meshes.rectangle(BARRIER_U_M - 0.1, BARRIER_U_M + 0.1, -0.5, 3.0)
        st.sweep(PartKind.BARRIER, side, st.s0, st.s1, _on_side(wall, sign),
                 closed=True)
    elif st.rng.random() < 0.6:
        a = st.rng.uniform(0.0, 0.4) * (st.s1 - st.s0)
        hedge = meshes.rectangle(HEDGE_U_M - 0.4, HEDGE_U_M + 0.4, -0.3, 1.2)
        st.sweep(PartKind.TREE, side, st.s0 + a, st.s1 - 0.5, _on_side(hedge, sign),
                 closed=True)


BUILDINGS = {"house": ((7.0, 10.0), (7.0, 9.0), (5.5, 6.5)),
             "block": ((12.0, 20.0), (10.0, 14.0), (9.0, 24.0)),
             "warehouse": ((14.0, 22.0), (12.0, 16.0), (6.0, 9.0))}
"""Ranges of length along the track, depth across it and wall height, in metres."""


def _lots(st: _Strip, side: str, sign: float) -> None:
    """Buildings along each row of lots, a tree in most gaps between them."""
    kappa = float(np.interp((st.s0 + st.s1) / 2, st.b.traj.centres_s, st.b.traj.curvature))
    for row, (u0, u1) in enumerate(LOT_ROWS_M):
        # Arc length at offset u is (1 - kappa u) times the centre line's: a building on the
        # inner side of a curve spans more of the centre line.
        stretch = 1.0 / max(0.5, 1.0 - kappa * sign * (u1 + st.shift))
        cursor = st.s0 + st.rng.uniform(0.5, 3.0)
        while True:
            kinds = ("house", "block", "warehouse") if row else ("house", "house", "warehouse")
            kind = kinds[int(st.rng.integers(3))]
            (l0, l1), (d0, d1), (h0, h1) = BUILDINGS[kind]
            length = st.rng.uniform(l0, l1)
            depth = min(st.rng.uniform(d0, d1), u1 - u0)
            span = max(length * stretch, length)
            if cursor + span > st.s1 - 0.5:
                break
            u = sign * (u0 + st.rng.uniform(0.0, u1 - u0 - depth) + depth / 2)
            _building(st, side, kind, cursor + span / 2, u, length, depth,
                      st.rng.uniform(h0, h1))
            gap = st.rng.uniform(1.0, 6.0)
            if st.rng.random() < 0.7:
                _tree(st, side, cursor + span + gap / 2, sign * st.rng.uniform(u0, u1))
            cursor += span + gap
    for _ in range(int(st.rng.integers(1, 4))):  # along the town's outer edge
        _tree(st, side, st.rng.uniform(st.s0 + 2, st.s1 - 2), sign * st.rng.uniform(69, 73))


def _building(st: _Strip, side: str, kind: str, s: float, u: float, length: float,
              depth: float, height: float) -> None:
    """Walls from 0.5 m below the lowest ground of the footprint, and a roof: a gable over
    a house, a slab with an overhang on the others."""
    ground = st.b.traj.ground_at(np.array([s - length / 2, s, s + length / 2]))
    z0 = float(ground.min() - ground[1]) - 0.5
    if kind == "block":
        height = 3.0 * round(height / 3.0)  # whole floors of 3 m
    top = st.box(PartKind.BUILDING, side, s, u, (length, depth, height - z0), z0)
    xyz, heading = st.place(s, u)
    if kind != "house":
        st.box(PartKind.ROOF, side, s, u, (length + 0.4, depth + 0.4, 0.3), top - xyz[2])
        return
    rise, eave = st.rng.uniform(1.8, 3.0), 0.4
    ridge = np.array([np.cos(heading), np.sin(heading), 0.0])
    half = length / 2 + eave
    path = np.array([xyz - half * ridge, xyz + half * ridge])
    path[:, 2] = top
    across = np.tile(np.cross([0.0, 0.0, 1.0], ridge), (2, 1))
    w = depth / 2 + eave
    gable = np.array([[-w, 0.0], [w, 0.0], [0.0, rise]])
    st.put(PartKind.ROOF, side, meshes.sweep(gable, path, across, np.tile([0.0, 0.0, 1.0],
                                                                          (2, 1)),
                                             closed=True, caps=True))


def _tree(st: _Strip, side: str, s: float, u: float) -> None:
    """A trunk and a low-poly crown (an icosahedron, 20 faces)."""
    trunk = st.rng.uniform(1.5, 3.0)
    top = st.box(PartKind.TREE, side, s, u, (0.35, 0.35, trunk + 0.5), -0.5)
    radius = st.rng.uniform(1.5, 3.5)
    xyz, _ = st.place(s, u)
    crown = trimesh.creation.icosphere(subdivisions=0, radius=radius)
    vertices = crown.vertices * [1.0, 1.0, st.rng.uniform(0.9, 1.3)]
    vertices += [xyz[0], xyz[1], top + 0.7 * radius]
    # Faces unshared so each is flat; UVs in metres on the world's xz and yz planes.
    flat = vertices[crown.faces].reshape(-1, 3)
    uv = np.stack([flat[:, 0] + flat[:, 1], flat[:, 2]], axis=-1)
    st.put(PartKind.TREE, side, meshes._mesh(flat, np.arange(len(flat)).reshape(-1, 3), uv))


def _terrain(b: "_Builder", rng: np.random.Generator) -> trimesh.Trimesh:
    """A polar grid round the trajectory's middle: TERRAIN_DROP_M under the ground of the
    nearest centre-line point (so the ground strips hide its edge; none lies wholly under
    them), rising from HILLS_M[0] beyond the
    town's farthest point to a crest at HILLS_M[1] whose height varies smoothly round the
    ring, flat out to HILLS_M[2]; past that edge the renderer's sky shows."""
    traj, margin = b.traj, b.cfg.end_margin_m
    s = np.linspace(-margin, traj.total_length_m + margin, 64)
    line, _, _ = traj.frame(s)
    ground = traj.ground_at(s)
    centre = line[len(s) // 2, :2]
    reach = float(np.linalg.norm(line[:, :2] - centre, axis=1).max()) + TOWN_HALF_WIDTH_M
    inner = np.arange(0.0, reach + 1.0, 10.0)[1:]
    radii = np.concatenate([inner, reach + np.linspace(*HILLS_M[:2], 8), [reach + HILLS_M[2]]])
    angles = np.linspace(0.0, 2 * np.pi, 96, endpoint=False)
    # The crest: a few random harmonics round the ring, scaled into HILL_HEIGHT_M.
    k = np.arange(1, 7)[:, None]
    a, c = rng.normal(size=(2, 6, 1)) / k
    wave = (a * np.cos(k * angles) + c * np.sin(k * angles)).sum(axis=0)
    lo, hi = HILL_HEIGHT_M
    crest = lo + (hi - lo) * (wave - wave.min()) / max(float(np.ptp(wave)), 1e-9)
    rise = np.clip((radii - reach - HILLS_M[0]) / (HILLS_M[1] - HILLS_M[0]), 0.0, 1.0)
    rise = 0.5 - 0.5 * np.cos(np.pi * rise)  # smooth at both ends
    xy = centre + np.stack([np.outer(radii, np.cos(angles)), np.outer(radii, np.sin(angles))],
                           axis=-1)  # (rings, angles, 2)
    distance = np.linalg.norm(xy[:, :, None] - line[None, None, :, :2], axis=-1)
    nearest = np.argmin(distance, axis=-1)
    # Under a ground strip: nearer the centre line than its edge, less 2 m, between its ends.
    covered = ((distance.min(axis=-1) < TOWN_HALF_WIDTH_M - 2.0) & (nearest > 0)
               & (nearest < len(s) - 1)).reshape(-1)
    z = ground[nearest] - TERRAIN_DROP_M + rise[:, None] * crest[None, :]
    vertices = np.concatenate([xy, z[..., None]], axis=-1).reshape(-1, 3)
    rings, m = len(radii), len(angles)
    i, j = np.meshgrid(np.arange(rings - 1), np.arange(m), indexing="ij")
    p, q = i * m + j, i * m + (j + 1) % m  # this ring at angle j, j + 1
    faces = np.concatenate([np.stack([p, p + m, q + m], -1).reshape(-1, 3),
                            np.stack([p, q + m, q], -1).reshape(-1, 3)])
    # The hole at the centre (r < 10 m) lies under the ground strips; fill it with a fan.
    hole = np.stack([np.full(m - 2, 0), np.arange(1, m - 1), np.arange(2, m)], -1)
    faces = np.concatenate([hole, faces])
    # Triangles wholly under the strips are never seen, yet llvmpipe would rasterise them.
    faces = faces[~covered[faces].all(axis=1)]
    # ... and their vertices go with them: a vertex of no triangle has no normal (the glTF
    # validator refuses a zero one).
    used = np.unique(faces)
    renumber = np.full(len(vertices), -1)
    renumber[used] = np.arange(len(used))
    return meshes._mesh(vertices[used], renumber[faces], vertices[used, :2].copy())


def town(b: "_Builder", root_seed: int, env_index: int) -> None:
    """The town (module docstring): ground, then each strip's pieces, then the terrain."""
    half_deck = b.d.deck_width_m / 2
    shift = max(0.0, half_deck + DECK_CLEARANCE_M - ROAD_M[0])
    strips = _strips(b)
    for s0, s1, tag in strips:
        _ground_strip(b, s0, s1, tag, TOWN_HALF_WIDTH_M + shift)
    n = b.traj.n
    for s0, s1, tag in strips:
        viaduct = _viaduct_of(tag)
        item = viaduct if viaduct is not None else (n if tag == "start" else n + 1)
        st = _Strip(b, s0, s1, tag, shift, make_rng(root_seed, env_index, Stream.WORLD, item))
        if viaduct is not None:
            _under_deck(st, viaduct)
        for side, sign in (("l", 1.0), ("r", -1.0)):
            _roadside(st, side, sign)
            _vehicles(st, side, sign)
            _poles_and_wires(st, side, sign, last=tag == strips[-1][2])
            _lots(st, side, sign)
        st.add_parts()
    rng = make_rng(root_seed, env_index, Stream.WORLD, n + 2)
    b.add(f"{_WORD[Component.NONBRIDGE]}_terrain", PartKind.TERRAIN, None, _terrain(b, rng))
