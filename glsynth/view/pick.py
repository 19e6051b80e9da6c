"""Which part a pixel shows: a ray cast through the pixel centre against the environment's
parts (the renderer draws component ids, not part ids). Pure numpy: boxes first, then the
Moller-Trumbore test on the triangles of the parts whose boxes the ray crosses."""

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from glsynth.world.cameras import Camera
from glsynth.world.environment import Part


@dataclass(frozen=True)
class Hit:
    part: str
    depth_m: float
    """Along the optical axis, as the depth pass measures it."""


class PartPicker:
    """The parts of one environment, with their world boxes computed once."""

    def __init__(self, parts: Sequence[Part]) -> None:
        self.parts = list(parts)
        corners = [p.world_vertices() for p in self.parts]
        self.low = np.array([c.min(axis=0) for c in corners])
        self.high = np.array([c.max(axis=0) for c in corners])

    def _crossed_boxes(self, origin: np.ndarray, direction: np.ndarray) -> np.ndarray:
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / direction
            t1, t2 = (self.low - origin) * inv, (self.high - origin) * inv
        near = np.nanmax(np.minimum(t1, t2), axis=1)
        far = np.nanmin(np.maximum(t1, t2), axis=1)
        order = np.argsort(near)
        return order[(far[order] >= np.maximum(near[order], 0.0))]

    def pick(self, camera: Camera, col: float, row: float) -> Hit | None:
        """The nearest part along the ray through pixel (col, row) (OpenCV pixel centres)."""
        K = camera.K
        local = np.array([(col - K[0, 2]) / K[0, 0], -(row - K[1, 2]) / K[1, 1], -1.0])
        direction = camera.pose[:3, :3] @ local  # unit length along the optical axis
        origin = camera.pose[:3, 3]
        best: Hit | None = None
        for i in self._crossed_boxes(origin, direction):
            t = _nearest_triangle(self.parts[i], origin, direction)
            if t is not None and t >= camera.znear and (best is None or t < best.depth_m):
                best = Hit(self.parts[i].name, float(t))
        return best


def _nearest_triangle(part: Part, origin: np.ndarray, direction: np.ndarray) -> float | None:
    """Ray parameter of the nearest triangle of ``part`` the ray hits (Moller-Trumbore)."""
    tri = part.world_vertices()[part.mesh.faces]
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    p = np.cross(direction, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-12
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = origin - tri[:, 0]
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    v = (q @ direction) * inv
    t = np.einsum("ij,ij->i", e2, q) * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
    return float(t[hit].min()) if hit.any() else None
