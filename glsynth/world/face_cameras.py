"""Close-range inspection cameras at member faces ([cameras] placement = "faces"; the paper's
future work iv, issue 29; docs/design.md, "Inspection preset").

Each camera draws, from its own generator (Stream.CAMERAS, item = its index):
1. its focal length, uniform in [cameras] focal_mm, and, where [cameras] face_crack_share is
   above 0, whether it aims at a crack (with that probability; never where the environment
   has no crack on an inspected face);
2. a face of a member, with probability proportional to the face's area: the four lateral
   faces of every column and, of every cross and tie beam, the two sides and the soffit (a
   beam's top lies under the slab or is seen only from above the deck). The girders are left
   out, though mechanics cracks them too (glsynth.appearance.girder_cracks): they are swept
   along the curved track, not boxes, so each of their flat pieces would be a face of its
   own. Views among the viaducts see their sides and soffit;
3. a point uniform on the face, at least 5 cm (or a quarter of the face) from its edges. A
   camera aiming at a crack draws steps 2-3 together instead: a point on the cracks of
   inspected faces, drawn by the area each piece of crack opens on the face (its length
   times its width: an inspector photographs the cracks that show, CrackAims), and the face
   that holds it;
4. a direction within face_angle_deg of the face's normal, uniform in solid angle, and a
   distance along it, log-uniform in face_distance_m (each doubling of the distance is as
   likely: an inspector's photos range from a crack's width at a few decimetres to a whole
   face at metres, and what a photo resolves scales with the distance). A camera aiming at
   a crack, where face_crack_px is above 0, stands no farther than makes the crack's width at
   the point span that many pixels (as an inspector steps close enough to read a crack's
   width; at face_distance_m's near end where even that is too far). The camera stands
   there and looks at the point, held upright (its image rows horizontal) and then rolled
   uniformly within face_roll_deg.
The draw is kept when the point is the first surface on the camera's optical axis, the camera
is inside no solid part and stands at least GROUND_CLEARANCE_M above the ground; else steps
2-4 are drawn again, at most MAX_TRIES times. So the camera never starts inside a part, and
its centre pixel shows the member.

Where [cameras] face_foot_share is above 0, a camera not aimed at a crack aims at a column's
foot with that probability, drawn from a generator of its own (Stream.FOOT_VIEWS), so that no
other camera's draws change. It draws steps 2-3 as a column face, by its width (each column
has one foot, whatever its height), and a point uniform across it on the line where the ground
in front of it meets it; in step 4 a direction below level is mirrored to above it, and the
point is raised up the face by FOOT_FRAME of half the height the view spans there. The view
takes in the wall's foot and the ground before it, where the soil, growth and debris lie that
an inspector's photographs of a hinge zone show.
"""

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from glsynth.core.config import CameraConfig, RenderConfig
from glsynth.core.errors import UserError
from glsynth.core.geometry import transform_points
from glsynth.core.seeding import Stream, make_rng
from glsynth.world.cameras import (
    Camera,
    CameraPlacement,
    FaceAim,
    environment_camera,
    euler_from_matrix,
)
from glsynth.world.environment import BOX_BEAMS, OPEN_KINDS, Environment, Part, PartKind
from glsynth.world.trajectory import Trajectory
from glsynth.world.visibility import part_boxes, ray_hits, ray_meets_boxes

MAX_TRIES = 200
"""Draws of a face, point and direction before a camera gives up (an error: a viaduct
environment needs a few at most)."""
GROUND_CLEARANCE_M = 0.2
"""Least height of a camera above the ground below it (a hand-held or pole-mounted camera)."""
HIT_TOLERANCE_M = 1e-6
"""A ray's hit this near the aimed point is the point itself."""
EDGE_MARGIN_M = 0.05
FOOT_FRAME = (0.2, 0.8)
"""A foot view's aimed point stands above the ground line by this share (uniform) of half the
height its view spans at its distance: the ground fills the lower part of the frame."""
FOOT_GROUND_M = 0.05
"""The ground under a foot view's point is found this far in front of the face."""
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
    if part.kind is PartKind.COLUMN:
        return [(0, 1), (0, -1), (1, 1), (1, -1)]
    if part.kind in BOX_BEAMS:
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
        long_axis = rotation[:, 2] if part.kind is PartKind.COLUMN else \
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
        solid = np.array([p.kind not in OPEN_KINDS for p in parts])
        ground = np.array([p.kind is PartKind.GROUND for p in parts])
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

    def ground_below(self, point: np.ndarray) -> np.ndarray:
        """How far below ``point`` the ground lies, at every crossing (empty where none)."""
        under = self.ground & np.all((self.lo[:, :2] <= point[:2])
                                     & (point[:2] <= self.hi[:, :2]), axis=1)
        heights = [ray_hits(self.parts[i], point, -_UP) for i in np.flatnonzero(under)]
        return np.concatenate(heights) if heights else np.empty(0)

    def above_ground(self, camera: np.ndarray) -> bool:
        """Whether the ground lies at least GROUND_CLEARANCE_M below the camera."""
        heights = self.ground_below(camera)
        return heights.size > 0 and float(heights.min()) >= GROUND_CLEARANCE_M


