"""The sun's shadow: the orthographic shadow-map frustum fitted to one camera. No GL.

The shadow map covers the part of the camera's view frustum nearer than
``[render] shadow_distance_m``; beyond it everything is lit. Its depth range is that part's
extent along the light only; the renderer draws with depth clamping, so casters on the sun
side of it (the slab above a column, a neighbouring viaduct) land at depth 0 and still shadow
it. The matrix thus depends on the camera alone, not on which parts were uploaded. Which parts
can cast a shadow into some camera's view is answered here as well, so that culling keeps them.
"""

import numpy as np

from glsynth.core.config import RenderConfig
from glsynth.core.geometry import transform_points
from glsynth.world.cameras import Camera


def light_frame(sun: np.ndarray) -> np.ndarray:
    """Rows (right, up, towards the sun): light-from-world rotation. A sun at the zenith takes
    +y as its up, since world z is then the viewing axis."""
    back = sun / np.linalg.norm(sun)
    helper = np.array([0.0, 0.0, 1.0]) if abs(back[2]) < 0.999 else np.array([0.0, 1.0, 0.0])
    right = np.cross(helper, back)
    right /= np.linalg.norm(right)
    return np.stack([right, np.cross(back, right), back])


def frustum_corners(camera: Camera, distance: float) -> np.ndarray:
    """World-space corners (8, 3) of the view frustum between the near plane and
    min(distance, zfar), through the outer edges of the corner pixels."""
    k = camera.K
    far = min(distance, camera.zfar)
    corners = []
    for d in (camera.znear, far):
        for col in (-0.5, camera.width - 0.5):
            for row in (-0.5, camera.height - 0.5):
                corners.append([(col - k[0, 2]) / k[0, 0] * d, -(row - k[1, 2]) / k[1, 1] * d,
                                -d])
    cam = np.array(corners)
    return transform_points(camera.pose, cam)


def _shadowed_box(camera: Camera, reach_m: float,
                  frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Light-space bounds (lo, hi) of the camera's view frustum up to ``reach_m``."""
    local = frustum_corners(camera, reach_m) @ frame.T
    return local.min(0), local.max(0)


def shadow_matrix(camera: Camera, render: RenderConfig, sun: np.ndarray) -> np.ndarray:
    """Clip-from-world orthographic matrix (4x4, float64) of the shadow map of the sun in world
    direction ``sun`` for this camera. Depth -1 is the sun side of the shadowed range, +1 its
    far side."""
    frame = light_frame(sun)
    lo, hi = _shadowed_box(camera, render.shadow_distance_m, frame)
    z_sun, z_far = hi[2] + 1.0, lo[2] - 1.0
    # Square texels: the shorter side of the footprint is widened to the longer one.
    half = max(hi[0] - lo[0], hi[1] - lo[1]) / 2 * 1.01 + 1e-3
    cx, cy = (lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2
    ortho = np.array([[1 / half, 0, 0, -cx / half],
                      [0, 1 / half, 0, -cy / half],
                      [0, 0, -2 / (z_sun - z_far), (z_sun + z_far) / (z_sun - z_far)],
                      [0, 0, 0, 1.0]])
    light = np.eye(4)
    light[:3, :3] = frame
    return ortho @ light


def shadow_texel_m(matrix: np.ndarray, size_px: int) -> float:
    """World size of one shadow-map texel."""
    return 2.0 / float(np.linalg.norm(matrix[0, :3])) / size_px


def shadow_casters(corners: np.ndarray, cameras: list[Camera], sun: np.ndarray,
                   reach_m: list[float]) -> np.ndarray:
    """For part boxes (P, 8, 3), whether each may cast a shadow along ``sun`` into some
    camera's view up to that camera's ``reach_m``: its light-space footprint overlaps the
    camera's, and it is not wholly on the far side of the camera's receivers (P,).
    Conservative, like the view test."""
    frame = light_frame(sun)
    local = corners @ frame.T
    p_lo, p_hi = local.min(1), local.max(1)
    casts = np.zeros(len(corners), bool)
    for camera, reach in zip(cameras, reach_m):
        lo, hi = _shadowed_box(camera, reach, frame)
        casts |= (np.all(p_hi[:, :2] >= lo[:2], axis=1) & np.all(p_lo[:, :2] <= hi[:2], axis=1)
                  & (p_hi[:, 2] >= lo[2]))
    return casts
