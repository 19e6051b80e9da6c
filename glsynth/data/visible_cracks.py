"""The cracks a rendered view shows, for its meta JSON (docs/design.md, "Crack ground truth").

The renderer labels crack pixels and their widths but not which crack a pixel belongs to, so
each crack's centreline is sampled here, every half pixel or finer (on a rough crack along
the path the shader draws below the vertices, glsynth.appearance.crack_paths), and projected
into the view. A sample is labelled when it lands in the image in front of the near plane,
the render's crack widths inside the RRDR (those the written map keeps) hold a crack within
one pixel of it (a surface in front without cracks hides it, and cracks outside the RRDR are
unlabelled), and the rendered depth there is the sample's own (a cracked surface in front
hides it too). A crack is listed when at least one of its samples is labelled, with the
length of chord its labelled samples stand for and the number of pixels of the written
640x360 crack-width map that they mark. Pure numpy.
"""

import numpy as np

from glsynth.appearance import crack_paths
from glsynth.appearance.cracks import CrackNetwork
from glsynth.core.arrays import unique_ints
from glsynth.core.geometry import nearest_triangles, transform_points
from glsynth.world.cameras import Camera
from glsynth.world.environment import Part
from glsynth.world.visibility import in_frustum, part_corners, seen_by

SAMPLE_STEP_PX = 0.5
"""Samples along a centreline, at most this many image pixels apart."""
MAX_SAMPLES_PER_SEGMENT = 4096
"""A bound for segments that reach behind the camera (their step is taken at the near
plane); 4096 half pixels cover twice the image's width."""
DEPTH_TOLERANCE = (0.02, 0.01)
"""A sample is on the rendered surface when its depth is within 2 % + 1 cm of the depth there:
on a face seen at 85 degrees the surface under a pixel spans about 1 % of the depth, and an
occluding surface stands farther off than that."""