def _face_point(face: MemberFace, rng: np.random.Generator) -> np.ndarray:
    """Step 3: a point uniform on ``face``, EDGE_MARGIN_M (or a quarter of it) from its edges."""
    offsets = [rng.uniform(-1.0, 1.0) * max(h - min(EDGE_MARGIN_M, h / 2), 0.0)
               for h in face.half_extents]
    return face.centre + offsets[0] * face.tangents[0] + offsets[1] * face.tangents[1]


def _upright(face: MemberFace) -> tuple[int, int]:
    """The indices of a column face's tangent along its height and of the one across it."""
    v = int(abs(face.tangents[1] @ _UP) > abs(face.tangents[0] @ _UP))
    return v, 1 - v


def _up_the_face(face: MemberFace) -> tuple[np.ndarray, float]:
    """A column face's tangent that points up, and half the face's extent along it."""
    v, _ = _upright(face)
    return face.tangents[v] * np.sign(face.tangents[v] @ _UP), face.half_extents[v]


def _foot_point(face: MemberFace, scene: _Scene, rng: np.random.Generator
                ) -> np.ndarray | None:
    """A foot view's point on column face ``face`` before it is raised: uniform across the
    face (EDGE_MARGIN_M from its edges), where the ground in front of it meets it; None where
    no ground lies under the face's top there or the ground is off the face (a column
    standing on a beam)."""
    up, half_up = _up_the_face(face)
    _, h = _upright(face)
    half = face.half_extents[h]
    across = rng.uniform(-1.0, 1.0) * max(half - min(EDGE_MARGIN_M, half / 2), 0.0)
    top = face.centre + across * face.tangents[h] + half_up * up
    below = scene.ground_below(top + FOOT_GROUND_M * face.normal)
    if not below.size:
        return None
    along = float(below.min()) / float(up @ _UP)  # down the face from its top
    return top - along * up if 0.0 <= along <= 2.0 * half_up else None


def _raised(face: MemberFace, point: np.ndarray, distance: float, focal_mm: float,
            cameras: CameraConfig, render: RenderConfig, rng: np.random.Generator
            ) -> np.ndarray | None:
    """A foot view's ``point`` raised up the face by FOOT_FRAME of half the height a view
    from ``distance`` spans; None where that leaves the face."""
    up, half_up = _up_the_face(face)
    half_view = distance * cameras.sensor_mm * render.height / render.width / (2.0 * focal_mm)
    raised = point + float(rng.uniform(*FOOT_FRAME)) * half_view * up
    inside = half_up - min(EDGE_MARGIN_M, half_up / 2)  # as _face_point keeps off the edges
    return raised if float((raised - face.centre) @ up) <= inside else None


