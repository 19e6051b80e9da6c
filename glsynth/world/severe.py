"""Severe column damage as geometry ([damage] geometry = true; docs/design.md, "Severe damage
as geometry").

A column whose drawn severity is "severe" loses cover and core concrete over a band near both
ends of each clear span: its box is cut into intact segments, and each band is a crushed
surface of reduced, irregular section (a CRUSHED part) around exposed reinforcement (a REBAR
part): longitudinal bars buckled outward between the band's ends and broken hoops pushed open.
The bands' sizes and shapes come from the SEVERE stream (item = the column's index in the
environment's part list); the severity is the dressing's own draw (the DAMAGE stream, same
item), made here again, before dressing, from the same generator. New parts are appended after
the environment's parts, one of each kind per severe column (tight bounds, so that a camera
beside a column is not taken to stand inside one), in their world frame.
"""

from dataclasses import dataclass, replace

import numpy as np
import trimesh
from trimesh.visual import TextureVisuals

from glsynth.core.config import Config, DamageConfig
from glsynth.core.geometry import transform_points
from glsynth.core.labels import Damage
from glsynth.core.seeding import Stream, make_rng
from glsynth.world import meshes
from glsynth.world.environment import Environment, Part, PartKind

DAMAGE_OF_KIND = {PartKind.CRUSHED: Damage.CONCRETE, PartKind.REBAR: Damage.REBAR}
"""The damage id every point of these parts carries (their materials' constant mask)."""

GAP_DEPTHS = (0.1, 0.3)
"""Intact concrete between a clear span's end and its crushed band, in section depths."""
LENGTH_DEPTHS = (0.6, 1.2)
"""A band's length in section depths: with the gap, within one to 1.5 depths of the end."""
CORE_LOSS_M = (0.03, 0.12)
"""Concrete lost beyond the bars' cover at a band's deepest point."""
RINGS = 7
"""Sections across a band (the first and last are the intact section)."""
POINTS_PER_SIDE = 6
BAR_SPACING_M = 0.2
"""Largest distance between neighbouring longitudinal bars along a face."""
BULGE_DIAMETERS = (1.0, 4.0)
"""How far a buckled bar bows outward at mid-band, in bar diameters."""
HOOP_RATIO = 0.5
"""A hoop's diameter over a longitudinal bar's (D13 around D25)."""
HOOP_BREAK = (0.15, 0.4)
"""The share of its perimeter a broken hoop has lost."""
HOOP_END_M = (0.03, 0.08)
"""How far a broken hoop's ends spring outward."""
BAR_SAMPLES = 5
"""Sections along a buckled bar."""
TUBE_SEGMENTS = 5
"""Facets around a bar or hoop (a few pixels wide in any view)."""


def column_damage_rng(root_seed: int, env_index: int, ordinal: int) -> np.random.Generator:
    """The generator of a column's damage record (severity first), item = its part index."""
    return make_rng(root_seed, env_index, Stream.DAMAGE, ordinal)


def draw_severity(cfg: DamageConfig, rng: np.random.Generator) -> str | None:
    """Section 3.3's draw: undamaged with [damage] undamaged_probability, else one of
    [damage] severities (all three under "paper")."""
    if rng.random() < cfg.undamaged_probability:
        return None
    return cfg.severities[int(rng.integers(len(cfg.severities)))]


def clear_spans(env: Environment, part: Part) -> list[tuple[float, float]]:
    """A column's clear spans, (z0, z1) in its mesh frame: from the ground to the underside of
    the cross beam, split by the tie beams where Table 3 has them."""
    viaduct = next(v for v in env.viaducts if v.index == part.viaduct)
    info = next(c for c in viaduct.columns if c.name == part.name)
    centre = (info.top_z + info.bottom_z) / 2
    z0, z1 = info.bottom_z - centre, info.top_z - env.config.design.embed_m - centre
    tie = next((p for p in env.parts if p.viaduct == part.viaduct
                and p.kind is PartKind.TIE_BEAM), None)
    if tie is None:
        return [(z0, z1)]
    middle, half = float(tie.pose[2, 3]) - centre, float(tie.mesh.extents[2]) / 2
    return [(z0, middle - half), (middle + half, z1)]


