"""Close-range inspection cameras at member faces ([cameras] placement = "faces"; the paper's
future work iv, issue 29; docs/design.md, "Inspection preset").

Each camera draws, from its own generator (Stream.CAMERAS, item = its index):
1. its focal length, uniform in [cameras] focal_mm;
2. a face of a member, with probability proportional to the face's area: the four lateral
   faces of every column and, of every cross and tie beam, the two sides and the soffit (the
   members that [damage] model = "mechanics" cracks; a beam's top lies under the slab or is
   seen only from above the deck). The girders are left out, though mechanics cracks them too
   (glsynth.appearance.girder_cracks): they are swept along the curved track, not boxes, so
   each of their flat pieces would be a face of its own, and adding them would change every
   camera the inspection preset draws. Views among the viaducts see their sides and soffit;
3. a point uniform on the face, at least 5 cm (or a quarter of the face) from its edges;
4. a direction within face_angle_deg of the face's normal, uniform in solid angle, and a
   distance along it, uniform in face_distance_m: the camera stands there and looks at the
   point, held upright (its image rows horizontal) and then rolled uniformly within
   face_roll_deg.
The draw is kept when the point is the first surface on the camera's optical axis, the camera
is inside no solid part and stands at least GROUND_CLEARANCE_M above the ground; else steps
2-4 are drawn again, at most MAX_TRIES times. So the camera never starts inside a part, and
its centre pixel shows the member.
"""

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from glsynth.core.config import CameraConfig, RenderConfig
from glsynth.core.errors import UserError
from glsynth.core.seeding import Stream, make_rng
from glsynth.world.cameras import (
    Camera,
    CameraPlacement,
    FaceAim,
    environment_camera,
    euler_from_matrix,
)
from glsynth.world.environment import Environment, Part
from glsynth.world.trajectory import Trajectory
from glsynth.world.visibility import part_boxes, ray_hits, ray_meets_boxes

MAX_TRIES = 200
"""Draws of a face, point and direction before a camera gives up (an error: a viaduct
environment needs a few at most)."""
GROUND_CLEARANCE_M = 0.2
"""Least height of a camera above the ground below it (a hand-held or pole-mounted camera)."""
OPEN_SURFACES = ("ground_", "scene_")
"""Name prefixes of the parts that are open surfaces; every other part is a closed solid."""
HIT_TOLERANCE_M = 1e-6
"""A ray's hit this near the aimed point is the point itself."""
EDGE_MARGIN_M = 0.05
_UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class MemberFace:
    """One face of a box member, in world coordinates."""

    part: int
    """Index into the environment's parts."""
    member: str
    label: str
    """"+x", "-x", "+y", "-y" or "-z" in the member's mesh frame."""
    centre: np.ndarray
    normal: np.ndarray
    """Outward unit normal."""
    tangents: tuple[np.ndarray, np.ndarray]
    half_extents: tuple[float, float]
    """Half the face's size along each tangent."""
    long_axis: np.ndarray
    """The member's axis (a column's vertical, a beam's span)."""

    @property
    def area(self) -> float:
        return 4.0 * self.half_extents[0] * self.half_extents[1]


def _face_axes(part: Part) -> list[tuple[int, int]] | None:
    """(axis, sign) of a member's inspected faces in its mesh frame; None for other parts."""
    if part.name.startswith("column_"):
        return [(0, 1), (0, -1), (1, 1), (1, -1)]
    if part.name.startswith("beam_") and ("_cross_" in part.name or "_tie_" in part.name):
        across = 1 - int(np.argmax(part.mesh.extents[:2]))
        return [(across, 1), (across, -1), (2, -1)]
    return None


def member_faces(parts: tuple[Part, ...] | list[Part]) -> list[MemberFace]:
    """The faces cameras may aim at, of every column and cross and tie beam (boxes)."""
    faces = []
    for index, part in enumerate(parts):
        axes = _face_axes(part)
        if axes is None:
            continue
        rotation, extents = part.pose[:3, :3], part.mesh.extents
        centre = part.pose[:3, :3] @ part.mesh.bounds.mean(axis=0) + part.pose[:3, 3]
        long_axis = rotation[:, 2] if part.name.startswith("column_") else \
            rotation[:, int(np.argmax(extents[:2]))]
        for axis, sign in axes:
            t1, t2 = (a for a in range(3) if a != axis)
            faces.append(MemberFace(
                index, part.name, f"{'+' if sign > 0 else '-'}{'xyz'[axis]}",
                centre + sign * extents[axis] / 2 * rotation[:, axis], sign * rotation[:, axis],
                (rotation[:, t1], rotation[:, t2]), (extents[t1] / 2, extents[t2] / 2),
                long_axis))
    return faces