def _view(face: MemberFace, cameras: CameraConfig, far: float, rng: np.random.Generator
          ) -> tuple[np.ndarray, float, float, float]:
    """Step 4 for a point on ``face``: the unit direction from it to the camera, the distance
    (log-uniform from face_distance_m's near end to ``far``, or the near end where ``far`` is
    nearer), the angle to the normal (degrees) and the roll (degrees)."""
    cos_theta = rng.uniform(math.cos(math.radians(cameras.face_angle_deg)), 1.0)
    phi = rng.uniform(0.0, 2 * math.pi)
    sin_theta = math.sqrt(max(0.0, 1.0 - cos_theta ** 2))
    out = cos_theta * face.normal + sin_theta * (math.cos(phi) * face.tangents[0]
                                                 + math.sin(phi) * face.tangents[1])
    near = cameras.face_distance_m[0]
    distance = near * (max(far, near) / near) ** rng.uniform()  # exactly near where far is
    roll = rng.uniform(-cameras.face_roll_deg, cameras.face_roll_deg)
    angle = math.degrees(math.acos(min(1.0, cos_theta)))
    return out / np.linalg.norm(out), float(distance), angle, float(roll)


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
class CrackAims:
    """The crack segments on inspected faces that cameras may aim at, in world metres."""

    segments: np.ndarray
    """(N, 2, 3) end points."""
    widths_m: np.ndarray
    """(N, 2) the crack's width at each end point."""
    faces: np.ndarray
    """(N,) int: the face (index into FaceTargets.faces) that holds each segment."""
    weights: np.ndarray
    """(N,) each segment's share of the area the cracks open (length x mean width): an
    inspector's eye and camera go to the cracks that show (why not by length: docs/design.md,
    "Inspection preset")."""

    def draw(self, rng: np.random.Generator) -> tuple[int, np.ndarray, float]:
        """A face, an open end of a segment drawn by its area (the cracks' vertices: a rough
        crack's path strays from its segments between them, docs/design.md "Crack paths", and
        passes through them; a crack's tip, of width 0, is not aimed at), and the width
        there."""
        k = int(rng.choice(len(self.weights), p=self.weights))
        (a, b), (wa, wb), end = self.segments[k], self.widths_m[k], int(rng.integers(2))
        t = float(end if (wa, wb)[end] > 0 else 1 - end)
        return int(self.faces[k]), a + t * (b - a), float(wa + t * (wb - wa))


ON_FACE_M = 1e-6
"""A crack segment whose midpoint lies this near a face's plane, within its extent, is on it."""


Cracks = Mapping[str, tuple[np.ndarray, np.ndarray]]
"""Crack segments by member name: end points (N, 2, 3) in its mesh frame, and the widths at
them (N, 2) in metres."""


def crack_aims(parts: Sequence[Part], faces: list[MemberFace], cracks: Cracks
               ) -> CrackAims | None:
    """The segments of ``cracks`` that lie on an inspected face, in world metres, with their
    faces; None where there are none (or none open: every width 0)."""
    index = {p.name: i for i, p in enumerate(parts)}
    kept, widths, owners = [], [], []
    for name, (local, width) in cracks.items():
        mine = [k for k, f in enumerate(faces) if f.part == index.get(name)]
        if not mine or not len(local):
            continue
        pose = parts[index[name]].pose
        world = transform_points(pose, local)
        rel = world.mean(axis=1)[:, None, :] - np.array([faces[k].centre for k in mine])
        normal = np.array([faces[k].normal for k in mine])
        tangents = np.array([faces[k].tangents for k in mine])  # (F, 2, 3)
        half = np.array([faces[k].half_extents for k in mine])
        off = np.abs(np.einsum("nfc,fc->nf", rel, normal))
        inside = np.all(np.abs(np.einsum("nfc,ftc->nft", rel, tangents)) <= half + ON_FACE_M, 2)
        off = np.where(inside, off, np.inf)
        best = np.argmin(off, axis=1)
        on = off[np.arange(len(best)), best] <= ON_FACE_M
        kept.append(world[on])
        widths.append(width[on])
        owners.append(np.array(mine)[best[on]])
    if not kept:
        return None
    segments = np.concatenate(kept)
    widths = np.concatenate(widths)
    area = np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1) * widths.mean(axis=1)
    if not area.sum() > 0:
        return None
    return CrackAims(segments, widths, np.concatenate(owners), area / area.sum())


@dataclass(frozen=True)
class FaceTargets:
    """An environment's member faces and what the sight-line tests need, made once for all
    its cameras."""

    env: Environment
    faces: list[MemberFace]
    weights: np.ndarray
    """Each face's probability: its share of the faces' area."""
    scene: _Scene
    cracks: CrackAims | None = None
    feet: np.ndarray | None = None
    """The column faces foot views aim at (indices into ``faces``); None where there are none."""
    foot_weights: np.ndarray | None = None
    """Each of ``feet``'s probability: its share of their widths."""

    @classmethod
    def of(cls, env: Environment, cracks: Cracks | None = None) -> "FaceTargets":
        """``cracks``: the environment's crack segments per member, in its mesh frame (for
        [cameras] face_crack_share)."""
        faces = member_faces(env.parts)
        if not faces:
            raise UserError('[cameras] placement = "faces": the environment has no column or '
                            "cross or tie beam to aim at")
        area = np.array([f.area for f in faces])
        aims = crack_aims(env.parts, faces, cracks) if cracks else None
        feet = np.array([i for i, f in enumerate(faces)
                         if env.parts[f.part].kind is PartKind.COLUMN], int)
        width = np.array([faces[i].half_extents[_upright(faces[i])[1]] for i in feet])
        return cls(env, faces, area / area.sum(), _Scene.of(env.parts), aims,
                   feet if feet.size else None, width / width.sum() if feet.size else None)

    def draw(self, on_crack: bool, foot: bool, rng: np.random.Generator
             ) -> tuple[MemberFace, np.ndarray | None, float | None]:
        """Steps 2-3: a face, a point on it (None where a foot view's draw found no foot), and
        the crack's width there (None off cracks)."""
        if on_crack and self.cracks is not None:
            face, point, width = self.cracks.draw(rng)
            return self.faces[face], point, width
        if foot and self.feet is not None:
            face = self.faces[int(self.feet[rng.choice(len(self.feet), p=self.foot_weights)])]
            return face, _foot_point(face, self.scene, rng), None
        face = self.faces[int(rng.choice(len(self.faces), p=self.weights))]
        return face, _face_point(face, rng), None