@dataclass(frozen=True)
class Band:
    """One crushed band of a column, in its mesh frame."""

    z0: float
    z1: float
    cover_m: float
    """Face to the longitudinal bars' centres."""
    loss_m: float
    """Concrete lost at the band's deepest point, from the face inward."""


def crushed_bands(cfg: DamageConfig, section: tuple[float, float],
                  spans: list[tuple[float, float]], rng: np.random.Generator) -> list[Band]:
    """A band at both ends of each clear span, sorted by z; a short span's two bands shrink
    so that they stay apart."""
    depth, thinnest = max(section), min(section)
    bar_r = cfg.bar_diameter_mm / 2000.0
    bands = []
    for z0, z1 in spans:
        for end, sign in ((z0, 1.0), (z1, -1.0)):
            gap = rng.uniform(*GAP_DEPTHS) * depth
            length = rng.uniform(*LENGTH_DEPTHS) * depth
            room = (z1 - z0) / 2 - 0.05
            fit = min(1.0, room / (gap + length))
            near, far = end + sign * gap * fit, end + sign * (gap + length) * fit
            cover = rng.uniform(*cfg.axial_cover_cm) / 100.0
            loss = min(cover + bar_r + rng.uniform(*CORE_LOSS_M), thinnest / 2 - 0.05)
            bands.append(Band(min(near, far), max(near, far), cover, loss))
    return sorted(bands, key=lambda b: b.z0)


def _mesh(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray) -> trimesh.Trimesh:
    mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=False)
    mesh.visual = TextureVisuals(uv=uv)
    return mesh


def _segment(section: tuple[float, float], height: float, z0: float, z1: float,
             bottom_cap: bool, top_cap: bool) -> trimesh.Trimesh:
    """The column box between z0 and z1 with the UVs the whole box has there (a side's v runs
    from the column's foot), without the caps that face a band (the crushed surface meets the
    box's edge there)."""
    piece = meshes.box((section[0], section[1], z1 - z0))
    vertices = piece.vertices + [0.0, 0.0, (z0 + z1) / 2]
    uv = piece.visual.uv.copy()
    uv[:16, 1] += z0 + height / 2  # the four sides come first in meshes.box
    keep = np.ones(len(piece.faces), bool)
    keep[8:10], keep[10:12] = top_cap, bottom_cap  # then +z, then -z
    faces = piece.faces[keep]
    used, faces = np.unique(faces, return_inverse=True)
    return _mesh(vertices[used], faces.reshape(-1, 3), uv[used])


def cut_column(mesh: trimesh.Trimesh, bands: list[Band]) -> trimesh.Trimesh:
    """A column's box (centred at the origin) with ``bands`` taken out: its intact segments."""
    a, b, height = (float(e) for e in mesh.extents)
    cuts = [-height / 2] + [z for band in bands for z in (band.z0, band.z1)] + [height / 2]
    pieces = [_segment((a, b), height, cuts[k], cuts[k + 1], k == 0, k == len(cuts) - 2)
              for k in range(0, len(cuts), 2)]
    return trimesh.util.concatenate(pieces)


def _perimeter(a: float, b: float) -> tuple[np.ndarray, np.ndarray]:
    """POINTS_PER_SIDE points per side of the a x b rectangle, counter-clockwise from +z and
    starting at a corner, and the arc length at each (one more: back at the start)."""
    corners = np.array([[-a, -b], [a, -b], [a, b], [-a, b], [-a, -b]]) / 2
    t = np.arange(POINTS_PER_SIDE) / POINTS_PER_SIDE
    points = np.concatenate([c0 + t[:, None] * (c1 - c0)
                             for c0, c1 in zip(corners[:-1], corners[1:])])
    ring = np.vstack([points, points[:1]])
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(ring, axis=0), axis=1))])
    return points, arc


