"""Inspection flights ([flight]; glsynth fly): camera paths around a column, along a viaduct's
side and under its deck, and their validation against the environment's meshes. No GL.

In every plan the camera moves along its image x axis (sideways to what it looks at), so the
overlap of consecutive frames is set by the spacing along the path:

    footprint_m = standoff_m * sensor_mm / focal_mm        (the image width at the stand-off)
    spacing_m   = (1 - forward_overlap_pct / 100) * footprint_m

and, for a facade's rows, the image height at the stand-off (sensor height = sensor width x
H / W) with the side overlap. For an orbit the spacing is measured along the camera's circle:
a point of the column's face, nearer than the axis the camera turns about, moves less in the
image than on a straight path, so the overlap there is at least the one asked for.

A frame's time is its distance along the path over [flight] speed_mps; a plan whose frames
come faster than [flight] frame_rate_hz is refused, as are plans that come within
[flight] clearance_m of a mesh, fly below the ground or start inside a part.
"""

import math
from dataclasses import dataclass

import numpy as np
import trimesh

from glsynth.core.config import Config, FlightConfig
from glsynth.core.errors import UserError
from glsynth.core.geometry import segment_distance
from glsynth.world.cameras import Camera
from glsynth.world.environment import ColumnInfo, Environment, Part, ground_parts


@dataclass(frozen=True)
class FlightPlan:
    """Waypoints in flight order: one camera pose per frame."""

    plan: str
    poses: np.ndarray
    """(N, 4, 4) world-from-camera, camera looking down -z, +y up (as glsynth's Camera)."""
    times_s: np.ndarray
    """(N,) time of each frame from the start."""
    spacing_m: float
    """Distance between consecutive frames along the path (the overlap formula's)."""
    focal_mm: float

    def __len__(self) -> int:
        return len(self.poses)

    def cameras(self, config: Config) -> list[Camera]:
        r = config.render
        return [Camera(r.width, r.height, self.focal_mm, config.cameras.sensor_mm, pose,
                       r.znear_m, r.zfar_m) for pose in self.poses]


def footprint_m(standoff_m: float, sensor_mm: float, focal_mm: float) -> float:
    """Width covered by an image extent of ``sensor_mm`` at the stand-off (pinhole)."""
    return standoff_m * sensor_mm / focal_mm


def frame_spacing_m(flight: FlightConfig, sensor_mm: float) -> float:
    """Distance along the path between frames for the forward overlap."""
    return (1 - flight.forward_overlap_pct / 100) * footprint_m(
        flight.standoff_m, sensor_mm, flight.focal_mm)


def sensor_height_mm(config: Config) -> float:
    """The sensor's height: [cameras] sensor_mm wide, in [render]'s aspect."""
    return config.cameras.sensor_mm * config.render.height / config.render.width


def ring_overlap_pct(flight: FlightConfig, sensor_h_mm: float) -> list[float]:
    """An orbit's consecutive rings: how much of the image height at the stand-off each pair
    shares (0 where they leave a gap). [flight] heights_m places the rings; side_overlap_pct
    spaces a facade's rows only, so this says what the heights give."""
    tall = footprint_m(flight.standoff_m, sensor_h_mm, flight.focal_mm)
    steps = np.abs(np.diff(flight.heights_m))
    return [round(max(0.0, 100.0 * (1.0 - float(d) / tall)), 1) for d in steps]


def look_pose(position: np.ndarray, yaw: float, pitch: float) -> np.ndarray:
    """World-from-camera looking along azimuth ``yaw`` (from +x, counter-clockwise) tilted up
    by ``pitch``, image x horizontal: camera x = (sin yaw, -cos yaw, 0)."""
    forward = np.array([math.cos(pitch) * math.cos(yaw), math.cos(pitch) * math.sin(yaw),
                        math.sin(pitch)])
    right = np.array([math.sin(yaw), -math.cos(yaw), 0.0])
    back = -forward
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2] = right, np.cross(back, right), back
    pose[:3, 3] = position
    return pose


MAX_PLAN_FRAMES = 100_000
"""The most waypoints a flight plan may have (about a day of rendering at 1 s a frame): a
plan is counted before its poses are made, so a tiny spacing is refused at once."""


def check_plan_size(frames: int | float, spacing: float, fix: str) -> None:
    """Refuse, before any pose is made, a plan of more than MAX_PLAN_FRAMES waypoints."""
    if frames > MAX_PLAN_FRAMES:
        raise UserError(f"[flight] plan: {frames:,.0f} frames {spacing:.3g} m apart, more than "
                        f"the {MAX_PLAN_FRAMES:,} a plan may have; {fix}")