def face_camera(targets: FaceTargets, cameras: CameraConfig, render: RenderConfig, index: int,
                rng: np.random.Generator, foot_rng: np.random.Generator) -> CameraPlacement:
    """Camera ``index`` aimed at a member face, drawn from ``rng`` (the module's steps), and
    whether it is a foot view from ``foot_rng``."""
    focal = float(rng.uniform(*cameras.focal_mm))
    on_crack = bool(cameras.face_crack_share) and rng.random() < cameras.face_crack_share
    foot = (not on_crack and bool(cameras.face_foot_share)
            and foot_rng.random() < cameras.face_foot_share)
    for tries in range(1, MAX_TRIES + 1):
        face, point, width = targets.draw(on_crack, foot, rng)
        if point is None:
            continue
        far = cameras.face_distance_m[1]
        if width is not None and cameras.face_crack_px:
            far = min(far, width * focal / cameras.sensor_mm * render.width
                      / cameras.face_crack_px)
        out, distance, angle, roll = _view(face, cameras, far, rng)
        if foot:
            if out[2] < 0.0:  # from level or above: the ground lies before the foot
                out = out - 2.0 * out[2] * _UP
            point = _raised(face, point, distance, focal, cameras, render, rng)
            if point is None:
                continue
        position = point + distance * out
        if targets.scene.above_ground(position) and targets.scene.clear_view(
                face.part, position, point, distance):
            pose = aim_pose(position, point, roll, face.long_axis)
            camera = Camera(render.width, render.height, focal, cameras.sensor_mm, pose,
                            render.znear_m, render.zfar_m)
            aim = FaceAim(face.member, face.label, tuple(float(v) for v in point), distance,
                          angle, roll, tries, None if width is None else width * 1e3)
            return _placement(targets.env.trajectory, cameras, index, camera, aim)
    raise UserError(f"camera {index} of environment {targets.env.env_index}: no clear view of a "
                    f"member face in {MAX_TRIES} draws; widen [cameras] face_distance_m or "
                    "face_angle_deg")


def place_cameras(env: Environment, cameras: CameraConfig, render: RenderConfig,
                  indices: Sequence[int], cracks: Cracks | None = None
                  ) -> list[CameraPlacement]:
    """Cameras ``indices`` of environment ``env`` by [cameras] placement, each from its own
    generator (so each is reproducible alone). ``cracks``: the environment's crack segments,
    which [cameras] face_crack_share aims at (every crack, seen or not:
    glsynth.appearance.dressing.crack_segments)."""
    for index in indices:
        if not 0 <= index < cameras.total:
            raise ValueError(f"camera index = {index}: must be in [0, {cameras.total - 1}]")
    if cameras.placement != "faces":
        return [environment_camera(env.trajectory, cameras, render, env.root_seed,
                                   env.env_index, i) for i in indices]
    if cameras.face_crack_share and cracks is None:
        raise ValueError("face_crack_share > 0: pass the environment's cracks")
    targets = FaceTargets.of(env, cracks if cameras.face_crack_share else None)
    return [face_camera(targets, cameras, render, i,
                        make_rng(env.root_seed, env.env_index, Stream.CAMERAS, i),
                        make_rng(env.root_seed, env.env_index, Stream.FOOT_VIEWS, i))
            for i in indices]


def place_camera(env: Environment, cameras: CameraConfig, render: RenderConfig,
                 index: int, cracks: Cracks | None = None) -> CameraPlacement:
    """Camera ``index`` of environment ``env`` (``place_cameras`` for one)."""
    return place_cameras(env, cameras, render, [index], cracks)[0]
