"""The photograph: what a real camera does to the light a pinhole render records.

The renderer's colour is a pinhole's: everything sharp, no noise, no lens fall-off. Here the
rendered colour goes through a camera's imaging chain ([sensor], docs/design.md "The camera
model"), in this order:

1. back to linear light by inverting the tone curve (the GL colour pass gives display sRGB
   only; highlights it clipped stay clipped), times the exposure error;
2. the lens: defocus by the thin lens from the depth map, motion blur (image velocity x
   exposure time), vignetting (cos^4 of the field angle), lateral chromatic aberration;
3. the sensor: Poisson-Gaussian noise, variance gain x / full_well + (gain read / full_well)^2
   for linear signal x, gain = ISO / 100, drawn as a Gaussian of that variance (the normal
   approximation of the Poisson counts: a pixel holds hundreds of electrons or more);
4. the camera's processing: automatic white balance (grey world over the surfaces) with an
   error, the tone curve, 8 bits, an unsharp mask, a JPEG round trip.

Labels and depth are the scene's and are not touched. Pure numpy and OpenCV; every draw comes
from the generator the caller makes for the view (Stream.SENSOR), the noise's from OpenCV's
generator seeded by it, so an image is reproduced from its seeds.
"""

import functools
import math
import threading
from dataclasses import dataclass

import cv2
import numpy as np

from glsynth.appearance.materials import srgb_decode
from glsynth.core.config import SensorConfig
from glsynth.render.tonemap import srgb_encode
from glsynth.world.cameras import Camera

BASE_ISO = 100.0
DEFOCUS_LEVELS = tuple(m * 2.0 ** k for k in range(7) for m in (1.0, 1.5))[:-1]
"""Blur-circle diameters (px) blurred for, 1, 1.5, 2, 3, ... 48, 64: a pixel's blur blends the
two levels around its own diameter; 1 px is sharp. Diameters past the last are cut to it.
Powers of two and halfway between make a diameter's level index 2 log2 (its octave) + twice
its step into it (level_index)."""
DIRECT_BLUR_PX = 6.0
"""A disc is blurred at the smallest power-of-two fraction of the image size that leaves it
at least this wide (px), then scaled back up: a disc of 12 px or more loses no detail there."""
AWB_CLIP = 0.98
"""Pixels at or over this linear value in a channel are clipped: the white balance's grey
world leaves them out (their colour is the clip's, not the light's)."""
_UNDER_CLIP = float(np.nextafter(np.float32(AWB_CLIP), np.float32(0)))
"""The largest float32 under AWB_CLIP: an unclipped value is at most this."""
AWB_MAX_GAIN = 4.0
"""The most a white-balance gain corrects (a camera's presets span about 2,500-10,000 K)."""
CHUNK_ROWS = 64
"""Rows of a frame that a pass with a temporary works on at a time: the temporary stays in the
cache, and no frame-sized one is allocated (a fresh one costs the kernel its page faults)."""
STRIP_ROWS = 128
"""Rows of the strips that the defocus finds each level's boxes in (level_boxes): a level's
pixels lie in bands that cross the frame at any slant, and one box per strip and run of
columns blurs less than half the area that one box over the frame does; 128 rows took the
fewest CPU seconds of 64-192 on inspection views."""
FOCUS_WINDOW = 0.1
"""The aimed point: the middle FOCUS_WINDOW x FOCUS_WINDOW of the frame."""
_DECODE = srgb_decode(np.arange(256)).astype(np.float32).reshape(256, 1)
"""8-bit sRGB to linear, as a table for cv2.LUT."""
_ENCODE_STEPS = 16383
_ENCODE = np.rint(srgb_encode(np.arange(_ENCODE_STEPS + 1) / _ENCODE_STEPS) * 255).astype(
    np.uint8)
"""Linear [0, 1] in 1/16383 steps to 8-bit sRGB: finer than one output code everywhere."""