def _steps(length: float, spacing: float, closed: bool, repeats: int = 1) -> np.ndarray:
    """Fractions in [0, 1] of a path of ``length``: at most ``spacing`` apart; a closed path
    leaves out its end (the start again); a path of length 0 has one. Refused where the path,
    flown ``repeats`` times, would take more than MAX_PLAN_FRAMES frames."""
    if length <= 0:
        return np.zeros(1)
    n = max(1.0, math.ceil(length / spacing - 1e-9))
    check_plan_size(repeats * (n if closed else n + 1), spacing,
                    "lower forward_overlap_pct or shorten the path in [flight]")
    n = int(n)
    return np.arange(n) / n if closed else np.arange(n + 1) / n


def environment_columns(env: Environment) -> list[ColumnInfo]:
    return [c for v in env.viaducts for c in v.columns]


def _orbit(env: Environment, flight: FlightConfig, spacing: float) -> list[np.ndarray]:
    columns = environment_columns(env)
    if flight.column >= len(columns):
        raise UserError(f"flight.column = {flight.column}: this environment has columns 0 to "
                        f"{len(columns) - 1}; fix it in the [flight] table")
    col = columns[flight.column]
    radius = flight.standoff_m + math.hypot(*col.section_m) / 2  # the edges at the stand-off
    arc = math.radians(flight.arc_deg)
    closed = flight.arc_deg >= 360.0
    poses = []
    steps = _steps(arc * radius, spacing, closed, len(flight.heights_m))
    for height in flight.heights_m:
        for t in steps:
            angle = col.heading + math.pi / 2 + t * arc  # start facing the left side's face
            position = np.array([col.center_xy[0] + radius * math.cos(angle),
                                 col.center_xy[1] + radius * math.sin(angle),
                                 col.bottom_z + height])
            poses.append(look_pose(position, angle + math.pi,
                                   math.radians(flight.gimbal_pitch_deg)))
    return poses


def _viaduct_span(env: Environment, flight: FlightConfig) -> tuple[float, float]:
    if flight.viaduct >= len(env.viaducts):
        raise UserError(f"flight.viaduct = {flight.viaduct}: this environment has viaducts 0 "
                        f"to {len(env.viaducts) - 1}; fix it in the [flight] table")
    v = env.viaducts[flight.viaduct]
    length = env.config.design.length_m
    return v.start_s_m, min(flight.length_m, length)


def _track_poses(env: Environment, s: np.ndarray, offset: float, z: np.ndarray, yaw_turn: float,
                 pitch: float) -> list[np.ndarray]:
    """Poses at arc lengths ``s``, ``offset`` to the left of the centre line at heights ``z``,
    looking ``yaw_turn`` from the track's direction."""
    points, _, normal = env.trajectory.frame(s)
    heading = env.trajectory.heading(s)
    return [look_pose(np.array([*(p[:2] + offset * n[:2]), h]), yaw + yaw_turn, pitch)
            for p, n, h, yaw in zip(points, normal, z, heading)]


def _facade(env: Environment, flight: FlightConfig, spacing: float, sensor_h_mm: float
            ) -> list[np.ndarray]:
    d, traj = env.config.design, env.trajectory
    start, length = _viaduct_span(env, flight)
    s = start + _steps(length, spacing, closed=False) * length
    sign = 1.0 if flight.side == "left" else -1.0
    outer = d.column_spacing_m / 2 + max(d.girder_width_m / 2, max(
        c.section_m[1] / 2 for c in env.viaducts[flight.viaduct].columns))
    tall = footprint_m(flight.standoff_m, sensor_h_mm, flight.focal_mm)
    # The rows' centres run from half an image above the ground to half an image under the
    # slab, but never nearer to either than the clearance (and 10 cm, as the ground's mesh
    # runs straight between the samples of its height).
    margin = max(tall / 2, flight.clearance_m + 0.1)
    low = traj.ground_at(s) + margin
    high = np.maximum(traj.deck_at(s) - d.slab_thickness_m - margin, low)
    row_step = (1 - flight.side_overlap_pct / 100) * tall
    n_rows = 1 + math.ceil(float(np.max(high - low)) / row_step - 1e-9)
    check_plan_size(n_rows * len(s), spacing, "lower side_overlap_pct or forward_overlap_pct "
                    "in [flight]")
    poses = []
    for k in range(n_rows):  # bottom to top, turning at each end (a lawnmower)
        z = low + (k / (n_rows - 1) if n_rows > 1 else 0.5) * (high - low)
        row = _track_poses(env, s, sign * (outer + flight.standoff_m), z, -sign * math.pi / 2,
                           math.radians(flight.gimbal_pitch_deg))
        poses.extend(row if k % 2 == 0 else row[::-1])
    return poses


