"""Cameras of Section 3.4, as plain data (no GL).

Intrinsics K use the OpenCV convention: pixel (col, row) has its centre at integer coordinates
and the principal point is the image centre ((W - 1) / 2, (H - 1) / 2); fy = fx (square pixels)
with the 36 mm sensor spanning the image width. The pose is world-from-camera in pyrender's (and
Blender's) convention: the camera looks down its -z axis with +y up; world is z up.

Placement: at a uniform arc length along the trajectory, a uniform lateral offset within D of
the viaduct centre line ([cameras] placement = "within", the default; "at" puts it exactly D to
a random side) and a uniform height h above the ground there. Rotations are Blender XYZ Euler
angles: X in [pi/4, 3pi/4] (pi/2 looks horizontally), Y in [-pi/12, pi/12], and Z in
[-pi/2, pi/2] measured from the direction that points to the centre line. Cameras at member
faces ("faces", the inspection preset) need the environment's parts: glsynth.world.face_cameras.
"""

import math
from dataclasses import dataclass

import numpy as np

from glsynth.core.config import CameraConfig, RenderConfig
from glsynth.core.seeding import Stream, make_rng
from glsynth.world.trajectory import Trajectory


@dataclass(frozen=True)
class Camera:
    width: int
    height: int
    focal_mm: float
    sensor_mm: float
    pose: np.ndarray
    """4x4 world-from-camera, camera looking down -z."""
    znear: float
    zfar: float

    @property
    def fx(self) -> float:
        return self.focal_mm / self.sensor_mm * self.width

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, (self.width - 1) / 2],
                         [0.0, self.fx, (self.height - 1) / 2],
                         [0.0, 0.0, 1.0]])

    def projection(self) -> np.ndarray:
        """OpenGL clip-from-camera matrix for K, so that pixel centres land where K says."""
        w, h, n, f = self.width, self.height, self.znear, self.zfar
        K = self.K
        return np.array([
            [2 * K[0, 0] / w, 0.0, 1 - 2 * (K[0, 2] + 0.5) / w, 0.0],
            [0.0, 2 * K[1, 1] / h, 2 * (K[1, 2] + 0.5) / h - 1, 0.0],
            [0.0, 0.0, -(f + n) / (f - n), -2 * f * n / (f - n)],
            [0.0, 0.0, -1.0, 0.0]])

    def view(self) -> np.ndarray:
        """Camera-from-world."""
        return np.linalg.inv(self.pose)

    def rays(self) -> tuple[np.ndarray, np.ndarray]:
        """World origin and per-pixel world directions scaled so that depth = ray parameter
        (unit length along the optical axis), shape (H, W, 3)."""
        K = self.K
        cols, rows = np.meshgrid(np.arange(self.width), np.arange(self.height))
        cam = np.stack([(cols - K[0, 2]) / K[0, 0], -(rows - K[1, 2]) / K[1, 1],
                        -np.ones(cols.shape)], axis=-1)
        return self.pose[:3, 3].copy(), cam @ self.pose[:3, :3].T

    def to_json(self) -> dict:
        return {"K": self.K.tolist(), "pose": self.pose.tolist(), "focal_mm": self.focal_mm,
                "sensor_mm": self.sensor_mm, "width": self.width, "height": self.height,
                "znear": self.znear, "zfar": self.zfar,
                "convention": "K: OpenCV pixel centres; pose: world-from-camera, camera looks "
                              "down -z, +y up (pyrender); world z up"}


def euler_xyz(x: float, y: float, z: float) -> np.ndarray:
    """Blender's XYZ Euler rotation: R = Rz @ Ry @ Rx."""
    cx, sx, cy, sy, cz, sz = math.cos(x), math.sin(x), math.cos(y), math.sin(y), \
        math.cos(z), math.sin(z)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def euler_from_matrix(r: np.ndarray) -> tuple[float, float, float]:
    """Blender XYZ Euler angles (x, y, z) of a rotation, the inverse of ``euler_xyz`` for
    |y| < pi/2."""
    return (math.atan2(r[2, 1], r[2, 2]), math.asin(-max(-1.0, min(1.0, r[2, 0]))),
            math.atan2(r[1, 0], r[0, 0]))