@dataclass(frozen=True)
class Shot:
    """One photograph's settings, drawn per view."""

    iso: float
    f_number: float
    exposure_s: float
    shake_rad_s: float
    shake_angle: float
    """Direction of the handheld image motion in the image plane, radians from +x."""
    vignetting: float
    chromatic_px: float
    white_balance: tuple[float, float, float]
    exposure_gain: float
    jpeg_quality: int


def draw_shot(config: SensorConfig, rng: np.random.Generator) -> Shot:
    """The view's settings from ``rng``, in a fixed order (each field once)."""
    def uniform(lo_hi: tuple[float, float]) -> float:
        return float(rng.uniform(*lo_hi))

    iso = math.exp(uniform((math.log(config.iso[0]), math.log(config.iso[1]))))
    f_number = uniform(config.f_number)
    exposure_s = math.exp(uniform((math.log(config.exposure_s[0]),
                                   math.log(config.exposure_s[1]))))
    shake = math.radians(uniform(config.shake_deg_s))
    angle = uniform((0.0, 2 * math.pi))
    vignetting = uniform(config.vignetting)
    chromatic = uniform(config.chromatic_px)
    red, blue = uniform(config.white_balance), uniform(config.white_balance)
    gain = 2.0 ** uniform(config.exposure_ev)
    quality = int(rng.integers(int(config.jpeg_quality[0]), int(config.jpeg_quality[1]) + 1))
    return Shot(iso, f_number, exposure_s, shake, angle, vignetting, chromatic,
                (red, 1.0, blue), gain, quality)


def photograph(color: np.ndarray, depth: np.ndarray, camera: Camera, config: SensorConfig,
               rng: np.random.Generator, velocity_mps: np.ndarray | None = None
               ) -> np.ndarray:
    """The rendered ``color`` (H, W, 3 uint8 sRGB) as the camera photographs it, with the
    view's ``depth`` (metres along the axis). ``velocity_mps``: the world velocity of a
    moving camera (a flight's); None draws handheld shake. A disabled [sensor] returns
    ``color``."""
    if not config.enabled:
        return color
    shot = draw_shot(config, rng)
    # The sensor noise's seed is the generator's next draw, whatever the image; its normals
    # are drawn on a second thread (OpenCV releases the GIL) while the lens blurs here.
    normals = np.empty(color.shape, np.float32)
    drawing = threading.Thread(target=fill_standard_normal, args=(normals, noise_seed(rng)))
    drawing.start()
    # Drawn after the noise's seed, so that a view's other draws are those they were before
    # sharpening was modelled (and with an amount of 0, its bytes).
    amount = float(rng.uniform(*config.sharpen))
    sigma = float(rng.uniform(*config.sharpen_sigma_px))
    # The exposure error rides in the decoding table: the same float32 products, one pass.
    linear = cv2.LUT(np.ascontiguousarray(color), _DECODE * np.float32(shot.exposure_gain))
    focus = focus_distance(depth, camera.zfar)
    linear = defocus(linear, blur_diameter_px(depth, focus, camera, shot.f_number))
    if velocity_mps is None:
        speed = camera.fx * shot.shake_rad_s
        velocity_px_s = (speed * math.cos(shot.shake_angle), speed * math.sin(shot.shake_angle))
    else:
        velocity_px_s = image_velocity(camera, velocity_mps, focus)
    linear = motion_blur(linear, (velocity_px_s[0] * shot.exposure_s,
                                  velocity_px_s[1] * shot.exposure_s))
    linear *= vignetting_factor(camera, shot.vignetting)[..., None]
    linear = chromatic_aberration(linear, shot.chromatic_px)
    a, b = noise_parameters(config, shot.iso)
    drawing.join()
    linear = add_sensor_noise(linear, a, b, normals)
    surfaces = depth < np.float32(camera.zfar) * np.float32(0.999)
    gains = grey_world_gains(linear, surfaces) * np.asarray(shot.white_balance, np.float32)
    return jpeg_round_trip(sharpen(encode(linear, gains), amount, sigma), shot.jpeg_quality)


