"""A flight's frames for 3-D tools: a COLMAP text model, nerfstudio's transforms.json and a
labelled point cloud (points.ply). Pure numpy; the frames are read back from their files.

Conventions (docs/design.md "Flights"):
- glsynth's camera looks down -z with +y up and has pixel centres at integer coordinates
  (K's principal point is ((W - 1) / 2, (H - 1) / 2)). COLMAP's looks down +z with +y down,
  and COLMAP, nerfstudio and instant-ngp put pixel centres at +0.5: cx = W / 2 there.
- COLMAP stores world-to-camera: R = F R_gl^T, t = -R c, with F = diag(1, -1, -1) and c the
  camera centre, and R as a unit quaternion (qw, qx, qy, qz), qw >= 0.
- transforms.json stores camera-to-world in OpenGL axes: glsynth's pose unchanged.
- A frame *sees* a point when the point projects inside the image in front of the camera and
  the frame's depth at that pixel is within tau of the point's depth z, tau = g + 0.005 z +
  1 mm, where g is the depth's change per pixel there (in each direction the smaller of the
  two one-sided differences where both run the same way, summed over both directions: a
  slanted surface's change, not a silhouette's jump, nor the two jumps of a thing one pixel
  wide). The point lies within half a pixel of the pixel's centre, so on the surface the
  pixel sees its depth differs by at most about g.
"""

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from glsynth.core.fileio import atomic_write_bytes, atomic_write_json
from glsynth.core.geometry import transform_points
from glsynth.world.cameras import Camera
from glsynth.world.lens import Lens, label_rays, normalized_to_pixel

EDGE_MARGIN_PX = 2
"""Points are sampled at least this many pixels (in x and y) from a label's edge."""

FLIP_YZ = np.diag([1.0, -1.0, -1.0])
"""glsynth's camera axes to COLMAP's (and back)."""


def rotation_quaternion(r: np.ndarray) -> np.ndarray:
    """(qw, qx, qy, qz) of a rotation matrix, qw >= 0 (Shepperd's method: the largest of the
    four squared components is taken from the trace, the rest from off-diagonal sums)."""
    t = np.trace(r)
    squares = np.array([1 + t, 1 + 2 * r[0, 0] - t, 1 + 2 * r[1, 1] - t, 1 + 2 * r[2, 2] - t])
    k = int(np.argmax(squares))
    q = np.empty(4)
    q[k] = math.sqrt(squares[k]) / 2
    s = 4 * q[k]
    pairs = {0: (r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]),
             1: (r[2, 1] - r[1, 2], r[0, 1] + r[1, 0], r[0, 2] + r[2, 0]),
             2: (r[0, 2] - r[2, 0], r[0, 1] + r[1, 0], r[1, 2] + r[2, 1]),
             3: (r[1, 0] - r[0, 1], r[0, 2] + r[2, 0], r[1, 2] + r[2, 1])}[k]
    others = [i for i in range(4) if i != k]
    for i, value in zip(others, pairs):
        q[i] = value / s
    return q if q[0] >= 0 else -q