def crushed_surface(section: tuple[float, float], band: Band, rng: np.random.Generator
                    ) -> trimesh.Trimesh:
    """The band's surface: RINGS sections from the intact rectangle at both ends to one cut
    back by up to ``band.loss_m`` in between, irregularly (each point its own depth)."""
    a, b = section
    points, arc = _perimeter(a, b)
    t = np.linspace(0.0, 1.0, RINGS)
    envelope = np.sqrt(np.sin(np.pi * t))[:, None]  # blunt: most of the band is deep
    inset = band.loss_m * envelope * rng.uniform(0.55, 1.0, (RINGS, len(points)))
    half = np.array([a, b]) / 2
    limit = half[None, None, :] - inset[..., None]
    xy = np.clip(points[None], -limit, limit)  # each point moves in from the face(s) it is on
    xy = np.concatenate([xy, xy[:, :1]], axis=1)  # the seam: u runs on to the full perimeter
    z = band.z0 + t * (band.z1 - band.z0)
    m = xy.shape[1]
    vertices = np.concatenate([xy, np.broadcast_to(z[:, None, None], (RINGS, m, 1))], axis=2)
    uv = np.stack(np.broadcast_arrays(arc[None, :], z[:, None]), axis=-1)
    k, j = np.meshgrid(np.arange(RINGS - 1), np.arange(m - 1), indexing="ij")
    p = (k * m + j).ravel()
    faces = np.concatenate([np.stack([p, p + 1, p + m + 1], -1),
                            np.stack([p, p + m + 1, p + m], -1)])
    return _mesh(vertices.reshape(-1, 3), faces, uv.reshape(-1, 2))


def tubes(paths: list[np.ndarray], hints: list[np.ndarray], radius: float) -> trimesh.Trimesh:
    """Capped tubes of ``radius`` along ``paths`` (each (K, 3)), each ring's profile turned by
    its ``hints`` row, as meshes.sweep makes them (smooth, UVs in metres), merged into one
    mesh; the paths of one length are swept together (vectorised)."""
    pieces = []
    for k in sorted({len(p) for p in paths}):
        chosen = [i for i, p in enumerate(paths) if len(p) == k]
        pieces.append(_tubes_of_length(np.stack([paths[i] for i in chosen]),
                                       np.stack([hints[i] for i in chosen]), radius))
    return trimesh.util.concatenate(pieces)


def _tubes_of_length(path: np.ndarray, hint: np.ndarray, radius: float) -> trimesh.Trimesh:
    """N tubes along paths (N, K, 3) of one length: meshes.sweep's layout for one, its
    vertices and UVs computed for all at once."""
    n, k = path.shape[:2]
    profile = meshes.circle(radius, TUBE_SEGMENTS)
    direction = np.gradient(path, axis=1)
    direction /= np.linalg.norm(direction, axis=-1, keepdims=True)
    up = hint - np.sum(hint * direction, axis=-1, keepdims=True) * direction
    up /= np.linalg.norm(up, axis=-1, keepdims=True)
    across = np.cross(up, direction)  # across x up = direction, as meshes.sweep wants
    template = meshes.sweep(profile, path[0], across[0], up[0], closed=True, smooth=True,
                            caps=True)
    ring = np.vstack([profile, profile[:1]])
    points = (path[:, :, None] + ring[None, None, :, :1] * across[:, :, None]
              + ring[None, None, :, 1:] * up[:, :, None])  # (N, K, S + 1, 3)
    vertices = np.concatenate([points.reshape(n, -1, 3), points[:, 0, :-1],
                               points[:, -1, :-1]], axis=1)
    arc = np.concatenate([np.zeros((n, 1)), np.cumsum(
        np.linalg.norm(np.diff(path, axis=1), axis=-1), axis=1)], axis=1)
    side_uv = np.stack(np.broadcast_arrays(arc[:, :, None], template.visual.uv[None, None,
                       :ring.shape[0], 1]), -1).reshape(n, -1, 2)
    uv = np.concatenate([side_uv, np.broadcast_to(template.visual.uv[k * len(ring):],
                                                  (n, 2 * len(profile), 2))], axis=1)
    per = len(template.vertices)
    faces = (template.faces[None] + per * np.arange(n)[:, None, None]).reshape(-1, 3)
    return _mesh(vertices.reshape(-1, 3), faces, uv.reshape(-1, 2))