def _underdeck(env: Environment, flight: FlightConfig, spacing: float) -> list[np.ndarray]:
    d = env.config.design
    start, length = _viaduct_span(env, flight)
    s = start + _steps(length, spacing, closed=False) * length
    z = env.trajectory.deck_at(s) - d.slab_thickness_m - flight.standoff_m
    return _track_poses(env, s, 0.0, z, math.pi / 2, math.radians(flight.gimbal_pitch_deg))


def plan_flight(env: Environment, config: Config, validate: bool = False) -> FlightPlan:
    """The flight [flight] describes in ``env``: poses in order and their times; with
    ``validate``, refused (validate_flight) where it collides or leaves the ground."""
    flight, sensor = config.flight, config.cameras.sensor_mm
    spacing = frame_spacing_m(flight, sensor)
    if spacing * flight.frame_rate_hz < flight.speed_mps * (1 - 1e-9):
        raise UserError(f"flight.speed_mps = {flight.speed_mps}: frames {spacing:.3f} m apart "
                        f"would come faster than frame_rate_hz = {flight.frame_rate_hz}; fly "
                        f"at most {spacing * flight.frame_rate_hz:.3f} m/s")
    if flight.plan == "orbit":
        poses = _orbit(env, flight, spacing)
    elif flight.plan == "facade":
        poses = _facade(env, flight, spacing, sensor_height_mm(config))
    else:
        poses = _underdeck(env, flight, spacing)
    if flight.max_frames:
        poses = poses[:flight.max_frames]
    stacked = np.stack(poses)
    steps = np.linalg.norm(np.diff(stacked[:, :3, 3], axis=0), axis=1)
    _check_frame_rate(steps, flight)
    times = np.concatenate([[0.0], np.cumsum(steps)]) / flight.speed_mps
    plan = FlightPlan(flight.plan, stacked, times, spacing, flight.focal_mm)
    if validate:
        validate_flight(env, plan, flight.clearance_m)
    return plan


def _check_frame_rate(steps: np.ndarray, flight: FlightConfig) -> None:
    """Refuse a plan with two frames nearer than the frame rate allows at its speed: an orbit's
    chords are shorter than its arc spacing, and a facade's turn to the next row may be
    shorter than a row's spacing."""
    if not steps.size:
        return
    i = int(np.argmin(steps))
    if steps[i] < 1e-9:  # only an orbit's rings at one height meet (one frame each)
        raise UserError(f"flight.heights_m = {list(flight.heights_m)}: waypoints {i} and "
                        f"{i + 1} coincide; give each ring a height of its own")
    if steps[i] * flight.frame_rate_hz < flight.speed_mps * (1 - 1e-9):
        raise UserError(f"flight.speed_mps = {flight.speed_mps}: waypoints {i} and {i + 1} are "
                        f"{steps[i]:.3f} m apart and would come faster than frame_rate_hz = "
                        f"{flight.frame_rate_hz}; fly at most "
                        f"{steps[i] * flight.frame_rate_hz:.3f} m/s")


def _path_samples(positions: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Points along the path at most ``step`` apart: the waypoints and points between them;
    for each, the waypoint it belongs to as 2 i (waypoint i) or 2 i + 1 (after waypoint i)."""
    points, owner = [positions[:1]], [np.zeros(1, int)]
    for i in range(len(positions) - 1):
        a, b = positions[i], positions[i + 1]
        n = max(1, math.ceil(np.linalg.norm(b - a) / step))
        t = np.arange(1, n + 1)[:, None] / n
        points.append(a + t * (b - a))
        owner.append(np.r_[np.full(n - 1, 2 * i + 1), 2 * (i + 1)])
    return np.concatenate(points), np.concatenate(owner)


def surface_distance(triangles: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Exact distance from each point (P, 3) to the nearest of ``triangles`` (T, 3, 3): to
    its plane where the foot falls inside the triangle, else to its nearest edge."""
    p = points[:, None, :]
    a, b, c = (triangles[None, :, k] for k in range(3))
    normal = np.cross(b - a, c - a)
    normal /= np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-300)
    height = np.sum((p - a) * normal, -1)
    foot = p - height[..., None] * normal
    inside = np.ones(height.shape, bool)
    for u, v in ((a, b), (b, c), (c, a)):  # the foot is on the inner side of every edge
        inside &= np.sum(np.cross(v - u, foot - u) * normal, -1) >= 0
    edges = np.minimum.reduce([segment_distance(p, u, v)[0]
                               for u, v in ((a, b), (b, c), (c, a))])
    return np.where(inside, np.abs(height), edges).min(axis=1)


