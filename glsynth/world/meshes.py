"""Small pure mesh constructors. UVs are in metres; texture scale is applied by materials.

Faces wind counter-clockwise seen from outside, so face normals point outwards. Meshes are made
with ``process=False`` so that vertices split at hard edges (and at UV seams) stay split.
"""

import numpy as np
import trimesh
from trimesh.visual import TextureVisuals

# Box faces: (normal axis, normal sign, u axis, u sign, v axis) with (u sign * u axis) x v axis =
# normal. On the four side faces v is +z, so texture "up" is world up (axial rebar runs up a
# column on every face).
_BOX_FACES = ((0, 1, 1, 1, 2), (0, -1, 1, -1, 2), (1, 1, 0, -1, 2), (1, -1, 0, 1, 2),
              (2, 1, 0, 1, 1), (2, -1, 0, -1, 1))


def _mesh(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray) -> trimesh.Trimesh:
    mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=False)
    mesh.visual = TextureVisuals(uv=uv)
    return mesh


def _box_arrays(extents: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    half = np.asarray(extents, dtype=float) / 2.0
    verts, faces, uvs = [], [], []
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float)
    for axis, sign, a, a_sign, b in _BOX_FACES:
        quad = np.zeros((4, 3))
        quad[:, axis] = sign * half[axis]
        quad[:, a] = a_sign * corners[:, 0] * half[a]
        quad[:, b] = corners[:, 1] * half[b]
        base = 4 * len(faces) // 2
        verts.append(quad)
        uvs.append((corners + 1.0) / 2.0 * [2 * half[a], 2 * half[b]])
        faces += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    return np.concatenate(verts), np.array(faces), np.concatenate(uvs)


def box(extents: tuple[float, float, float]) -> trimesh.Trimesh:
    """Axis-aligned box centred at the origin, 4 vertices per face, UVs in metres per face."""
    extents = np.asarray(extents, dtype=float)
    if extents.shape != (3,) or not np.all(np.isfinite(extents)) or np.any(extents <= 0):
        raise ValueError(f"extents = {extents!r}: must be three finite lengths > 0")
    return _mesh(*_box_arrays(extents))


def boxes(extents: tuple[float, float, float], poses: np.ndarray) -> trimesh.Trimesh:
    """Many equal boxes merged into one mesh, each placed by a 4x4 pose (e.g. sleepers)."""
    verts, faces, uv = _box_arrays(np.asarray(extents, dtype=float))
    poses = np.asarray(poses, dtype=float).reshape(-1, 4, 4)
    placed = verts @ poses[:, :3, :3].transpose(0, 2, 1) + poses[:, None, :3, 3]
    offsets = (np.arange(len(poses)) * len(verts))[:, None, None]
    return _mesh(placed.reshape(-1, 3), (faces[None] + offsets).reshape(-1, 3),
                 np.tile(uv, (len(poses), 1)))


def sweep(profile: np.ndarray, path: np.ndarray, across: np.ndarray, up: np.ndarray,
          *, closed: bool, smooth: bool = False, caps: bool = False) -> trimesh.Trimesh:
    """Sweep a 2D profile along a path.

    profile: (M, 2) points (a, b); a closed profile runs counter-clockwise in the (a, b) plane.
    path: (K, 3) points; across, up: (K, 3) unit vectors with across x up = path direction.
    A profile point (a, b) at path sample k lands at path[k] + a across[k] + b up[k].
    An open profile's faces face to the left of its direction of travel (rotate the edge by -90
    degrees in the (a, b) plane). smooth: share vertices between profile edges (cylinders);
    otherwise every profile edge is its own flat strip. caps: close both ends (convex profiles).
    UV: u = arc length along the path, v = length along the profile, both in metres.
    """
    profile = np.asarray(profile, dtype=float)
    path = np.asarray(path, dtype=float)
    if profile.ndim != 2 or profile.shape[1] != 2 or len(profile) < 2:
        raise ValueError(f"profile shape {profile.shape}: must be (M >= 2, 2)")
    if path.ndim != 2 or path.shape[1] != 3 or len(path) < 2:
        raise ValueError(f"path shape {path.shape}: must be (K >= 2, 3)")
    ring = np.vstack([profile, profile[:1]]) if closed else profile
    u = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
    v = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(ring, axis=0), axis=1))])
    k, m = len(path), len(ring)
    points = (path[:, None, :] + ring[None, :, :1] * across[:, None, :]
              + ring[None, :, 1:] * up[:, None, :])  # (K, M, 3)
    # Strips of quads between path samples, one per row of ``cols`` (its profile columns, in
    # consecutive pairs): one strip round a smooth profile, or one per edge of a flat-sided
    # one, all made at once (a strip at a time cost 7 % of a demo environment's build).
    cols = np.arange(m)[None] if smooth else np.stack([np.arange(m - 1), np.arange(1, m)], -1)
    g, c = cols.shape
    verts = [points[:, cols].transpose(1, 0, 2, 3).reshape(-1, 3)]
    uvs = [np.stack(np.broadcast_arrays(u[None, :, None], v[cols][:, None, :]), -1)
           .reshape(-1, 2)]
    i, j = np.meshgrid(np.arange(k - 1), np.arange(c - 1), indexing="ij")
    a = np.arange(g)[:, None, None] * (k * c) + i * c + j
    b, cc, d = a + 1, a + c + 1, a + c
    faces = [np.stack([np.stack([a, b, cc], -1), np.stack([a, cc, d], -1)], -2).reshape(-1, 3)]
    if caps:
        if not closed:
            raise ValueError("caps need a closed profile")
        n = len(profile)
        fan = np.stack([np.zeros(n - 2, int), np.arange(1, n - 1), np.arange(2, n)], -1)
        for end, order in ((0, fan[:, ::-1]), (k - 1, fan)):
            base = sum(len(x) for x in verts)
            verts.append(points[end, :n])
            uvs.append(profile - profile.min(axis=0))
            faces.append(order + base)
    return _mesh(np.concatenate(verts), np.concatenate(faces), np.concatenate(uvs))


def circle(radius: float, segments: int) -> np.ndarray:
    """Counter-clockwise polygon of ``segments`` points."""
    t = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    return radius * np.stack([np.cos(t), np.sin(t)], axis=-1)


def rectangle(a0: float, a1: float, b0: float, b1: float) -> np.ndarray:
    """Counter-clockwise rectangle [a0, a1] x [b0, b1] in the (a, b) plane."""
    return np.array([[a0, b0], [a1, b0], [a1, b1], [a0, b1]], dtype=float)


def pose(rotation_z: float, translation: np.ndarray) -> np.ndarray:
    """4x4 world-from-local: rotation about +z, then translation."""
    c, s = np.cos(rotation_z), np.sin(rotation_z)
    out = np.eye(4)
    out[:2, :2] = [[c, -s], [s, c]]
    out[:3, 3] = translation
    return out