def centreline_samples(net: CrackNetwork, part: Part, camera: Camera
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points along every segment of ``part``'s network that can show in the view, in world
    coordinates (M, 3), the segment each lies on (M,) and the length in metres of chord each
    stands for (M,). A segment is cut into equal pieces at most SAMPLE_STEP_PX long in the
    image (taken at its nearer end) and sampled at their middles; a segment that cannot show
    (``in_frustum``, grown by a rough path's reach) gets none. On a rough network the samples
    lie on the path the shader draws (path_offsets), not on the chord."""
    a = transform_points(part.pose, net.points[:, 0])
    b = transform_points(part.pose, net.points[:, 1])
    view = camera.view()
    depth = -np.minimum(a @ view[2, :3], b @ view[2, :3]) - view[2, 3]
    step_m = SAMPLE_STEP_PX * np.maximum(depth, camera.znear) / camera.fx
    length = np.linalg.norm(b - a, axis=1)
    n = np.clip(np.ceil(length / step_m), 1, MAX_SAMPLES_PER_SEGMENT).astype(np.int64)
    # A rough crack's path strays up to CRACK_REACH_M from its chord, into view from off it.
    grow = crack_paths.SHADER_CONSTANTS["CRACK_REACH_M"] if net.rough else 0.0
    n = np.where(in_frustum(a, b, camera, grow), n, 0)
    segment = np.repeat(np.arange(len(n)), n)
    t = (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n) + 0.5) / n[segment]
    points = a[segment] + t[:, None] * (b - a)[segment]
    if net.rough and len(segment):
        points += path_offsets(net, part, segment, t, points, camera)
    return points, segment, (length / np.maximum(n, 1))[segment]


def path_offsets(net: CrackNetwork, part: Part, segment: np.ndarray, t: np.ndarray,
                 points: np.ndarray, camera: Camera) -> np.ndarray:
    """(M, 3) world vectors from chord points (``points``, at parameters ``t`` of their
    ``segment``) to the rough path the shader draws through them: crack_paths.shader_offsets
    along the shader's across direction, the surface's normal (sign fixed as crack_normal
    fixes it) crossed with the chord, in the mesh frame. The shader refines down to the pixel's
    footprint; here, the footprint of a fronto-parallel pixel at the point's depth (the levels
    below it move a path by a tenth of a pixel at most)."""
    used, back = np.unique(segment, return_inverse=True)
    a, b = net.points[used, 0], net.points[used, 1]
    faces = nearest_triangles(part.mesh.triangles, (a + b) / 2)
    normal = part.mesh.face_normals[faces]
    lead = normal[np.arange(len(used)), np.argmax(np.abs(normal), axis=1)]
    across = np.cross(np.where(lead[:, None] < 0, -normal, normal), b - a)
    size = np.linalg.norm(across, axis=1, keepdims=True)
    across = np.where(size > 0, across / np.where(size > 0, size, 1.0), 0.0)
    depth = -transform_points(camera.view(), points)[:, 2]
    offset = crack_paths.shader_offsets(
        t, np.linalg.norm(b - a, axis=1)[back], crack_paths.segment_seeds(net.widths_m[used])[back],
        np.maximum(depth, camera.znear) / camera.fx)
    return (across @ part.pose[:3, :3].T)[back] * offset[:, None]


def project(points: np.ndarray, camera: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixel column and row (nearest pixel centre) and depth along the optical axis of world
    points; columns and rows are -1 where the point is outside the image or before the near
    plane."""
    view = camera.view()
    c = transform_points(view, points)
    depth = -c[:, 2]
    front = depth > camera.znear
    safe = np.where(front, depth, 1.0)
    k = camera.K
    col = np.rint(k[0, 0] * c[:, 0] / safe + k[0, 2])
    row = np.rint(k[1, 2] - k[1, 1] * c[:, 1] / safe)
    inside = front & (col >= 0) & (col < camera.width) & (row >= 0) & (row < camera.height)
    return (np.where(inside, col, -1).astype(np.int64),
            np.where(inside, row, -1).astype(np.int64), depth)


def on_surface(net: CrackNetwork, part: Part, camera: Camera, depth_m: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The network's centreline samples (centreline_samples) in the view: each one's pixel
    row and column (-1 outside the image), segment and length, and whether it lies on the
    rendered surface (within DEPTH_TOLERANCE of ``depth_m`` there, not hidden)."""
    points, segment, weight = centreline_samples(net, part, camera)
    col, row, depth = project(points, camera)
    on = col >= 0
    rel, ab = DEPTH_TOLERANCE
    on[on] = np.abs(depth[on] - depth_m[row[on], col[on]]) <= rel * depth[on] + ab
    return row, col, segment, weight, on


def near_crack(crack_width_mm: np.ndarray) -> np.ndarray:
    """Pixels with a labelled crack within one pixel (the 3x3 neighbourhood), bool."""
    cracked = np.pad(crack_width_mm > 0, 1)
    h, w = crack_width_mm.shape
    out = np.zeros((h, w), bool)
    for dr in range(3):
        for dc in range(3):
            out |= cracked[dr:dr + h, dc:dc + w]
    return out


def member_cracks(records: list[dict], net: CrackNetwork, part: Part, camera: Camera,
                  near: np.ndarray, depth_m: np.ndarray, written_code: np.ndarray,
                  stride: int) -> list[dict]:
    """The labelled cracks of one member: its dressing records (id, member, type, length and
    widths) with ``labelled_length_m`` and ``pixels`` (of the written crack-width map, whose
    pixels span ``stride`` x ``stride`` render pixels)."""
    row, col, segment, weight, on = on_surface(net, part, camera, depth_m)
    on[on] = near[row[on], col[on]]
    crack = net.crack[segment]
    listed = []
    for record in records:
        mine = on & (crack == record["id"])
        if not mine.any():
            continue
        cells = unique_ints((row[mine] // stride) * written_code.shape[1] + col[mine] // stride)
        pixels = int(np.count_nonzero(written_code.ravel()[cells]))
        listed.append({**record, "labelled_length_m": round(float(weight[mine].sum()), 4),
                       "pixels": pixels})
    return listed


def visible_cracks(parts: list[Part], networks: dict[str, CrackNetwork],
                   records: dict[str, list[dict]], camera: Camera, crack_width_mm: np.ndarray,
                   depth_m: np.ndarray, written_code: np.ndarray, stride: int) -> list[dict]:
    """Every crack the view labels, member by member in part order: ``networks`` and
    ``records`` (the dressing's crack records) by part name; ``crack_width_mm`` (inside the
    RRDR) and ``depth_m`` the render's full-size maps, ``written_code`` the crack-width map
    written."""
    cracked = [p for p in parts if p.name in networks]
    if not cracked or not crack_width_mm.any():
        return []
    in_view = seen_by(np.stack([part_corners(p) for p in cracked]), camera)
    near = near_crack(crack_width_mm)
    listed = []
    for part, seen in zip(cracked, in_view):
        if seen:
            listed += member_cracks(records[part.name], networks[part.name], part, camera,
                                    near, depth_m, written_code, stride)
    return listed
