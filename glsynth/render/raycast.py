"""Ground truth independent of GL: Embree ray casts through each pixel centre of a camera.

Depth is the hit's distance along the optical axis, the component that of the part hit, and
the damage id the part's damage mask at the hit's interpolated UV, sampled as GL samples it
(nearest texel, repeating, UV (0, 0) at the image's bottom-left corner), and 1 outside the
material's damage zones where it has them (cracks are not cast). Used by the test
suite and by ``glsynth bench quality`` as the accuracy reference of the rasterizer.
"""

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import trimesh

from glsynth.appearance.materials import Material
from glsynth.core.errors import UserError
from glsynth.core.labels import Component, Damage
from glsynth.world.cameras import Camera
from glsynth.world.environment import Part


@dataclass(frozen=True)
class RayCastTruth:
    """Per-pixel ground truth of one camera, in the renderer's conventions but from its own
    code: this module imports nothing of glsynth.render.gl."""

    component: np.ndarray
    """(H, W) uint8 component ids; Nonbridge where nothing is hit."""
    damage: np.ndarray
    """(H, W) uint8 damage ids; no damage where nothing is hit."""
    depth: np.ndarray
    """(H, W) float32 metres along the optical axis; zfar where nothing is hit."""


def _intersector(mesh: trimesh.Trimesh):
    try:
        from trimesh.ray.ray_pyembree import RayMeshIntersector
    except ImportError as err:  # trimesh's pure-Python fallback would take minutes per view
        raise UserError("ray-cast ground truth needs Embree: pip install embreex "
                           "(in glsynth's test and bench extras)") from err
    return RayMeshIntersector(mesh)


def mask_lookup(mask: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Damage ids at UVs (N, 2) by GL's nearest, repeating lookup of a mask uploaded flipped."""
    h, w = mask.shape
    col = np.floor(uv[:, 0] * w).astype(np.int64) % w
    row = np.floor(uv[:, 1] * h).astype(np.int64) % h
    return mask[h - 1 - row, col]


def ray_cast(parts: Sequence[Part], materials: Mapping[str, Material],
             camera: Camera) -> RayCastTruth:
    """Component, damage and depth at every pixel centre (depth zfar where nothing is hit)."""
    faces_per_part = [len(p.mesh.faces) for p in parts]
    scene = trimesh.util.concatenate([trimesh.Trimesh(p.world_vertices(), p.mesh.faces,
                                                      process=False) for p in parts])
    owner = np.repeat(np.arange(len(parts)), faces_per_part)
    first_face = np.concatenate([[0], np.cumsum(faces_per_part)])
    origin, dirs = camera.rays()
    d = dirs.reshape(-1, 3)
    tri, ray, loc = _intersector(scene).intersects_id(
        np.repeat(origin[None], len(d), 0), d, multiple_hits=False, return_locations=True)
    depth = np.full(len(d), camera.zfar, np.float64)
    comp = np.full(len(d), int(Component.NONBRIDGE), np.uint8)
    damage = np.full(len(d), int(Damage.NO_DAMAGE), np.uint8)
    # Ray parameter along directions of unit axial length = depth along the optical axis.
    depth[ray] = np.einsum("ij,ij->i", loc - origin, d[ray]) / np.einsum("ij,ij->i", d[ray],
                                                                         d[ray])
    hit_part = owner[tri]
    comp[ray] = np.array([int(p.component) for p in parts], np.uint8)[hit_part]
    # Hits grouped by part (one sort), so each damage mask is looked up once for its hits.
    order = np.argsort(hit_part, kind="stable")
    bounds = np.searchsorted(hit_part[order], np.arange(len(parts) + 1))
    for i, part in enumerate(parts):
        hits = order[bounds[i]:bounds[i + 1]]
        if not hits.size:
            continue  # before reading the material: a deferred one is built on each read
        material = materials[part.name]
        if material.damage_mask is None:
            continue
        bary = trimesh.triangles.points_to_barycentric(scene.triangles[tri[hits]], loc[hits])
        face_uv = part.mesh.visual.uv[part.mesh.faces[tri[hits] - first_face[i]]]
        uv = np.einsum("nk,nkj->nj", bary, face_uv)
        ids = mask_lookup(material.damage_mask, uv * material.uv_scale)
        if material.zones is not None:
            local = np.einsum("nk,nkj->nj", bary,
                              part.mesh.vertices[part.mesh.faces[tri[hits] - first_face[i]]])
            ids = np.where(material.zones.contains(local[:, 2]), ids, Damage.NO_DAMAGE)
        damage[ray[hits]] = ids
    h, w = camera.height, camera.width
    return RayCastTruth(component=comp.reshape(h, w), damage=damage.reshape(h, w),
                        depth=depth.reshape(h, w).astype(np.float32))