def _bar_seats(section: tuple[float, float], inset: float) -> tuple[np.ndarray, np.ndarray]:
    """Longitudinal bars' (x, y) on the rectangle ``inset`` in from the faces, corners
    included, at most BAR_SPACING_M apart, and each bar's outward direction."""
    half = np.array(section) / 2 - inset
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1], [-1, -1]]) * half
    seats, outward = [], []
    for c0, c1 in zip(corners[:-1], corners[1:]):
        n = max(1, int(np.ceil(np.linalg.norm(c1 - c0) / BAR_SPACING_M)))
        side = c0 + np.arange(n)[:, None] / n * (c1 - c0)
        normal = np.array([(c1 - c0)[1], -(c1 - c0)[0]]) / np.linalg.norm(c1 - c0)
        seats.append(side)
        outward.append(np.tile(normal, (n, 1)))
        outward[-1][0] = np.sign(c0) / np.sqrt(2.0)  # a corner bar bows out diagonally
    return np.concatenate(seats), np.concatenate(outward)


def buckled_bars(cfg: DamageConfig, section: tuple[float, float], band: Band,
                 rng: np.random.Generator) -> list[tuple[np.ndarray, np.ndarray]]:
    """Every longitudinal bar through the band, bowed outward by its own drawn amount at
    mid-band, as (path, profile hint) for ``tubes``; its ends stay in the intact concrete."""
    seats, outward = _bar_seats(section, band.cover_m)
    radius = cfg.bar_diameter_mm / 2000.0
    t = np.linspace(0.0, 1.0, BAR_SAMPLES)
    z = band.z0 + t * (band.z1 - band.z0)
    bars = []
    for seat, out in zip(seats, outward):
        bulge = rng.uniform(*BULGE_DIAMETERS) * 2 * radius * np.sin(np.pi * t)
        xy = seat[None] + bulge[:, None] * out[None]
        path = np.column_stack([xy, z])
        bars.append((path, np.tile([out[0], out[1], 0.0], (BAR_SAMPLES, 1))))
    return bars


