"""Which parts a set of cameras can see: a conservative frustum test, no GL.

A part is seen when its oriented bounding box is not entirely outside one of the camera's
frustum planes (near plane and the four image edges). Occlusion is ignored, so the answer may
include hidden parts but never misses a part that is in view. With shadows, the parts that
may shadow a view are needed as well (glsynth.world.sunlight).

Exact sight lines (the cameras at member faces, glsynth.world.face_cameras) are ray casts in
numpy: boxes first, then the triangles of the parts whose box a ray meets.
"""

import numpy as np

from glsynth.core.config import RenderConfig
from glsynth.core.geometry import transform_points
from glsynth.world.cameras import Camera
from glsynth.world.environment import Part, PartKind
from glsynth.world.lighting import Lighting, sky_directions
from glsynth.world.sunlight import shadow_casters

_CORNERS = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)


def box_corners(bounds: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """The 8 world-space corners (8, 3) of a box (2, 3) given in the frame ``pose``."""
    lo, hi = bounds
    local = lo + _CORNERS * (hi - lo)
    return transform_points(pose, local)


def part_corners(part: Part) -> np.ndarray:
    """The 8 world-space corners of the part's bounding box in its own frame (8, 3)."""
    return box_corners(part.mesh.bounds, part.pose)


def seen_by(corners: np.ndarray, camera: Camera, margin_px: float = 0.5) -> np.ndarray:
    """For point sets (P, M, 3) (a box's 8 corners), whether each may be in this camera's view
    (P,): not all of its points beyond one plane of the frustum, whose sides stand
    ``margin_px`` beyond the outermost pixel centres (0.5: the image's edges)."""
    view = camera.view()
    c = transform_points(view, corners)
    x, y, d = c[..., 0], c[..., 1], -c[..., 2]
    k, m = camera.K, margin_px
    planes = (d - camera.znear,                                     # in front of the near plane
              k[0, 0] * x + (k[0, 2] + m) * d,                      # right of the left edge
              (camera.width - 1 + m - k[0, 2]) * d - k[0, 0] * x,   # left of the right edge
              -k[1, 1] * y + (k[1, 2] + m) * d,                     # below the top edge
              (camera.height - 1 + m - k[1, 2]) * d + k[1, 1] * y)  # above the bottom edge
    outside = np.zeros(corners.shape[0], bool)
    for value in planes:
        outside |= np.all(value < 0, axis=1)
    return ~outside


def farthest_seen(corners: np.ndarray, camera: Camera) -> float:
    """The depth (along the axis, at most the far plane) of the farthest box corner among the
    boxes (P, 8, 3) that may be in this camera's view (seen_by); the near plane if none is."""
    seen = seen_by(corners, camera)
    if not seen.any():
        return camera.znear
    depth = -transform_points(camera.view(), corners[seen])[..., 2]
    return float(min(depth.max(), camera.zfar))


def in_clip_xy(corners: np.ndarray, clip_from_world: np.ndarray) -> np.ndarray:
    """For boxes (P, 8, 3), whether each is not wholly beyond one side of the clip volume of
    ``clip_from_world`` in x or y (P,); depth is not tested (the shadow pass clamps it)."""
    clip = transform_points(clip_from_world, corners)
    w = corners @ clip_from_world[3, :3] + clip_from_world[3, 3]
    outside = np.zeros(corners.shape[0], bool)
    for axis in (0, 1):
        outside |= np.all(clip[..., axis] < -w, axis=1) | np.all(clip[..., axis] > w, axis=1)
    return ~outside


def visible_parts(parts: tuple[Part, ...] | list[Part], cameras: list[Camera]) -> set[str]:
    corners = np.stack([part_corners(p) for p in parts])
    seen = np.zeros(len(parts), bool)
    for camera in cameras:
        seen |= seen_by(corners, camera)
    return {p.name for p, s in zip(parts, seen) if s}


def shadowing_parts(parts: tuple[Part, ...] | list[Part], cameras: list[Camera],
                    render: RenderConfig, lighting: Lighting) -> set[str]:
    """Parts that may cast the sun's shadow into some camera's view (with shadows and the sun
    above the horizon), or hide the sky from it along one of the sky-visibility directions
    (with those maps)."""
    corners = np.stack([part_corners(p) for p in parts])
    # The sun's shadow map reaches shadow_distance_m; the sky-visibility maps cover the
    # whole scene, so a part hiding the sky from any surface in view counts, as far as the
    # farthest part the camera may see.
    directions: list[tuple[np.ndarray, list[float]]] = []
    if render.shadow_map_px and lighting.sun_irradiance:
        directions.append((lighting.sun_direction, [render.shadow_distance_m] * len(cameras)))
    if render.sky_visibility_maps:
        # Beyond the maps' extent (the far terrain) a point reads open sky: no caster counts.
        mapped = corners[[p.kind is not PartKind.TERRAIN for p in parts]]
        farthest = [farthest_seen(mapped, camera) for camera in cameras]
        directions.extend((d, farthest) for d in sky_directions(render.sky_visibility_maps))
    casts = np.zeros(len(parts), bool)
    for direction, reach in directions:
        casts |= shadow_casters(corners, cameras, direction, reach)
    return {p.name for p, c in zip(parts, casts) if c}


def occlusion_extent(parts: tuple[Part, ...] | list[Part]) -> np.ndarray:
    """Corners (8 P, 3) of every part's box but the terrain's: what the sky-visibility maps
    are fitted to, so that they are the same whichever parts are uploaded. The terrain reaches
    hills 0.5 km and more away: fitted to it, a map's texel would grow fivefold over the
    viaduct, where the occlusion matters; the far land outside the maps counts as open."""
    return np.concatenate([part_corners(p) for p in parts if p.kind is not PartKind.TERRAIN])


def part_boxes(parts: tuple[Part, ...] | list[Part]) -> tuple[np.ndarray, np.ndarray]:
    """World axis-aligned bounds (P, 3) and (P, 3) of every part's box."""
    corners = np.stack([part_corners(p) for p in parts])
    return corners.min(axis=1), corners.max(axis=1)


def ray_meets_boxes(lo: np.ndarray, hi: np.ndarray, origin: np.ndarray,
                    direction: np.ndarray, t_max: float = np.inf) -> np.ndarray:
    """For boxes (P, 3) and (P, 3), whether the ray origin + t direction, 0 <= t <= t_max,
    meets each (P,): the slab test."""
    d = np.where(direction == 0, 1e-300, direction)  # a parallel ray: +-inf slab bounds
    t1, t2 = (lo - origin) / d, (hi - origin) / d
    t_in = np.minimum(t1, t2).max(axis=1)
    t_out = np.maximum(t1, t2).min(axis=1)
    return (t_out >= np.maximum(t_in, 0.0)) & (t_in <= t_max)


def ray_hits(part: Part, origin: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Ray parameters t > 0, sorted, of every crossing of the ray origin + t direction with
    the part's triangles (Moller-Trumbore; both sides of a triangle count)."""
    tri = part.world_vertices()[part.mesh.faces]
    v0, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    p = np.cross(direction, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-15
    inv = np.divide(1.0, det, out=np.zeros_like(det), where=ok)
    s = origin - v0
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    v = (q @ direction) * inv
    t = np.einsum("ij,ij->i", e2, q) * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
    return np.sort(t[hit])


def rays_meet_triangles(origin: np.ndarray, dirs: np.ndarray, tri: np.ndarray,
                        chunk: int = 2048) -> np.ndarray:
    """(N,) bool: whether each ray origin + t dirs[i], t > 0, crosses one of the triangles
    (T, 3, 3) (Moller-Trumbore, both sides; the triangles taken ``chunk`` at a time)."""
    met = np.zeros(len(dirs), bool)
    for start in range(0, len(tri), chunk):
        part = tri[start:start + chunk]
        v0, e1, e2 = part[:, 0], part[:, 1] - part[:, 0], part[:, 2] - part[:, 0]
        p = np.cross(dirs[:, None], e2[None])                        # (N, T, 3)
        det = np.einsum("tk,ntk->nt", e1, p)
        ok = np.abs(det) > 1e-15
        inv = np.divide(1.0, det, out=np.zeros_like(det), where=ok)
        s = origin - v0                                               # (T, 3)
        u = np.einsum("tk,ntk->nt", s, p) * inv
        q = np.cross(s, e1)                                           # (T, 3)
        v = (dirs @ q.T) * inv
        t = np.einsum("tk,tk->t", e2, q)[None] * inv
        met |= np.any(ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0), axis=1)
    return met


def in_frustum(a: np.ndarray, b: np.ndarray, camera: Camera, grow_m: float = 0.0
               ) -> np.ndarray:
    """(N,) False for the segments a-b (world, (N, 3) each) that lie wholly beyond one plane of
    the view's frustum (the near plane, or a side grown by 2 pixels): none of their points can
    land in the image. True for the rest (a conservative test). ``grow_m`` > 0 tests each
    segment's box grown by that much instead: for what strays from the segment (a rough
    crack's path)."""
    if grow_m > 0:
        lo, hi = np.minimum(a, b) - grow_m, np.maximum(a, b) + grow_m
        points = lo[:, None] + _CORNERS * (hi - lo)[:, None]
    else:
        points = np.stack([a, b], axis=1)
    return seen_by(points, camera, margin_px=2.5)