def grey_world_gains(linear: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(3,) float32 gains, green 1, that make the mean of ``linear`` (H, W, 3) over ``mask``'s
    unclipped pixels grey: a camera's automatic white balance by the grey-world assumption,
    which real cameras' AWB approximates. Over the surfaces only, as a camera's AWB leaves the
    sky out (its blue is not the light on the scene). Renders carry the daylight's colour
    (blue skylight in shade, the grass's green bounce), which a photograph does not."""
    # Every channel under the clip (at most the float32 below it), in one OpenCV pass.
    unclipped = cv2.inRange(linear, (-np.inf,) * 3, (_UNDER_CLIP,) * 3)
    usable = cv2.bitwise_and(unclipped, mask.view(np.uint8))
    if not cv2.countNonZero(usable):
        return np.ones(3, np.float32)
    # Summed in float64 by OpenCV, without gathering the pixels first.
    mean = np.asarray(cv2.mean(linear, mask=usable)[:3])
    if mean.min() <= 0.0:
        return np.ones(3, np.float32)
    return np.clip(mean[1] / mean, 1.0 / AWB_MAX_GAIN, AWB_MAX_GAIN).astype(np.float32)


def focus_distance(depth: np.ndarray, zfar: float) -> float:
    """Where the camera focuses: the median depth of the aimed point (the middle of the
    frame), or of the whole view where no surface is there (depth ``zfar``); 1 m where no
    surface is anywhere."""
    h, w = depth.shape
    dh, dw = max(1, round(h * FOCUS_WINDOW)), max(1, round(w * FOCUS_WINDOW))
    middle = depth[(h - dh) // 2:(h + dh) // 2, (w - dw) // 2:(w + dw) // 2]
    for values in (middle, depth):
        hit = values[values < np.float32(zfar) * np.float32(0.999)]
        if hit.size:
            return float(np.median(hit))
    return 1.0


def blur_diameter_px(depth: np.ndarray, focus_m: float, camera: Camera,
                     f_number: float) -> np.ndarray:
    """Thin-lens blur-circle diameter in pixels: c = f^2 |d - s| / (N (s - f) d) on the
    sensor, over the pixel pitch (sensor_mm / width)."""
    f = camera.focal_mm / 1000.0
    s = max(focus_m, 1.01 * f)  # focus nearer than the focal length has no real image
    # In float32 (7 digits; the defocus levels are 1.5x apart): |d - s| / d, then one factor.
    d = np.maximum(depth.astype(np.float32, copy=False), np.float32(1.01 * f))
    c_px = np.subtract(d, np.float32(s))
    np.abs(c_px, out=c_px)
    c_px /= d
    c_px *= np.float32(f * f / (f_number * (s - f)) / (camera.sensor_mm / 1000.0 / camera.width))
    return c_px


def disc_kernel(diameter_px: float) -> np.ndarray:
    """A uniform disc of the diameter, its edge anti-aliased; sums to 1."""
    radius = diameter_px / 2
    half = math.ceil(radius)
    y, x = np.mgrid[-half:half + 1, -half:half + 1]
    kernel = np.clip(radius + 0.5 - np.hypot(x, y), 0.0, 1.0).astype(np.float32)
    return kernel / kernel.sum()


def blur_scale(diameter_px: float, shape: tuple[int, ...]) -> int:
    """The power of two that a disc of ``diameter_px`` is blurred at a 1 / it of an image of
    ``shape`` (DIRECT_BLUR_PX)."""
    scale = 1
    while diameter_px / (2 * scale) >= DIRECT_BLUR_PX and min(shape[:2]) >= 16 * scale:
        scale *= 2
    return scale


def disc_blur(image: np.ndarray, diameter_px: float, scale: int | None = None) -> np.ndarray:
    """``image`` seen through a disc; wide discs at a smaller size (they lose no detail there),
    1 / ``scale`` of it (None: blur_scale's)."""
    if diameter_px <= 1.0:
        return image
    scale = blur_scale(diameter_px, image.shape) if scale is None else scale
    if scale == 1:
        return cv2.filter2D(image, -1, disc_kernel(diameter_px), borderType=cv2.BORDER_REFLECT)
    h, w = image.shape[:2]
    small = cv2.resize(image, (max(1, w // scale), max(1, h // scale)),
                       interpolation=cv2.INTER_AREA)
    small = cv2.filter2D(small, -1, disc_kernel(diameter_px / scale),
                         borderType=cv2.BORDER_REFLECT)
    return cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR)


def crops_on_grid(scale: int, shape: tuple[int, ...]) -> bool:
    """Whether crops of an image of ``shape`` can lie on the pixels of its 1 / ``scale``
    image (its sides whole multiples of ``scale``), as disc_blur_box's must to blur as the
    whole image does; otherwise it blurs the whole image."""
    return not (shape[0] % scale or shape[1] % scale)


def disc_blur_box(image: np.ndarray, diameter_px: float, box: tuple[int, int, int, int]
                  ) -> np.ndarray:
    """disc_blur(image, diameter_px) inside ``box`` (x, y, w, h), from the box and the margin
    around it that the disc and the small image's resampling read: a crop whose sides lie on
    the small image's pixels (or on the image's edges, reflected about as the whole image's
    are) blurs as the whole image does there, to float32 rounding."""
    x, y, w, h = box
    height, width = image.shape[:2]
    scale = blur_scale(diameter_px, image.shape)
    if diameter_px <= 1.0 or not crops_on_grid(scale, image.shape):
        return disc_blur(image, diameter_px)[y:y + h, x:x + w]
    margin = (math.ceil(diameter_px / scale / 2) + 1) * scale
    y0, x0 = max(0, (y - margin) // scale * scale), max(0, (x - margin) // scale * scale)
    y1 = min(height, -(-(y + h + margin) // scale) * scale)
    x1 = min(width, -(-(x + w + margin) // scale) * scale)
    blurred = disc_blur(image[y0:y1, x0:x1], diameter_px, scale)
    return blurred[y - y0:y - y0 + h, x - x0:x - x0 + w]


def level_index(diameter_px: np.ndarray) -> np.ndarray:
    """Each diameter's place among DEFOCUS_LEVELS, linear between two levels (float32).

    A diameter m 2^e, m in [0.5, 1), lies in the octave from 2^(e-1), whose level is 2e - 2,
    and 2 (2m - 1) levels into it (its levels are 2^(e-1) apart over there): 4m + 2e - 4.
    np.interp's binary search over the levels costs twice this."""
    clipped = np.clip(diameter_px, np.float32(DEFOCUS_LEVELS[0]), np.float32(DEFOCUS_LEVELS[-1]))
    index, exponent = np.frexp(clipped)
    index *= np.float32(4)
    exponent *= 2
    exponent -= 4
    index += exponent
    return index


def level_boxes(needed: np.ndarray, diameter_px: float, shape: tuple[int, ...]
                ) -> list[tuple[int, int, int, int]]:
    """Boxes (x, y, w, h) that cover the nonzero pixels of ``needed`` (a uint8 mask), for
    blurring a disc of ``diameter_px`` in an image of ``shape`` by disc_blur_box: per strip of
    STRIP_ROWS rows, one box per run of columns that hold some, runs closer than the margins
    the blur reads around two boxes joined. One bounding box where disc_blur_box blurs the
    whole image (crops_on_grid false), so that it does so once; none where no pixel is (a
    band's rows can span a level that no pixel is near: a sky edge jumps from a near
    surface's level to the last)."""
    scale = blur_scale(diameter_px, shape)
    if not crops_on_grid(scale, shape):
        x, y, w, h = cv2.boundingRect(needed)
        return [(x, y, w, h)] if w else []
    gap = 2 * (math.ceil(diameter_px / scale / 2) + 1) * scale
    boxes: list[tuple[int, int, int, int]] = []
    for top in range(0, needed.shape[0], STRIP_ROWS):
        strip = needed[top:top + STRIP_ROWS]
        columns = np.flatnonzero(strip.any(axis=0))
        if not columns.size:
            continue
        breaks = np.flatnonzero(np.diff(columns) > gap)
        for first, last in zip(columns[np.r_[0, breaks + 1]], columns[np.r_[breaks, -1]]):
            rows = np.flatnonzero(strip[:, first:last + 1].any(axis=1))
            boxes.append((int(first), top + int(rows[0]), int(last - first + 1),
                          int(rows[-1] - rows[0] + 1)))
    return boxes


def defocus(linear: np.ndarray, diameter_px: np.ndarray) -> np.ndarray:
    """Each pixel blurred by its own blur circle: the image blurred at each level of
    DEFOCUS_LEVELS that some pixel needs, blended per pixel between the two levels around
    its diameter (linear in the level index). Linear in ``linear`` for a fixed map."""
    index = level_index(diameter_px)
    row_low, row_high = index.min(axis=1), index.max(axis=1)
    if not row_high.any():
        return linear
    lower = np.floor(index)
    share = np.subtract(index, lower)  # of the level above, in [0, 1)
    # Per pixel: twice its lower level, plus 1 where the level above has a share.
    key = cv2.add(lower, lower, dtype=cv2.CV_8U)
    key += share > 0
    # Each level's blur is copied where it is a pixel's lower level and where its upper one,
    # and the two blended once at the end: a level's own weight pass costs more. ``above``
    # keeps zeros where no upper level is, and ``below`` where no level is at all (a row of
    # NaN diameters, which no band holds). np.zeros: the kernel's fresh zeroed pages, with
    # no fill pass (np.zeros_like fills).
    below, above = np.zeros(linear.shape, linear.dtype), np.zeros(linear.shape, linear.dtype)
    for level, diameter in enumerate(DEFOCUS_LEVELS):
        # Level L serves the pixels whose index lies in (L - 1, L + 1); depth is smooth, so
        # they lie in a band of rows, and only the band is looked at.
        rows = np.flatnonzero((row_low < level + 1) & (row_high > level - 1))
        if not rows.size:
            continue
        band = slice(rows[0], rows[-1] + 1)
        as_lower = cv2.inRange(key[band], 2 * level, 2 * level + 1)
        as_upper = cv2.compare(key[band], 2 * level - 1, cv2.CMP_EQ)
        # Only the boxes of the pixels that need the level are blurred (about a quarter of
        # the frame a level, at close, slanted views); OpenCV writes into the arrays' boxes
        # in place.
        for x, y, w, h in level_boxes(cv2.bitwise_or(as_lower, as_upper), diameter,
                                      linear.shape):
            blurred = disc_blur_box(linear, diameter, (x, band.start + y, w, h))
            box = (slice(band.start + y, band.start + y + h), slice(x, x + w))
            cv2.copyTo(blurred, as_lower[y:y + h, x:x + w], below[box])
            cv2.copyTo(blurred, as_upper[y:y + h, x:x + w], above[box])
    # below + share (above - below): every pixel's lower level is blurred; where its upper
    # one is not, its share is 0 and the zeros there drop out exactly.
    for top in range(0, linear.shape[0], CHUNK_ROWS):
        rows = slice(top, top + CHUNK_ROWS)
        step = np.subtract(above[rows], below[rows])
        step *= share[rows, :, None]
        below[rows] += step
    return below


def image_velocity(camera: Camera, velocity_mps: np.ndarray, depth_m: float
                   ) -> tuple[float, float]:
    """Image motion (px/s, x right, y down) of what lies ``depth_m`` ahead of a camera moving
    at ``velocity_mps`` (world): the scene slides against the camera's motion across the
    view, fx v / depth (motion along the axis, which only scales the view, is left out)."""
    along = camera.pose[:3, :3].T @ np.asarray(velocity_mps, np.float64)  # camera: +y up
    scale = camera.fx / max(depth_m, 1e-3)
    return float(-along[0] * scale), float(along[1] * scale)


def motion_blur(linear: np.ndarray, path_px: tuple[float, float]) -> np.ndarray:
    """The image averaged along a straight path of ``path_px`` (dx, dy) pixels, the image's
    motion during the exposure; under a pixel it is left as it is."""
    length = math.hypot(*path_px)
    if length < 1.0:
        return linear
    half = math.ceil(length / 2)
    size = 2 * half + 1
    kernel = np.zeros((size, size), np.float32)
    steps = max(2, math.ceil(4 * length))
    for t in np.linspace(-0.5, 0.5, steps):
        x, y = half + t * path_px[0], half + t * path_px[1]
        x0, y0 = math.floor(x), math.floor(y)
        fx, fy = x - x0, y - y0
        for dx, dy, w in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)),
                          (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
            if 0 <= x0 + dx < size and 0 <= y0 + dy < size:
                kernel[y0 + dy, x0 + dx] += w
    return cv2.filter2D(linear, -1, kernel / kernel.sum(), borderType=cv2.BORDER_REFLECT)


@functools.lru_cache(maxsize=4)
def _radius2(width: int, height: int) -> np.ndarray:
    """Each pixel centre's squared distance from the principal point (the image centre), in
    px^2; read only (made once per image size, as the vignetting of each view reads it)."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    x -= np.float32((width - 1) / 2)
    y -= np.float32((height - 1) / 2)
    r2 = x * x + y * y
    r2.flags.writeable = False
    return r2


def vignetting_factor(camera: Camera, strength: float) -> np.ndarray:
    """(H, W) share of light kept: 1 - v (1 - cos^4 t), t the field angle, tan t = r / fx."""
    # In place on one float32 plane: the same operations, in the same order, as the formula.
    factor = np.divide(_radius2(camera.width, camera.height), np.float32(camera.fx ** 2))
    factor += np.float32(1)
    np.divide(np.float32(1), factor, out=factor)  # cos^2 t
    factor *= factor
    np.subtract(np.float32(1), factor, out=factor)
    factor *= np.float32(strength)
    np.subtract(np.float32(1), factor, out=factor)
    return factor


def chromatic_aberration(linear: np.ndarray, corner_px: float) -> np.ndarray:
    """Red magnified and blue shrunk about the centre, so that at the corners each lies
    ``corner_px`` / 2 px from green (``corner_px`` apart). Overwrites ``linear``."""
    if corner_px <= 0:
        return linear
    h, w = linear.shape[:2]
    k = corner_px / 2 / math.hypot(w / 2, h / 2)
    cx, cy = (w - 1) / 2, (h - 1) / 2
    for channel, sign in ((0, 1), (2, -1)):
        # A channel magnified by (1 + k) reads its value at r / (1 + k). Each plane is
        # scaled about the centre by warpAffine (an affine remap that computes its
        # coordinates itself, a third of remap's cost) and put back in place (half the CPU
        # of splitting and merging the frame).
        scale = 1 / (1 + sign * k)
        reads = np.array([[scale, 0.0, cx * (1 - scale)], [0.0, scale, cy * (1 - scale)]])
        plane = cv2.warpAffine(cv2.extractChannel(linear, channel), reads, (w, h),
                               flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                               borderMode=cv2.BORDER_REPLICATE)
        linear = cv2.insertChannel(plane, linear, channel)  # in place where C-ordered
    return linear


def noise_parameters(config: SensorConfig, iso: float) -> tuple[float, float]:
    """(a, b) of the Poisson-Gaussian variance a x + b of linear signal x at ``iso``."""
    gain = iso / BASE_ISO
    return gain / config.full_well_e, (gain * config.read_noise_e / config.full_well_e) ** 2


def noise_seed(rng: np.random.Generator) -> int:
    """The seed of a view's sensor noise (fill_standard_normal), ``rng``'s next draw: OpenCV
    seeds its generator from a C int, so one of 2^31 - 1."""
    return int(rng.integers(1, 2**31))


def fill_standard_normal(out: np.ndarray, seed: int) -> None:
    """Fill float32 ``out`` (C-ordered) with standard normal draws, the same for the same
    ``seed``: OpenCV's generator (multiply-with-carry, ziggurat), a third of the CPU time of
    numpy's Generator for the 6 M draws of a frame. Its state is the calling thread's own,
    seeded here just before the draw, so no other draw comes between."""
    cv2.setRNGSeed(seed)
    cv2.randn(out.reshape(out.shape[0], -1), 0.0, 1.0)  # one channel: the scalars apply


def add_sensor_noise(linear: np.ndarray, a: float, b: float, normals: np.ndarray
                     ) -> np.ndarray:
    """Signal plus a Gaussian draw of variance a x + b per pixel and channel: ``normals``
    (the shape of ``linear``, float32) are the standard normal draws, one a value.
    Overwrites ``linear``."""
    for top in range(0, linear.shape[0], CHUNK_ROWS):  # the deviations' buffer: CHUNK_ROWS
        rows = slice(top, top + CHUNK_ROWS)
        sigma = np.maximum(linear[rows], np.float32(0))
        sigma *= np.float32(a)
        sigma += np.float32(b)
        np.sqrt(sigma, out=sigma)
        sigma *= normals[rows]
        linear[rows] += sigma
    return linear


def encode(linear: np.ndarray, gains: np.ndarray | None = None) -> np.ndarray:
    """Linear light times ``gains`` (3,) per channel (None: 1), clipped to [0, 1], to 8-bit
    sRGB."""
    scale = np.float32(_ENCODE_STEPS) * (np.ones(3, np.float32) if gains is None else gains)
    # One OpenCV pass scales each channel, rounds half to even (as np.rint) and clips below
    # 0 while converting to 16 bits; the top clip stays in those 16 bits.
    codes = cv2.multiply(linear, (*(float(s) for s in scale), 0.0), dtype=cv2.CV_16U)
    np.minimum(codes, np.uint16(_ENCODE_STEPS), out=codes)
    return _ENCODE[codes]


def sharpen(color: np.ndarray, amount: float, sigma_px: float) -> np.ndarray:
    """``color`` (uint8) with ``amount`` of its detail finer than a Gaussian of ``sigma_px``
    added back (an unsharp mask), rounded and clipped to 8 bits: what a camera's processor
    does to every photograph before it compresses it, leaving a bright and a dark rim along
    each edge. An amount of 0 returns ``color``."""
    if amount <= 0.0:
        return color
    blurred = cv2.GaussianBlur(color, (0, 0), sigma_px, borderType=cv2.BORDER_REFLECT)
    return cv2.addWeighted(color, 1.0 + amount, blurred, -amount, 0.0)


def jpeg_round_trip(color: np.ndarray, quality: int) -> np.ndarray:
    """``color`` (RGB uint8) as a JPEG of ``quality`` decodes it."""
    # OpenCV's JPEG takes BGR: cvtColor swaps on both cores, and the decoder gives RGB.
    ok, data = cv2.imencode(".jpg", cv2.cvtColor(color, cv2.COLOR_RGB2BGR),
                            [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise RuntimeError("OpenCV could not encode a JPEG")
    return cv2.imdecode(data, cv2.IMREAD_COLOR_RGB)
