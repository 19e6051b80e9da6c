"""A member's mesh cut at its damage zones' ends (glsynth.appearance.materials.DamageZones),
for the renderers that take a material per primitive (glTF, and through it the Cycles twin):
the triangles inside the zones carry the damage material, the rest the member's intact
concrete, as the GL zone variants draw them (shaders/zones.glsl)."""

import numpy as np
import trimesh
from trimesh.intersections import slice_faces_plane
from trimesh.visual import TextureVisuals

from glsynth.appearance.materials import DamageZones, Material


def _merged(intervals: tuple[tuple[float, float], ...]) -> list[tuple[float, float]]:
    """The intervals' union as disjoint sorted intervals (a short span's two zones meet)."""
    out: list[tuple[float, float]] = []
    for z0, z1 in sorted(intervals):
        if out and z0 <= out[-1][1]:
            out[-1] = (out[-1][0], max(out[-1][1], z1))
        else:
            out.append((z0, z1))
    return out


def _band(mesh: trimesh.Trimesh, lo: float, hi: float) -> trimesh.Trimesh | None:
    """The part of ``mesh`` with lo <= z <= hi (either may be infinite), UVs interpolated
    along the cut edges."""
    vertices, faces = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    uv = np.asarray(mesh.visual.uv)
    for normal, origin in (((0.0, 0.0, 1.0), lo), ((0.0, 0.0, -1.0), hi)):
        if not np.isfinite(origin) or not len(faces):
            continue
        vertices, faces, uv = slice_faces_plane(vertices, faces, np.array(normal),
                                                np.array([0.0, 0.0, origin]), uv=uv)
    if not len(faces):
        return None
    piece = trimesh.Trimesh(vertices, faces, process=False)
    piece.visual = TextureVisuals(uv=uv)
    return piece


def zone_pieces(mesh: trimesh.Trimesh, zones: DamageZones
                ) -> tuple[list[trimesh.Trimesh], list[trimesh.Trimesh]]:
    """(pieces inside the zones, pieces outside them) of ``mesh`` (its own frame, z the
    member's axis), cut at the zones' ends."""
    inside = _merged(zones.intervals)
    ends = [-np.inf] + [z for zone in inside for z in zone] + [np.inf]
    outside = list(zip(ends[::2], ends[1::2]))
    cut = ([_band(mesh, *zone) for zone in inside], [_band(mesh, *gap) for gap in outside])
    return tuple([p for p in pieces if p is not None] for pieces in cut)


def intact_material(material: Material) -> Material:
    """The member's intact concrete outside ``material``'s zones: its own image at its own
    scale, the damage material's colour factor and roughness, no metal, no relief, no damage
    id (DamageZones)."""
    zones = material.zones
    return Material(base_color=material.base_color, roughness=material.roughness,
                    uv_scale=zones.intact_uv_scale, base_color_map=zones.intact_map)