@dataclass(frozen=True)
class FaceAim:
    """What a camera under [cameras] placement = "faces" aims at (glsynth.world.face_cameras)."""

    member: str
    """The part's name: a column, or a cross or tie beam."""
    face: str
    """The face in the member's mesh frame: "+x", "-x", "+y", "-y" or "-z" (a beam's soffit)."""
    point: tuple[float, float, float]
    """The aimed point on the face, world metres: the optical axis passes through it."""
    distance_m: float
    """From the camera to the point, along the optical axis."""
    angle_deg: float
    """Between the optical axis and the face's normal."""
    roll_deg: float
    """About the optical axis, from level (the image's x axis horizontal)."""
    tries: int
    """Draws it took to find a clear view (1: the first)."""
    crack_width_mm: float | None = None
    """Under [cameras] face_crack_share, the width of the crack at the aimed point, for a
    camera aimed at a crack; else None."""

    def to_json(self) -> dict:
        return {"member": self.member, "face": self.face, "point": list(self.point),
                "distance_m": self.distance_m, "angle_deg": self.angle_deg,
                "roll_deg": self.roll_deg, "tries": self.tries,
                "crack_width_mm": self.crack_width_mm}


@dataclass(frozen=True)
class CameraPlacement:
    """The sampled values behind one camera (recorded in per-image metadata)."""

    index: int
    kind: str
    """'regular' or 'closeup'."""
    s_m: float
    side: int
    """+1: left of the centre line, -1: right."""
    distance_m: float
    """Horizontal distance from the centre line."""
    height_m: float
    """The sampled h, above the world origin or the ground ([cameras] height_from)."""
    euler_xyz_rad: tuple[float, float, float]
    """Z relative to the direction that points to the centre line."""
    camera: Camera
    face: FaceAim | None = None
    """Under placement = "faces", what the camera aims at; else None."""


def sample_camera(traj: Trajectory, cameras: CameraConfig, render: RenderConfig,
                  index: int, rng: np.random.Generator) -> CameraPlacement:
    """Camera ``index``: the first n_regular are regular, the next n_closeup close-up."""
    total = cameras.total
    if not 0 <= index < total:
        raise ValueError(f"camera index = {index}: must be in [0, {total - 1}] "
                         f"({cameras.n_regular} regular + {cameras.n_closeup} close-up)")
    if cameras.placement == "faces":
        raise ValueError('placement = "faces" needs the environment\'s parts: use '
                         "glsynth.world.face_cameras.place_camera")
    regular = index < cameras.n_regular
    distance = cameras.regular_distance_m if regular else cameras.closeup_distance_m
    h_range = cameras.regular_height_m if regular else cameras.closeup_height_m
    focal = rng.uniform(*cameras.focal_mm)
    s = rng.uniform(0.0, traj.total_length_m)
    if cameras.placement == "within":
        lateral = rng.uniform(-distance, distance)
        side = 1 if lateral >= 0 else -1
        distance = abs(lateral)
    else:
        side = 1 if rng.random() < 0.5 else -1
    h = rng.uniform(*h_range)
    rx, ry, rz = (math.radians(rng.uniform(*r)) for r in
                  (cameras.rot_x_deg, cameras.rot_y_deg, cameras.rot_z_deg))
    point, _, normal = traj.frame(np.array([s]))
    position = point[0] + side * distance * normal[0]
    position[2] = h if cameras.height_from == "origin" else traj.ground_at(np.array([s]))[0] + h
    to_line = -side * normal[0]
    azimuth = math.atan2(to_line[1], to_line[0])
    # Blender's camera at Z = 0 (and X = pi/2) looks along +y, i.e. azimuth pi/2.
    pose = np.eye(4)
    pose[:3, :3] = euler_xyz(rx, ry, azimuth - math.pi / 2 + rz)
    pose[:3, 3] = position
    camera = Camera(render.width, render.height, float(focal), cameras.sensor_mm, pose,
                    render.znear_m, render.zfar_m)
    return CameraPlacement(index, "regular" if regular else "closeup", float(s), side,
                           distance, float(h), (rx, ry, rz), camera)


def environment_camera(traj: Trajectory, cameras: CameraConfig, render: RenderConfig,
                       root_seed: int, env: int, index: int) -> CameraPlacement:
    """Camera ``index`` of environment ``env``; its own generator, so it is reproducible alone."""
    return sample_camera(traj, cameras, render, index,
                         make_rng(root_seed, env, Stream.CAMERAS, index))