@dataclass(frozen=True)
class _Scene:
    """What the sight-line tests need of an environment's parts."""

    parts: tuple[Part, ...]
    lo: np.ndarray
    hi: np.ndarray
    solid: np.ndarray
    """(P,) whether each part is a closed solid."""
    ground: np.ndarray
    """(P,) whether each part is the ground."""

    @classmethod
    def of(cls, parts: tuple[Part, ...]) -> "_Scene":
        lo, hi = part_boxes(parts)
        solid = np.array([not p.name.startswith(OPEN_SURFACES) for p in parts])
        ground = np.array([p.name.startswith("ground_") for p in parts])
        return cls(parts, lo, hi, solid, ground)

    def clear_view(self, member: int, camera: np.ndarray, point: np.ndarray,
                   distance: float) -> bool:
        """Whether ``point`` on part ``member`` is the first surface seen from ``camera`` along
        the line to it, and the camera is inside no solid part."""
        direction = (point - camera) / distance
        near = ray_meets_boxes(self.lo, self.hi, camera, direction, distance + HIT_TOLERANCE_M)
        enclosing = self.solid & np.all((self.lo <= camera) & (camera <= self.hi), axis=1)
        seen = False
        for i in np.flatnonzero(near | enclosing):
            t = ray_hits(self.parts[i], camera, direction)
            if t.size and t[0] < distance - HIT_TOLERANCE_M:
                return False  # something in front of the point
            if enclosing[i] and t.size % 2:
                return False  # odd crossings of a closed surface: the camera is inside it
            seen |= i == member and bool(np.any(np.abs(t - distance) <= HIT_TOLERANCE_M))
        return seen

    def above_ground(self, camera: np.ndarray) -> bool:
        """Whether the ground lies at least GROUND_CLEARANCE_M below the camera."""
        under = self.ground & np.all((self.lo[:, :2] <= camera[:2])
                                     & (camera[:2] <= self.hi[:, :2]), axis=1)
        heights = [ray_hits(self.parts[i], camera, -_UP) for i in np.flatnonzero(under)]
        heights = np.concatenate(heights) if heights else np.empty(0)
        return heights.size > 0 and float(heights.min()) >= GROUND_CLEARANCE_M


def _draw(face: MemberFace, cameras: CameraConfig, rng: np.random.Generator
          ) -> tuple[np.ndarray, np.ndarray, float, float, float]:
    """Steps 3-4 for one face: the point, the unit direction from it to the camera, the
    distance, the angle to the normal (degrees) and the roll (degrees)."""
    offsets = [rng.uniform(-1.0, 1.0) * max(h - min(EDGE_MARGIN_M, h / 2), 0.0)
               for h in face.half_extents]
    point = face.centre + offsets[0] * face.tangents[0] + offsets[1] * face.tangents[1]
    cos_theta = rng.uniform(math.cos(math.radians(cameras.face_angle_deg)), 1.0)
    phi = rng.uniform(0.0, 2 * math.pi)
    sin_theta = math.sqrt(max(0.0, 1.0 - cos_theta ** 2))
    out = cos_theta * face.normal + sin_theta * (math.cos(phi) * face.tangents[0]
                                                 + math.sin(phi) * face.tangents[1])
    distance = rng.uniform(*cameras.face_distance_m)
    roll = rng.uniform(-cameras.face_roll_deg, cameras.face_roll_deg)
    angle = math.degrees(math.acos(min(1.0, cos_theta)))
    return point, out / np.linalg.norm(out), float(distance), angle, float(roll)


def aim_pose(position: np.ndarray, point: np.ndarray, roll_deg: float,
             level_axis: np.ndarray) -> np.ndarray:
    """World-from-camera looking from ``position`` at ``point`` (-z), its x axis horizontal
    and then rolled by ``roll_deg`` about the optical axis. Looking straight up or down, x
    runs along ``level_axis``."""
    forward = (point - position) / np.linalg.norm(point - position)
    right = np.cross(forward, _UP)
    if np.linalg.norm(right) < 1e-9:
        right = level_axis - (level_axis @ forward) * forward
    right /= np.linalg.norm(right)
    up = np.cross(-forward, right)
    c, s = math.cos(math.radians(roll_deg)), math.sin(math.radians(roll_deg))
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2] = c * right + s * up, c * up - s * right, -forward
    pose[:3, 3] = position
    return pose