def colmap_pose(pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """COLMAP's world-to-camera (R, t) of a glsynth world-from-camera pose."""
    rotation = FLIP_YZ @ pose[:3, :3].T
    return rotation, -rotation @ pose[:3, 3]


def project(camera: Camera, lens: Lens, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """glsynth pixel coordinates (N, 2: col, row; centres at integers) and depth along the
    optical axis (N,) of world points."""
    view = camera.view()
    cam = transform_points(view, points)
    depth = -cam[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        xy = np.stack([cam[:, 0] / depth, -cam[:, 1] / depth], axis=1)  # COLMAP's axes
    return normalized_to_pixel(camera, lens, xy), depth


def depth_tolerance(depth: np.ndarray) -> np.ndarray:
    """g of the module docstring, per pixel (H, W)."""
    padded = np.pad(depth.astype(np.float64), 1, mode="edge")
    g = np.zeros(depth.shape)
    for axis in (0, 1):
        step = np.diff(padded, axis=axis)
        before, after = (step[:-1, 1:-1], step[1:, 1:-1]) if axis == 0 else \
            (step[1:-1, :-1], step[1:-1, 1:])
        # A slope runs one way through the pixel; a thing one pixel wide (a bar, a wire)
        # jumps both ways, and its jumps are silhouettes, not a change along a surface.
        g += np.where(before * after > 0, np.minimum(np.abs(before), np.abs(after)), 0.0)
    return g


def seen(camera: Camera, lens: Lens, depth_map: np.ndarray, points: np.ndarray
         ) -> tuple[np.ndarray, np.ndarray]:
    """Which points the frame sees (N,) and their glsynth pixel coordinates (N, 2)."""
    uv, z = project(camera, lens, points)
    col, row = np.floor(uv[:, 0] + 0.5), np.floor(uv[:, 1] + 0.5)
    inside = (z > camera.znear) & (col >= 0) & (col < camera.width) & (row >= 0) & \
        (row < camera.height)
    r, c = row[inside].astype(int), col[inside].astype(int)
    d = depth_map[r, c].astype(np.float64)
    tau = depth_tolerance(depth_map)[r, c] + 0.005 * z[inside] + 0.001
    ok = np.zeros(len(points), bool)
    ok[np.flatnonzero(inside)] = (np.abs(d - z[inside]) <= tau) & (d < camera.zfar)
    return ok, uv


@dataclass(frozen=True)
class Frame:
    """One written frame, as read back: what the exports need."""

    name: str
    """Path of its image.png, relative to the flight folder."""
    camera: Camera
    lens: Lens
    time_s: float
    color: np.ndarray
    component: np.ndarray
    damage: np.ndarray
    depth: np.ndarray


def label_interior(maps: Sequence[np.ndarray], radius: int = EDGE_MARGIN_PX) -> np.ndarray:
    """Pixels (H, W) whose neighbours up to ``radius`` pixels away in x and y hold the same
    id as they do, in every map."""
    ok = np.ones(maps[0].shape, bool)
    h, w = maps[0].shape
    size = 2 * radius + 1
    for m in maps:
        padded = np.pad(m, radius, mode="edge")
        for dy in range(size):
            for dx in range(size):
                ok &= padded[dy:dy + h, dx:dx + w] == m
    return ok


def sample_points(frames: Sequence[Frame], stride: int, spacing_m: float) -> dict:
    """Back-projected pixels of every frame at ``stride`` (from stride // 2 in each
    direction), then at most one per cube of ``spacing_m`` (the first in frame and pixel
    order): xyz (float64), rgb, component, damage, source frame. Sky is left out, and so are
    pixels within EDGE_MARGIN_PX of a label's edge (component or damage): another frame's
    pixel centre lands up to half its pixel from the point, across a near edge from it as
    often as not, so only a point inside a label region has one label all frames agree on."""
    parts = []
    for index, f in enumerate(frames):
        rows, cols = np.meshgrid(np.arange(stride // 2, f.camera.height, stride),
                                 np.arange(stride // 2, f.camera.width, stride), indexing="ij")
        rows, cols = rows.ravel(), cols.ravel()
        z = f.depth[rows, cols].astype(np.float64)
        keep = (z < f.camera.zfar) & label_interior((f.component, f.damage))[rows, cols]
        rows, cols, z = rows[keep], cols[keep], z[keep]
        xy = label_rays(f.camera, f.lens, cols, rows)
        cam = np.stack([xy[:, 0] * z, -xy[:, 1] * z, -z], 1)  # glsynth's axes
        xyz = transform_points(f.camera.pose, cam)
        parts.append((xyz, f.color[rows, cols], f.component[rows, cols], f.damage[rows, cols],
                      np.full(len(z), index)))
    xyz, rgb, component, damage, source = (np.concatenate(a) for a in zip(*parts))
    _, first = np.unique(np.floor(xyz / spacing_m).astype(np.int64), axis=0, return_index=True)
    keep = np.sort(first)
    return {"xyz": xyz[keep], "rgb": rgb[keep], "component": component[keep],
            "damage": damage[keep], "source": source[keep]}


def visibility(frames: Sequence[Frame], xyz: np.ndarray
               ) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Per frame: the ids of the points it sees (ascending) and their glsynth pixels."""
    ids, pixels = [], []
    for f in frames:
        ok, uv = seen(f.camera, f.lens, f.depth, xyz)
        ids.append(np.flatnonzero(ok))
        pixels.append(uv[ok])
    return ids, pixels


def _rows(fmt: str, table: np.ndarray) -> str:
    return "".join(fmt % tuple(row) for row in table)


def write_colmap(folder: Path, frames: Sequence[Frame], xyz: np.ndarray, rgb: np.ndarray,
                 ids: list[np.ndarray], pixels: list[np.ndarray]) -> None:
    """cameras.txt (one camera: PINHOLE, or the lens's SIMPLE_RADIAL or OPENCV), images.txt
    (poses and, per image, the points it sees at their exact pixels), points3D.txt (each
    point with its true track, error 0)."""
    cam = frames[0].camera
    model, params = frames[0].lens.colmap_params(cam)
    atomic_write_bytes(folder / "cameras.txt", (
        "# CAMERA_ID MODEL WIDTH HEIGHT PARAMS[] (pixel centres at +0.5)\n"
        f"1 {model} {cam.width} {cam.height} " + " ".join(repr(float(v)) for v in params) +
        "\n").encode())
    lines = ["# IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME\n# POINTS2D[] as (X, Y, "
             "POINT3D_ID)\n"]
    tracks: list[list[tuple[int, int]]] = [[] for _ in range(len(xyz))]
    for j, (f, seen_ids, uv) in enumerate(zip(frames, ids, pixels)):
        rotation, t = colmap_pose(f.camera.pose)
        q = rotation_quaternion(rotation)
        lines.append(f"{j + 1} " + " ".join(repr(float(v)) for v in (*q, *t)) +
                     f" 1 {f.name}\n")
        table = np.column_stack([uv + 0.5, seen_ids + 1])
        lines.append(_rows("%.6f %.6f %d ", table).rstrip() + "\n")
        for k2d, point in enumerate(seen_ids):
            tracks[point].append((j + 1, k2d))
    atomic_write_bytes(folder / "images.txt", "".join(lines).encode())
    out = ["# POINT3D_ID X Y Z R G B ERROR TRACK[] as (IMAGE_ID, POINT2D_IDX)\n"]
    for p, (x, c, track) in enumerate(zip(xyz, rgb, tracks)):
        pairs = " ".join(f"{i} {k2d}" for i, k2d in track)
        coords = " ".join(repr(float(v)) for v in x)
        out.append(f"{p + 1} {coords} {c[0]} {c[1]} {c[2]} 0 {pairs}\n")
    atomic_write_bytes(folder / "points3D.txt", "".join(out).encode())


def write_transforms(path: Path, frames: Sequence[Frame]) -> None:
    """nerfstudio / instant-ngp: shared intrinsics (pixel centres at +0.5) and radial
    distortion (OPENCV's k1, k2: the same formula as COLMAP's), camera-to-world in OpenGL axes
    per frame (glsynth's pose as it is)."""
    cam, lens = frames[0].camera, frames[0].lens
    k = cam.K
    atomic_write_json(path, {
        "camera_model": "OPENCV", "fl_x": k[0, 0], "fl_y": k[1, 1], "cx": k[0, 2] + 0.5,
        "cy": k[1, 2] + 0.5, "w": cam.width, "h": cam.height,
        "k1": lens.k1, "k2": lens.k2, "p1": 0.0, "p2": 0.0,
        "frames": [{"file_path": f.name, "transform_matrix": f.camera.pose.tolist(),
                    "time_s": f.time_s, "colmap_im_id": j + 1}
                   for j, f in enumerate(frames)]})


_PLY_FIELDS = [("x", "<f8", "double"), ("y", "<f8", "double"), ("z", "<f8", "double"),
               ("red", "u1", "uchar"), ("green", "u1", "uchar"), ("blue", "u1", "uchar"),
               ("component", "u1", "uchar"), ("damage", "u1", "uchar"),
               ("n_frames", "<u4", None)]
_PLY_RECORD = np.dtype([(name, kind) for name, kind, _ in _PLY_FIELDS])


def ply_bytes(xyz: np.ndarray, rgb: np.ndarray, component: np.ndarray, damage: np.ndarray,
              frames: list[np.ndarray]) -> bytes:
    """Binary little-endian PLY: per vertex x y z (double), red green blue, component, damage
    (uchar) and ``frames``, the list (uint count, uint ids) of the frames that see it."""
    n = len(xyz)
    header = ["ply", "format binary_little_endian 1.0",
              "comment glsynth flight: world metres, z up; component and damage ids as in "
              "docs/design.md; frames: ids of the frames that see the point (frame_NNNN)",
              f"element vertex {n}"]
    header += [f"property {ply} {name}" for name, _, ply in _PLY_FIELDS if ply]
    header += ["property list uint uint frames", "end_header"]
    fixed = np.zeros(n, _PLY_RECORD)
    for axis, name in enumerate("xyz"):
        fixed[name] = xyz[:, axis]
    for axis, name in enumerate(("red", "green", "blue")):
        fixed[name] = rgb[:, axis]
    fixed["component"], fixed["damage"] = component, damage
    counts = np.array([len(f) for f in frames], np.int64)
    fixed["n_frames"] = counts
    size = _PLY_RECORD.itemsize
    starts = np.arange(n) * size + 4 * np.concatenate([[0], np.cumsum(counts)[:-1]])
    body = np.zeros(n * size + 4 * int(counts.sum()), np.uint8)
    body[starts[:, None] + np.arange(size)] = fixed.view(np.uint8).reshape(n, size)
    if counts.sum():
        ids = np.concatenate(frames).astype("<u4").view(np.uint8).reshape(-1, 4)
        slot = np.concatenate([np.arange(c) for c in counts])
        offset = np.repeat(starts + size, counts) + 4 * slot
        body[offset[:, None] + np.arange(4)] = ids
    return ("\n".join(header) + "\n").encode() + body.tobytes()


def read_ply(path: str | Path) -> dict:
    """points.ply as written by ply_bytes: xyz, rgb, component, damage, frames (a list)."""
    data = Path(path).read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    n = int(next(line.split()[2] for line in data[:end].decode().splitlines()
                 if line.startswith("element vertex")))
    size = _PLY_RECORD.itemsize
    records, frames, at = np.zeros(n, _PLY_RECORD), [], end
    for i in range(n):
        records[i] = np.frombuffer(data, _PLY_RECORD, 1, at)[0]
        count = int(records[i]["n_frames"])
        frames.append(np.frombuffer(data, "<u4", count, at + size).astype(np.int64))
        at += size + 4 * count
    return {"xyz": np.stack([records[a] for a in "xyz"], 1),
            "rgb": np.stack([records[a] for a in ("red", "green", "blue")], 1),
            "component": records["component"], "damage": records["damage"], "frames": frames}
