"""Radial lens distortion in COLMAP's camera models ([flight] camera_model, k1, k2). No GL.

COLMAP's SIMPLE_RADIAL and OPENCV (without tangential terms) map a normalized image point
x = X / Z, y = Y / Z (camera looking down +z, +y down) to

    x_d = x (1 + k1 r^2 + k2 r^4),  r^2 = x^2 + y^2,   pixel u = f x_d + cx, v = f y_d + cy

with pixel centres at +0.5 (SIMPLE_RADIAL is k2 = 0). glsynth renders such a frame as a pinhole
image (the *source*, on a canvas grown so that it covers every distorted pixel's ray) and
resamples it: each output pixel centre is undistorted (Newton's method on the radius) and
looked up in the source, bilinearly for colour, at the nearest source pixel for the label maps
and depth, so ids stay exact. Depth after distortion is therefore the source's depth (z along
the optical axis, which distortion does not move) of the surface point its labels come from:
the one seen at the source pixel nearest to the output pixel's ray.
"""

import math
from dataclasses import dataclass, replace

import cv2
import numpy as np

from glsynth.core.errors import UserError
from glsynth.world.cameras import Camera


@dataclass(frozen=True)
class Lens:
    model: str
    """"PINHOLE", "SIMPLE_RADIAL" or "OPENCV"."""
    k1: float = 0.0
    k2: float = 0.0

    @property
    def pinhole(self) -> bool:
        return self.model == "PINHOLE"

    def factor(self, r2: np.ndarray) -> np.ndarray:
        return 1 + self.k1 * r2 + self.k2 * r2 * r2

    def distort(self, xy: np.ndarray) -> np.ndarray:
        """Normalized points (N, 2) to distorted ones."""
        return xy * self.factor(np.sum(xy * xy, axis=-1))[..., None]

    def undistort(self, xy_d: np.ndarray) -> np.ndarray:
        """The inverse of distort, where the radius map is increasing (checked by check)."""
        rd = np.linalg.norm(xy_d, axis=-1)
        r = rd.copy()
        for _ in range(50):  # Newton on r (1 + k1 r^2 + k2 r^4) = rd
            f = r * self.factor(r * r) - rd
            df = 1 + 3 * self.k1 * r * r + 5 * self.k2 * r ** 4
            r = r - f / df
        with np.errstate(invalid="ignore", divide="ignore"):
            scale = np.where(rd > 0, r / rd, 1.0)
        return xy_d * scale[..., None]

    def colmap_params(self, camera: Camera) -> tuple[str, list[float]]:
        """COLMAP's model name and parameters for ``camera``'s intrinsics (centres at +0.5)."""
        k = camera.K
        f, cx, cy = k[0, 0], k[0, 2] + 0.5, k[1, 2] + 0.5
        if self.model == "PINHOLE":
            return "PINHOLE", [f, f, cx, cy]
        if self.model == "SIMPLE_RADIAL":
            return "SIMPLE_RADIAL", [f, cx, cy, self.k1]
        return "OPENCV", [f, f, cx, cy, self.k1, self.k2, 0.0, 0.0]


def check_lens(lens: Lens, camera: Camera) -> None:
    """The radius map must increase until it reaches the image's corners, or pixels would
    fold over (barrel distortion turns back beyond some radius; the image must end before)."""
    k = camera.K
    corner = math.hypot(max(k[0, 2] + 0.5, camera.width - 0.5 - k[0, 2]),
                        max(k[1, 2] + 0.5, camera.height - 0.5 - k[1, 2])) / k[0, 0]
    r = np.linspace(0.0, 10.0, 100_001) * corner
    rd = r * lens.factor(r * r)
    reached = np.flatnonzero(rd >= corner)
    if not reached.size or np.any(np.diff(rd[:reached[0] + 1]) <= 0):
        raise UserError(f"flight.k1 = {lens.k1}, k2 = {lens.k2}: the distortion folds the image "
                        "over before its corners; use smaller coefficients")


def pixel_to_normalized(camera: Camera, lens: Lens, cols: np.ndarray, rows: np.ndarray
                        ) -> np.ndarray:
    """COLMAP normalized (x, y) of glsynth pixel coordinates (centres at integers)."""
    k = camera.K
    xy_d = np.stack([(cols - k[0, 2]) / k[0, 0], (rows - k[1, 2]) / k[1, 1]], axis=-1)
    return xy_d if lens.pinhole else lens.undistort(xy_d)


def normalized_to_pixel(camera: Camera, lens: Lens, xy: np.ndarray) -> np.ndarray:
    """glsynth pixel coordinates (col, row) of COLMAP normalized points."""
    k = camera.K
    xy_d = xy if lens.pinhole else lens.distort(xy)
    return np.stack([k[0, 0] * xy_d[..., 0] + k[0, 2], k[1, 1] * xy_d[..., 1] + k[1, 2]], -1)


def source_camera(camera: Camera, lens: Lens) -> Camera:
    """The pinhole camera whose image covers every pixel of the distorted ``camera``: the
    same pose and focal length, grown by an equal margin on each side."""
    if lens.pinhole:
        return camera
    check_lens(lens, camera)
    w, h = camera.width, camera.height
    border = np.concatenate([np.c_[np.arange(w), np.zeros(w)], np.c_[np.arange(w),
                             np.full(w, h - 1)], np.c_[np.zeros(h), np.arange(h)],
                             np.c_[np.full(h, w - 1), np.arange(h)]]).astype(float)
    xy = pixel_to_normalized(camera, lens, border[:, 0], border[:, 1])
    f, k = camera.K[0, 0], camera.K
    need_x = np.max(np.abs(xy[:, 0]) * f) - k[0, 2]
    need_y = np.max(np.abs(xy[:, 1]) * f) - k[1, 2]
    margin = max(0, math.ceil(max(need_x, need_y)) + 1)
    return replace(camera, width=w + 2 * margin, height=h + 2 * margin)


def source_pixels(camera: Camera, lens: Lens, source: Camera) -> np.ndarray:
    """For each pixel centre of the distorted ``camera`` (H, W), where its ray meets the
    source image, in the source's pixel coordinates (H, W, 2: col, row)."""
    rows, cols = np.mgrid[0:camera.height, 0:camera.width].astype(float)
    return normalized_to_pixel(source, Lens("PINHOLE"),
                               pixel_to_normalized(camera, lens, cols, rows))


def label_rays(camera: Camera, lens: Lens, cols: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """COLMAP normalized (x, y) of the rays whose surface points give pixels (cols, rows) of
    a distorted frame their labels and depth: through the nearest source pixel's centre. A
    point back-projected along it with the pixel's depth lies exactly on that surface."""
    if lens.pinhole:
        return pixel_to_normalized(camera, lens, cols, rows)
    source = source_camera(camera, lens)
    where = source_pixels(camera, lens, source)[rows.astype(int), cols.astype(int)]
    return pixel_to_normalized(source, Lens("PINHOLE"), np.floor(where[:, 0] + 0.5),
                               np.floor(where[:, 1] + 0.5))


def resample(image: np.ndarray, where: np.ndarray, nearest: bool) -> np.ndarray:
    """``image`` looked up at ``where`` (H, W, 2): the nearest pixel, or bilinearly."""
    if nearest:
        col = np.floor(where[..., 0] + 0.5).astype(np.intp)
        row = np.floor(where[..., 1] + 0.5).astype(np.intp)
        return image[np.clip(row, 0, image.shape[0] - 1), np.clip(col, 0, image.shape[1] - 1)]
    maps = where.astype(np.float32)
    return cv2.remap(image, maps[..., 0], maps[..., 1], cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE)
