"""Crack widths in millimetres from a damage map, a depth map and the camera's intrinsics
(issue 29 item 5; docs/design.md, "Crack widths in the assessment").

Concrete damage (id 2) is split into 8-connected regions; a region is a crack when its skeleton
is at least ``elongation`` times as long as its widest width (in pixels), and spalling
otherwise. Along each crack's skeleton the width in pixels is measured across the crack (a
sub-pixel scan of the mask's signed distance along the skeleton's normal, averaged over a few
pixels of the crack's length), and the two edge points are back-projected onto the surface
with the depth and the intrinsics: the width is their distance across the crack's 3-D
direction, so the surface's slant is corrected by geometry rather than by a cosine. Skeleton
pixels near an end or a junction are not measured (the scan would meet the tip or the other
branch). Pure numpy and OpenCV.
"""

from dataclasses import dataclass
from functools import cache

import cv2
import numpy as np

from glsynth.core.images import nearest_resize
from glsynth.core.labels import Component, Damage
from glsynth.core.palette import grade_rgb
from glsynth.core.surfaces import MAX_SLANT_DEG

TANGENT_RADIUS_PX = 4
"""Half-size of the window of skeleton pixels whose principal axis gives the local direction:
long enough to average the skeleton's one-pixel steps, short enough to follow a curve."""
SCAN_STEP_PX = 0.05
"""Step of the scan across the crack; the edge is interpolated between two steps."""
SCAN_SAMPLES = 2_000_000
"""Samples per batch of scans (a few tens of MB), whatever the number of skeleton pixels."""


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics in pixels of the map being measured (OpenCV's pixel centres)."""
    fx: float
    fy: float
    cx: float
    cy: float

    @classmethod
    def of_map(cls, K: np.ndarray, stride: float = 1.0) -> "Intrinsics":
        """Intrinsics of a map whose pixel spans ``stride`` photo pixels, from the photo's 3x3
        K (camera.json's "K"): map pixel i covers photo pixels [i s, (i + 1) s)."""
        K = np.asarray(K, dtype=np.float64)
        return cls(K[0, 0] / stride, K[1, 1] / stride, (K[0, 2] + 0.5) / stride - 0.5,
                   (K[1, 2] + 0.5) / stride - 0.5)

    @classmethod
    def centred(cls, focal_px: float, shape: tuple[int, int], stride: float = 1.0
                ) -> "Intrinsics":
        """Square pixels, principal point at the photo's centre (glsynth's cameras), focal
        length in photo pixels; ``shape`` is the map's (rows, cols)."""
        rows, cols = shape
        return cls(focal_px / stride, focal_px / stride, (cols - 1) / 2, (rows - 1) / 2)


@dataclass
class CrackMeasure:
    labels: np.ndarray
    """(H, W) int32: crack k + 1 on its pixels, 0 elsewhere (spalling included)."""
    skeleton: np.ndarray
    """(H, W) bool: the cracks' skeletons."""
    width_mm: np.ndarray
    """(H, W) float32: on every crack pixel the width measured at its nearest skeleton pixel
    [mm]; NaN where it could not be measured, 0 off cracks."""
    skeleton_width_mm: np.ndarray
    """(H, W) float32: the width on the surface at each measured skeleton pixel [mm] (the
    mean of the scans of the same crack within TANGENT_RADIUS_PX); NaN elsewhere."""
    skeleton_width_px: np.ndarray
    """(H, W) float32: the same in image pixels across the crack; NaN elsewhere."""
    cracks: list[dict]
    """Per crack: id, pixels, length_m, mean_width_mm (weighted by length), max_width_mm
    (the widest skeleton pixel), mean_width_px; the widths are None where no pixel could be
    measured (no valid depth, or cut lengthwise by the image border); attribute_components
    adds each crack's component."""
    spalling_regions: int
    """Concrete-damage regions left out as spalling (too wide for their length)."""


def check_grades(thresholds_mm: tuple[float, ...]) -> str | None:
    """Why a grade table is unusable, or None: positive, finite, strictly increasing."""
    t = np.asarray(thresholds_mm, dtype=np.float64)
    if t.size == 0 or not np.all(np.isfinite(t)) or np.any(t <= 0) or np.any(np.diff(t) <= 0):
        return "give positive widths in mm in increasing order, e.g. 0.2,0.3,0.5,1.0"
    return None


def grade(width_mm: float, thresholds_mm: tuple[float, ...]) -> int:
    """0 below the first threshold, k at or above the k-th (1-based) and below the next."""
    return int(np.searchsorted(np.asarray(thresholds_mm), width_mm, side="right"))


def grade_range(k: int, thresholds_mm: tuple[float, ...]) -> str:
    """'< 0.2 mm', '0.2-0.3 mm', ..., '>= 1 mm' for grade k."""
    t = [f"{v:g}" for v in thresholds_mm]
    if k == 0:
        return f"< {t[0]} mm"
    return f">= {t[-1]} mm" if k == len(t) else f"{t[k - 1]}-{t[k]} mm"


@cache
def _redundant_table() -> np.ndarray:
    """For each 8-neighbourhood code (bit i = neighbour i in ring order): True where the centre
    joins at least two neighbours that stay 8-connected without it (a staircase corner or a
    junction's extra pixel), so removing it keeps the skeleton's topology."""
    ring = [(-1, -1), (-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1)]
    table = np.zeros(256, bool)
    for code in range(256):
        on = [ring[i] for i in range(8) if code >> i & 1]
        if len(on) < 2:
            continue
        seen, todo = {on[0]}, [on[0]]
        while todo:
            r, c = todo.pop()
            for q in on:
                if q not in seen and max(abs(q[0] - r), abs(q[1] - c)) == 1:
                    seen.add(q)
                    todo.append(q)
        table[code] = len(seen) == len(on)
    return table


def skeletonize(mask: np.ndarray) -> np.ndarray:
    """A one-pixel, 8-connected skeleton (Guo-Hall thinning), with staircase corners taken
    out so that a straight crack at any angle has one pixel per step along its major axis
    (its length is then the pixel count times 1 / max(|cos|, |sin|))."""
    skel = cv2.ximgproc.thinning(mask.astype(np.uint8) * 255,
                                  thinningType=cv2.ximgproc.THINNING_GUOHALL)
    skel = (skel > 0).astype(np.uint8)
    weights = np.zeros((3, 3), np.float32)
    for i, (r, c) in enumerate([(0, 0), (0, 1), (0, 2), (1, 2), (2, 2), (2, 1), (2, 0), (1, 0)]):
        weights[r, c] = 1 << i
    table = _redundant_table()
    rows, cols = np.indices(mask.shape)
    changed = True
    while changed:
        changed = False
        for parity in ((0, 0), (0, 1), (1, 0), (1, 1)):  # removed pixels never touch
            code = cv2.filter2D(skel, cv2.CV_32F, weights, borderType=cv2.BORDER_CONSTANT)
            drop = (skel > 0) & table[code.astype(np.int64)] & (rows % 2 == parity[0]) & \
                (cols % 2 == parity[1])
            if drop.any():
                skel[drop] = 0
                changed = True
    return skel > 0


def skeleton_tangents(skeleton: np.ndarray, radius: int = TANGENT_RADIUS_PX) -> np.ndarray:
    """(H, W, 2) unit (x, y) direction of the skeleton at each of its pixels: the principal
    axis of the skeleton pixels in a (2 r + 1)^2 window (second moments by box filters)."""
    s = skeleton.astype(np.float64)
    rows, cols = np.indices(skeleton.shape, dtype=np.float64)
    size = (2 * radius + 1, 2 * radius + 1)

    def box(a: np.ndarray) -> np.ndarray:
        return cv2.boxFilter(a, cv2.CV_64F, size, normalize=False,
                             borderType=cv2.BORDER_CONSTANT)

    n = np.maximum(box(s), 1.0)
    mx, my = box(s * cols) / n, box(s * rows) / n
    sxx = box(s * cols * cols) / n - mx * mx
    syy = box(s * rows * rows) / n - my * my
    sxy = box(s * cols * rows) / n - mx * my
    angle = 0.5 * np.arctan2(2 * sxy, sxx - syy)
    return np.stack([np.cos(angle), np.sin(angle)], axis=-1)


def signed_distance(mask: np.ndarray) -> np.ndarray:
    """Approximate signed distance to the mask's outline, in pixels, positive inside: the
    outline lies half-way between an inside and an outside pixel centre."""
    m = mask.astype(np.uint8)
    inside = cv2.distanceTransform(m, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    outside = cv2.distanceTransform(1 - m, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return np.where(m > 0, inside - 0.5, 0.5 - outside).astype(np.float32)


def sample(image: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bilinear samples of a float image at (x, y) pixel coordinates (any equal shapes);
    outside the image the border is repeated."""
    n = int(np.size(x))
    if n == 0:
        return np.zeros(np.shape(x), np.float32)
    width = max(1, min(n, 4096))  # remap's maps must be under 32767 on each side
    size = -(-n // width) * width

    def grid(v: np.ndarray) -> np.ndarray:
        flat = np.zeros(size, np.float32)
        flat[:n] = np.ravel(v)
        return flat.reshape(-1, width)

    out = cv2.remap(image.astype(np.float32), grid(x), grid(y), cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REPLICATE)
    return out.ravel()[:n].reshape(np.shape(x))


def edge_offsets(phi: np.ndarray, points: np.ndarray, normals: np.ndarray, reach: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Sub-pixel distances (pixels) from each point to the crack's outline along +normal and
    -normal: the first zero of the signed distance, linearly interpolated between scan steps;
    NaN where the scan leaves the crack's reach, or the image, without crossing it (beyond
    the border the crack's width is unknown)."""
    steps = np.arange(0.0, reach + SCAN_STEP_PX, SCAN_STEP_PX)
    chunk = max(1, SCAN_SAMPLES // steps.size)  # bounds the memory of one batch of scans
    out = np.full((2, len(points)), np.nan)
    for start in range(0, len(points), chunk):
        part = slice(start, start + chunk)
        for side, sign in enumerate((1.0, -1.0)):
            out[side, part] = _first_zero(phi, points[part], sign * normals[part], steps)
    return out[0], out[1]


def _first_zero(phi: np.ndarray, points: np.ndarray, directions: np.ndarray,
                steps: np.ndarray) -> np.ndarray:
    x = points[:, :1] + directions[:, :1] * steps
    y = points[:, 1:] + directions[:, 1:] * steps
    values = sample(phi, x, y)
    in_image = (x >= -0.5) & (x <= phi.shape[1] - 0.5) & (y >= -0.5) & (y <= phi.shape[0] - 0.5)
    outside = values <= 0
    first = np.argmax(outside, axis=1)
    leaves = np.where(in_image.all(axis=1), steps.size, np.argmin(in_image, axis=1))
    found = outside.any(axis=1) & (first > 0) & (first < leaves)
    i = np.maximum(first, 1)
    rows = np.arange(len(points))
    v0, v1 = values[rows, i - 1], values[rows, i]
    frac = np.clip(v0 / np.maximum(v0 - v1, 1e-9), 0.0, 1.0)
    return np.where(found, steps[i - 1] + frac * SCAN_STEP_PX, np.nan)


def back_project(x: np.ndarray, y: np.ndarray, inverse_depth: np.ndarray,
                 intrinsics: Intrinsics) -> np.ndarray:
    """(..., 3) camera-frame points [m] at pixel coordinates (x, y). Inverse depth is
    interpolated: on a plane it is affine in pixel coordinates, so points between pixel
    centres land on the surface exactly. NaN where the depth is not valid."""
    rho = sample(inverse_depth, x, y).astype(np.float64)
    rho = np.where(rho > 0, rho, np.nan)
    k = intrinsics
    return np.stack([(x - k.cx) / k.fx / rho, (y - k.cy) / k.fy / rho, 1.0 / rho], axis=-1)


def _step_px(tangents: np.ndarray) -> np.ndarray:
    """Image length [px] a skeleton pixel stands for: a one-pixel 8-connected line along
    direction t has one pixel per 1 / max(|tx|, |ty|) pixels of length."""
    return 1.0 / np.maximum(np.abs(tangents[..., 0]), np.abs(tangents[..., 1]))


def split_cracks(mask: np.ndarray, elongation: float
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Crack labels (k + 1 on crack k, 0 elsewhere), the cracks' skeleton, its tangents and
    the number of regions left out as spalling. A region is a crack when its skeleton is at
    least ``elongation`` times as long as its widest width, both in pixels (the widest width
    from the distance transform: 2 max(distance to the background) - 1)."""
    m = mask.astype(np.uint8)
    count, regions = cv2.connectedComponents(m, connectivity=8)
    skeleton = skeletonize(m)
    tangents = skeleton_tangents(skeleton)
    length = np.bincount(regions[skeleton], weights=_step_px(tangents[skeleton]),
                         minlength=count)
    inside = cv2.distanceTransform(m, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    half = np.zeros(count)
    np.maximum.at(half, regions[m > 0], inside[m > 0])
    crack = length >= elongation * np.maximum(2 * half - 1, 1.0)
    crack[0] = False
    new_id = np.where(crack, np.cumsum(crack), 0).astype(np.int32)
    labels = new_id[regions]
    return labels, skeleton & (labels > 0), tangents, int(count - 1 - crack.sum())


def _away_from_nodes(skeleton: np.ndarray, half_width_px: np.ndarray) -> np.ndarray:
    """Skeleton pixels farther from every end and junction than their half width plus a pixel:
    there the scan across the crack meets the crack's own two edges, not a tip or a branch."""
    neighbours = cv2.filter2D(skeleton.astype(np.uint8), cv2.CV_16S,
                              np.array([[1, 1, 1], [1, 0, 1], [1, 1, 1]], np.int16),
                              borderType=cv2.BORDER_CONSTANT)
    nodes = skeleton & (neighbours != 2)
    to_node = cv2.distanceTransform((~nodes).astype(np.uint8), cv2.DIST_L2,
                                    cv2.DIST_MASK_PRECISE)
    return skeleton & (to_node > half_width_px + 1)


@dataclass
class _Samples:
    """Measurements at the skeleton pixels (1-D arrays in np.nonzero order)."""
    rows: np.ndarray
    cols: np.ndarray
    crack: np.ndarray
    width_px: np.ndarray
    width_m: np.ndarray
    step_m: np.ndarray
    kept: np.ndarray


def _measure_skeleton(labels: np.ndarray, skeleton: np.ndarray, tangents: np.ndarray,
                      depth_m: np.ndarray, intrinsics: Intrinsics) -> _Samples:
    """Width across the crack (pixels and metres on the surface) and length along it (metres)
    at every skeleton pixel."""
    rows, cols = np.nonzero(skeleton)
    t = tangents[rows, cols]
    normals = np.stack([-t[:, 1], t[:, 0]], axis=1)
    points = np.stack([cols, rows], axis=1).astype(np.float64)
    phi = signed_distance(labels > 0)
    reach = float(phi.max(initial=0.0)) + 2.0
    plus, minus = edge_offsets(phi, points, normals, reach)
    depth = np.asarray(depth_m, dtype=np.float64)
    inverse = np.where(np.isfinite(depth) & (depth > 0), 1.0 / np.where(depth > 0, depth, 1),
                       0.0)
    ends = [back_project(points[:, 0] + s * normals[:, 0], points[:, 1] + s * normals[:, 1],
                         inverse, intrinsics) for s in (plus, -minus)]
    along = [back_project(points[:, 0] + s * t[:, 0], points[:, 1] + s * t[:, 1], inverse,
                          intrinsics) for s in (1.0, -1.0)]
    z = depth[rows, cols]
    bound = (np.abs(np.stack([plus, minus, np.ones_like(plus), np.ones_like(plus)])) + 1.0) \
        * np.tan(np.radians(MAX_SLANT_DEG)) / intrinsics.fx
    steps = np.stack([p[:, 2] for p in ends + along]) / z - 1.0
    smooth = np.abs(steps) <= bound  # NaN steps fail too
    continuous = np.all(smooth, axis=0)
    tangent3 = along[0] - along[1]
    # Where a step along the crack crosses a silhouette, its length per pixel is the
    # fronto-parallel footprint: the back-projected step would span the two surfaces.
    smooth_along = np.all(smooth[2:], axis=0)
    metres_per_px = np.where(smooth_along, np.linalg.norm(tangent3, axis=1) / 2,
                             z / intrinsics.fx)
    unit = tangent3 / np.linalg.norm(tangent3, axis=1, keepdims=True)
    across = ends[0] - ends[1]
    across -= np.sum(across * unit, axis=1, keepdims=True) * unit
    kept = _away_from_nodes(skeleton, phi + 0.5)  # phi + 0.5: distance to the background
    return _Samples(rows, cols, labels[rows, cols] - 1, plus + minus,
                    np.where(continuous, np.linalg.norm(across, axis=1), np.nan),
                    metres_per_px * _step_px(t), kept[rows, cols])


def measure_cracks(damage: np.ndarray, depth_m: np.ndarray, intrinsics: Intrinsics,
                   elongation: float = 5.0) -> CrackMeasure:
    """Every crack in a damage-id map: its skeleton, its width along it and its length, in
    millimetres and metres on the surface seen at ``depth_m`` (metres along the optical axis,
    the damage map's size) through ``intrinsics`` (in the damage map's pixels)."""
    if damage.shape != depth_m.shape:
        raise ValueError(f"damage {damage.shape} and depth {depth_m.shape} maps differ in size")
    labels, skeleton, tangents, spalling = split_cracks(damage == Damage.CONCRETE, elongation)
    s = _measure_skeleton(labels, skeleton, tangents, depth_m, intrinsics)
    # A crack too short to have a pixel away from its ends is measured on all its pixels.
    has_kept = np.bincount(s.crack[s.kept], minlength=labels.max()) > 0
    s.kept |= ~has_kept[s.crack]
    s.kept &= np.isfinite(s.width_m) & np.isfinite(s.width_px)
    s.width_px, s.width_m = _smooth_along(s, labels.shape)
    skeleton_mm = np.full(labels.shape, np.nan, np.float32)
    skeleton_px = np.full(labels.shape, np.nan, np.float32)
    skeleton_mm[s.rows[s.kept], s.cols[s.kept]] = 1000 * s.width_m[s.kept]
    skeleton_px[s.rows[s.kept], s.cols[s.kept]] = s.width_px[s.kept]
    return CrackMeasure(labels, skeleton, _spread(skeleton_mm, labels), skeleton_mm,
                        skeleton_px, _per_crack(labels, s), spalling)


def _smooth_along(s: _Samples, shape: tuple[int, int], radius: int = TANGENT_RADIUS_PX
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Widths averaged over the measured pixels of the same crack within a (2 r + 1)^2 window
    (about 2 r + 1 pixels of its length): one scan of a binary mask is off by up to half a
    pixel where the pixel grid meets the crack's edge; the average over a stretch is not."""
    index = np.full(shape, -1, np.int64)
    index[s.rows[s.kept], s.cols[s.kept]] = np.flatnonzero(s.kept)
    total_px, total_m = np.zeros(s.rows.size), np.zeros(s.rows.size)
    count = np.zeros(s.rows.size)
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            r, c = s.rows + dy, s.cols + dx
            inside = (r >= 0) & (r < shape[0]) & (c >= 0) & (c < shape[1])
            other = np.where(inside, index[np.clip(r, 0, shape[0] - 1),
                                           np.clip(c, 0, shape[1] - 1)], -1)
            use = (other >= 0) & (s.crack[np.maximum(other, 0)] == s.crack)
            total_px[use] += s.width_px[other[use]]
            total_m[use] += s.width_m[other[use]]
            count[use] += 1
    keep = s.kept & (count > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return (np.where(keep, total_px / count, np.nan),
                np.where(keep, total_m / count, np.nan))


def _spread(skeleton_mm: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """Each crack pixel takes the width of its nearest measured skeleton pixel."""
    measured = np.isfinite(skeleton_mm)
    out = np.zeros(labels.shape, np.float32)
    if not measured.any():
        out[labels > 0] = np.nan
        return out
    _, nearest = cv2.distanceTransformWithLabels((~measured).astype(np.uint8), cv2.DIST_L2,
                                                 5, labelType=cv2.DIST_LABEL_PIXEL)
    values = np.concatenate([[np.nan], skeleton_mm[measured]])  # labels count from 1
    out[labels > 0] = values[nearest[labels > 0]]
    return out


def _per_crack(labels: np.ndarray, s: _Samples) -> list[dict]:
    count = int(labels.max())
    pixels = np.bincount(labels.ravel(), minlength=count + 1)[1:]
    length = np.bincount(s.crack, weights=np.nan_to_num(s.step_m), minlength=count)
    cracks = []
    for k in range(count):
        on = s.kept & (s.crack == k)
        widths, weights = s.width_m[on], np.nan_to_num(s.step_m[on])
        entry = {"id": k, "pixels": int(pixels[k]), "length_m": float(length[k]),
                 "mean_width_mm": None, "max_width_mm": None, "mean_width_px": None}
        if on.any():
            mean = np.average(widths, weights=weights) if weights.sum() > 0 else widths.mean()
            entry.update(mean_width_mm=float(1000 * mean),
                         max_width_mm=float(1000 * widths.max()),
                         mean_width_px=float(s.width_px[on].mean()))
        cracks.append(entry)
    return cracks


def attribute_components(measure: CrackMeasure, component: np.ndarray) -> None:
    """Give each crack the component under most of its pixels (its "component" key)."""
    on = measure.labels > 0
    count = len(measure.cracks)
    votes = np.zeros((count, len(Component)), np.int64)
    ids = np.clip(component[on].astype(np.int64), 0, len(Component) - 1)
    np.add.at(votes, (measure.labels[on] - 1, ids), 1)
    for crack, row in zip(measure.cracks, votes):
        crack["component"] = Component(int(row.argmax())).name.lower()


def component_cracks(cracks: list[dict], thresholds_mm: tuple[float, ...]) -> dict[str, dict]:
    """Per component (cracks attributed by attribute_components): crack count, total length,
    length-weighted mean width, maximum width and its grade."""
    out: dict[str, dict] = {}
    for name in dict.fromkeys(c["component"] for c in cracks):
        mine = [c for c in cracks if c["component"] == name]
        measured = [c for c in mine if c["mean_width_mm"] is not None]
        length = sum(c["length_m"] for c in mine)
        weights = [c["length_m"] for c in measured]
        mean = float(np.average([c["mean_width_mm"] for c in measured], weights=weights)) \
            if measured and sum(weights) > 0 else None
        widest = max((c["max_width_mm"] for c in measured), default=None)
        k = None if widest is None else grade(widest, thresholds_mm)
        out[name] = {"cracks": len(mine), "length_m": float(length), "mean_width_mm": mean,
                     "max_width_mm": widest, "grade": k,
                     "grade_range": None if k is None else grade_range(k, thresholds_mm)}
    return out


def width_errors(measure: CrackMeasure, truth_mm: np.ndarray) -> dict:
    """Measured against ground-truth widths at the measured skeleton pixels: signed errors
    [mm], the truth's width in pixels there, and per crack the error of its mean width."""
    if truth_mm.shape != measure.labels.shape:
        raise ValueError(f"ground-truth crack widths {truth_mm.shape} and damage map "
                         f"{measure.labels.shape} differ in size")
    at = np.isfinite(measure.skeleton_width_mm)
    truth = truth_mm.astype(np.float64)
    on = at & (truth > 0)
    measured = measure.skeleton_width_mm[on].astype(np.float64)
    px_per_mm = measure.skeleton_width_px[on] / np.maximum(measured, 1e-9)
    per_crack = []
    for k in range(len(measure.cracks)):
        mine = on & (measure.labels == k + 1)
        if mine.any():
            per_crack.append(float(measure.skeleton_width_mm[mine].mean() - truth[mine].mean()))
    return {"error_mm": measured - truth[on], "truth_mm": truth[on],
            "truth_px": truth[on] * px_per_mm, "crack_error_mm": np.array(per_crack),
            "off_truth_pixels": int((at & ~(truth > 0)).sum())}


def error_summary(errors: list[dict]) -> dict:
    """Median absolute and relative errors over all pixels and over those whose true width is
    at least 2 pixels (the issue's goal), and over cracks' mean widths."""
    def pool(key: str) -> np.ndarray:
        return np.concatenate([e[key] for e in errors]) if errors else np.zeros(0)

    err, truth, px, crack = (pool(k) for k in ("error_mm", "truth_mm", "truth_px",
                                                "crack_error_mm"))

    def stats(sel: np.ndarray) -> dict:
        if not sel.any():
            return {"pixels": 0, "median_abs_error_mm": None, "median_relative_error": None}
        return {"pixels": int(sel.sum()),
                "median_abs_error_mm": float(np.median(np.abs(err[sel]))),
                "median_relative_error": float(np.median(np.abs(err[sel]) / truth[sel]))}

    return {"all": stats(np.ones(err.size, bool)), "at_least_2px": stats(px >= 2),
            "cracks": int(crack.size),
            "crack_mean_median_abs_error_mm": float(np.median(np.abs(crack)))
            if crack.size else None,
            "skeleton_pixels_without_truth": int(sum(e["off_truth_pixels"] for e in errors))}


def crack_picture(rgb: np.ndarray, measure: CrackMeasure, thresholds_mm: tuple[float, ...]
                  ) -> np.ndarray:
    """The photo, dimmed, with each crack pixel coloured by the grade of its width and a
    legend of the grades in the top-left corner; unmeasured crack pixels are white. The width
    map is brought to the photo's size by nearest sampling."""
    width = nearest_resize(measure.width_mm, rgb.shape[:2])
    on = nearest_resize(measure.labels, rgb.shape[:2]) > 0
    colours = grade_rgb(len(thresholds_mm) + 1)
    picture = (rgb.astype(np.float32) * 0.6).round().astype(np.uint8)
    known = on & np.isfinite(width)
    k = np.searchsorted(np.asarray(thresholds_mm), width[known], side="right")
    picture[known] = colours[k]
    picture[on & ~known] = 255
    _legend(picture, colours, thresholds_mm)
    return picture


def _legend(picture: np.ndarray, colours: np.ndarray, thresholds_mm: tuple[float, ...]
            ) -> None:
    """Swatches and width ranges, scaled to the picture's height, drawn in place."""
    scale = max(picture.shape[0] / 1080, 0.25)
    row = max(int(36 * scale), 8)
    font = 0.8 * scale
    pad = row // 4
    for i, colour in enumerate(colours):
        y = pad + i * row
        cv2.rectangle(picture, (pad, y), (pad + row - pad, y + row - pad),
                      tuple(int(c) for c in colour), thickness=-1)
        cv2.putText(picture, grade_range(i, thresholds_mm), (pad + row, y + row - 2 * pad),
                    cv2.FONT_HERSHEY_SIMPLEX, font, (255, 255, 255), max(1, int(2 * scale)),
                    cv2.LINE_AA)