def _rectangle_point(half: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points at arc lengths ``p`` (mod the perimeter) round the rectangle of half sizes
    ``half``, counter-clockwise from (-x, -y), and their outward normals."""
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * half
    normals = np.array([[0.0, -1.0], [1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]])
    sides = np.array([2 * half[0], 2 * half[1], 2 * half[0], 2 * half[1]])
    starts = np.concatenate([[0.0], np.cumsum(sides)[:-1]])
    p = np.mod(p, sides.sum())
    k = np.minimum(np.searchsorted(starts, p, side="right") - 1, 3)
    direction = (np.roll(corners, -1, axis=0) - corners) / sides[:, None]
    return corners[k] + (p - starts[k])[:, None] * direction[k], normals[k]


def broken_hoops(cfg: DamageConfig, section: tuple[float, float], band: Band,
                 bulge_m: float, rng: np.random.Generator
                 ) -> list[tuple[np.ndarray, np.ndarray]]:
    """The hoops in the band at a drawn spacing, outside the bars, pushed out with them by up
    to ``bulge_m`` at mid-band, each with a drawn share of its perimeter gone and its two
    broken ends sprung outward, as (path, profile hint) for ``tubes``."""
    bar_r = cfg.bar_diameter_mm / 2000.0
    radius = HOOP_RATIO * bar_r
    spacing = rng.uniform(*cfg.stirrup_spacing_m)
    heights = np.arange(band.z0 + spacing / 2, band.z1, spacing)
    hoops = []
    for z in heights:
        push = bulge_m * np.sin(np.pi * (z - band.z0) / (band.z1 - band.z0))
        half = np.array(section) / 2 - band.cover_m + bar_r + radius + push
        perimeter = 4 * half.sum()
        start = rng.uniform(0.0, perimeter)
        end = start + (1.0 - rng.uniform(*HOOP_BREAK)) * perimeter
        starts = np.concatenate([[0.0], np.cumsum([2 * half[0], 2 * half[1]] * 2)])
        turns = np.concatenate([starts, starts + perimeter])
        p = np.unique(np.concatenate([[start, end], turns[(turns > start + 1e-3)
                                                         & (turns < end - 1e-3)]]))
        xy, normal = _rectangle_point(half, p)
        spring = rng.uniform(*HOOP_END_M, 2)
        xy = np.vstack([xy[:1] + spring[0] * normal[:1], xy, xy[-1:] + spring[1] * normal[-1:]])
        path = np.column_stack([xy, np.full(len(xy), z)])
        hoops.append((path, np.tile([0.0, 0.0, 1.0], (len(path), 1))))
    return hoops


def _placed(mesh: trimesh.Trimesh, pose: np.ndarray) -> trimesh.Trimesh:
    return _mesh(transform_points(pose, mesh.vertices), mesh.faces, mesh.visual.uv)


def severe_column(config: Config, part: Part, spans: list[tuple[float, float]],
                  rng: np.random.Generator
                  ) -> tuple[trimesh.Trimesh, trimesh.Trimesh, trimesh.Trimesh]:
    """A severe column's cut box (its mesh frame) and its crushed surface and exposed
    reinforcement (world frame)."""
    cfg = config.damage
    section = (float(part.mesh.extents[0]), float(part.mesh.extents[1]))
    bands = crushed_bands(cfg, section, spans, rng)
    crushed, bars, hoops = [], [], []
    bulge = float(np.mean(BULGE_DIAMETERS)) * cfg.bar_diameter_mm / 1000.0
    for band in bands:
        crushed.append(crushed_surface(section, band, rng))
        bars += buckled_bars(cfg, section, band, rng)
        hoops += broken_hoops(cfg, section, band, bulge, rng)
    bar_r = cfg.bar_diameter_mm / 2000.0
    steel = [tubes([path for path, _ in group], [hint for _, hint in group], radius)
             for group, radius in ((bars, bar_r), (hoops, HOOP_RATIO * bar_r)) if group]
    return (cut_column(part.mesh, bands),
            _placed(trimesh.util.concatenate(crushed), part.pose),
            _placed(trimesh.util.concatenate(steel), part.pose))


def with_severe_damage(env: Environment) -> Environment:
    """``env`` with every severe column cut at its bands and a CRUSHED and a REBAR part per
    severe column appended (in the order of the columns)."""
    parts, added = list(env.parts), []
    count: dict[int, int] = {}
    for ordinal, part in enumerate(env.parts):
        if part.kind is not PartKind.COLUMN or draw_severity(
                env.config.damage, column_damage_rng(env.root_seed, env.env_index,
                                                     ordinal)) != "severe":
            continue
        rng = make_rng(env.root_seed, env.env_index, Stream.SEVERE, ordinal)
        column, crushed, steel = severe_column(env.config, part, clear_spans(env, part), rng)
        parts[ordinal] = replace(part, mesh=column)
        k = count[part.viaduct] = count.get(part.viaduct, -1) + 1
        tag = f"column_v{part.viaduct:02d}"  # named as the component's parts are
        added += [Part(f"{tag}_crushed_{k}", PartKind.CRUSHED, part.viaduct, crushed,
                       np.eye(4)),
                  Part(f"{tag}_rebar_{k}", PartKind.REBAR, part.viaduct, steel, np.eye(4))]
    return replace(env, parts=tuple(parts + added))