def _world_mesh(part: Part) -> trimesh.Trimesh:
    """The part in world coordinates, its vertices merged (texture seams split them), so that
    a closed part reads as watertight."""
    return trimesh.Trimesh(part.world_vertices(), part.mesh.faces)


def _where(owner: int) -> str:
    return f"waypoint {owner // 2}" if owner % 2 == 0 else \
        f"the path from waypoint {owner // 2} to {owner // 2 + 1}"


def _ground_violation(env: Environment, positions: np.ndarray) -> str | None:
    """Every waypoint has ground under it (a vertical ray down from far above meets a ground
    strip) and stands above the highest such hit; else what fails and its fix."""
    ground = trimesh.util.concatenate([_world_mesh(p) for p in ground_parts(env.parts)])
    origins = positions.copy()
    origins[:, 2] = ground.bounds[1, 2] + 10.0
    down = np.tile([0.0, 0.0, -1.0], (len(positions), 1))
    hits, rays, _ = ground.ray.intersects_location(origins, down, multiple_hits=False)
    top = np.full(len(positions), -np.inf)
    np.maximum.at(top, rays, hits[:, 2])
    for i, (z, g) in enumerate(zip(positions[:, 2], top)):
        if not np.isfinite(g):
            return (f"waypoint {i} is beyond the ground's edge (no ground under it); move "
                    "the flight over the environment (column, viaduct, length_m)")
        if z <= g:
            return (f"waypoint {i} is {g - z:.2f} m below the ground; raise heights_m "
                    "(orbit) or lower standoff_m (underdeck)")
    return None


def _part_violations(env: Environment, points: np.ndarray, owner: np.ndarray,
                     clearance: float) -> list[tuple[int, str]]:
    """(owner, why) for path points inside a closed part or nearer than ``clearance`` to any
    part's surface; parts are tried only where their box, grown by ``clearance``, holds a
    point."""
    found = []
    for part in env.parts:
        corners = part.world_vertices()
        lo, hi = corners.min(axis=0) - clearance, corners.max(axis=0) + clearance
        near = np.flatnonzero(np.all((points >= lo) & (points <= hi), axis=1))
        if not near.size:
            continue
        mesh = _world_mesh(part)
        if mesh.is_watertight:
            for k in near[mesh.contains(points[near])]:
                found.append((int(owner[k]), f"inside {part.name}"))
        for k, dist in zip(near, surface_distance(mesh.triangles, points[near])):
            if dist < clearance:
                found.append((int(owner[k]), f"{dist:.2f} m from {part.name}, nearer than "
                                             f"[flight] clearance_m = {clearance}"))
    return found


def validate_flight(env: Environment, plan: FlightPlan, clearance: float) -> None:
    """Refuse, in one line, a plan that starts inside a part, goes below the ground or comes
    within ``clearance`` of a mesh anywhere along its path (sampled at clearance / 2, so no
    surface can pass between samples unnoticed)."""
    positions = plan.poses[:, :3, 3]
    points, owner = _path_samples(positions, clearance / 2)
    found = _part_violations(env, points, owner, clearance)
    starts_inside = [why for o, why in found if o == 0 and why.startswith("inside")]
    if starts_inside:
        raise UserError(f"[flight] {plan.plan}: waypoint 0 starts {starts_inside[0]}; "
                        "move the flight (column, viaduct, standoff_m, heights_m)")
    why = _ground_violation(env, positions)
    if why:
        raise UserError(f"[flight] {plan.plan}: {why}")
    if found:
        first, reason = min(found)
        others = len({o for o, _ in found}) - 1
        more = f" (and {others} more places)" if others else ""
        raise UserError(f"[flight] {plan.plan}: {_where(first)} is {reason}{more}; raise "
                        "standoff_m or move the flight")