def _arc_length(traj: Trajectory, xy: np.ndarray) -> float:
    """Arc length of the centre-line point nearest ``xy``: a 0.5 m grid, then Newton steps."""
    grid = np.linspace(0.0, traj.total_length_m, int(traj.total_length_m / 0.5) + 1)
    points, _, _ = traj.frame(grid)
    s = float(grid[np.argmin(np.linalg.norm(points[:, :2] - xy, axis=1))])
    for _ in range(3):
        point, tangent, _ = traj.frame(np.array([s]))
        s += float((xy - point[0, :2]) @ tangent[0, :2])
    return s


def _placement(traj: Trajectory, cameras: CameraConfig, index: int, camera: Camera,
               aim: FaceAim) -> CameraPlacement:
    """The camera with Section 3.4's description of where it stands (arc length, side,
    distance from the centre line, height, Euler angles relative to the centre line)."""
    position = camera.pose[:3, 3]
    s = _arc_length(traj, position[:2])
    point, _, normal = traj.frame(np.array([s]))
    lateral = float((position[:2] - point[0, :2]) @ normal[0, :2])
    side = 1 if lateral >= 0 else -1
    base = 0.0 if cameras.height_from == "origin" else float(traj.ground_at(np.array([s]))[0])
    rx, ry, z = euler_from_matrix(camera.pose[:3, :3])
    to_line = -side * normal[0]
    rz = z - (math.atan2(to_line[1], to_line[0]) - math.pi / 2)
    rz = math.remainder(rz, 2 * math.pi)
    return CameraPlacement(index, "closeup", s, side, abs(lateral), float(position[2]) - base,
                           (rx, ry, rz), camera, aim)


@dataclass(frozen=True)
class FaceTargets:
    """An environment's member faces and what the sight-line tests need, made once for all
    its cameras."""

    env: Environment
    faces: list[MemberFace]
    weights: np.ndarray
    """Each face's probability: its share of the faces' area."""
    scene: _Scene

    @classmethod
    def of(cls, env: Environment) -> "FaceTargets":
        faces = member_faces(env.parts)
        if not faces:
            raise UserError('[cameras] placement = "faces": the environment has no column or '
                            "cross or tie beam to aim at")
        area = np.array([f.area for f in faces])
        return cls(env, faces, area / area.sum(), _Scene.of(env.parts))


def face_camera(targets: FaceTargets, cameras: CameraConfig, render: RenderConfig, index: int,
                rng: np.random.Generator) -> CameraPlacement:
    """Camera ``index`` aimed at a member face, drawn from ``rng`` (the module's steps)."""
    focal = float(rng.uniform(*cameras.focal_mm))
    for tries in range(1, MAX_TRIES + 1):
        face = targets.faces[int(rng.choice(len(targets.faces), p=targets.weights))]
        point, out, distance, angle, roll = _draw(face, cameras, rng)
        position = point + distance * out
        if targets.scene.above_ground(position) and targets.scene.clear_view(
                face.part, position, point, distance):
            pose = aim_pose(position, point, roll, face.long_axis)
            camera = Camera(render.width, render.height, focal, cameras.sensor_mm, pose,
                            render.znear_m, render.zfar_m)
            aim = FaceAim(face.member, face.label, tuple(float(v) for v in point), distance,
                          angle, roll, tries)
            return _placement(targets.env.trajectory, cameras, index, camera, aim)
    raise UserError(f"camera {index} of environment {targets.env.env_index}: no clear view of a "
                    f"member face in {MAX_TRIES} draws; widen [cameras] face_distance_m or "
                    "face_angle_deg")


def place_cameras(env: Environment, cameras: CameraConfig, render: RenderConfig,
                  indices: Sequence[int]) -> list[CameraPlacement]:
    """Cameras ``indices`` of environment ``env`` by [cameras] placement, each from its own
    generator (so each is reproducible alone)."""
    for index in indices:
        if not 0 <= index < cameras.total:
            raise ValueError(f"camera index = {index}: must be in [0, {cameras.total - 1}]")
    if cameras.placement != "faces":
        return [environment_camera(env.trajectory, cameras, render, env.root_seed,
                                   env.env_index, i) for i in indices]
    targets = FaceTargets.of(env)
    return [face_camera(targets, cameras, render, i,
                        make_rng(env.root_seed, env.env_index, Stream.CAMERAS, i))
            for i in indices]


def place_camera(env: Environment, cameras: CameraConfig, render: RenderConfig,
                 index: int) -> CameraPlacement:
    """Camera ``index`` of environment ``env`` (``place_cameras`` for one)."""
    return place_cameras(env, cameras, render, [index])[0]
