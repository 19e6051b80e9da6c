"""The camera model ([sensor], glsynth.render.camera_model) on real renders of the inspection
preset: labels and depth untouched, Poisson-Gaussian noise, thin-lens defocus, vignetting,
reproducible bytes, and the paper preset left as it was."""

import dataclasses
import math

import cv2
import numpy as np
import pytest

from glsynth.appearance.materials import srgb_decode
from glsynth.core.config import SensorConfig, config_from_dict, load_config
from glsynth.core.errors import UserError
from glsynth.core.seeding import Stream, make_rng
from glsynth.render import camera_model
from glsynth.render.view import EnvironmentView, preview_config

WIDTH = 480
CAMERA = 3


@pytest.fixture(scope="module")
def view():
    config = preview_config(load_config("inspection"), WIDTH)
    # Culled for CAMERA alone (what culling keeps: tests/test_render_viaduct.py); the tests
    # compare this view with itself.
    return EnvironmentView.open(config, 0, 0, rendering=[CAMERA])


@pytest.fixture(scope="module")
def rendered(view):
    """(placement, the render, the photograph) of one inspection camera."""
    placement, render = view.render(CAMERA, photo=False)
    _, photo = view.render(CAMERA)
    return placement, render, photo


def quiet(**fields) -> SensorConfig:
    """A [sensor] whose every effect is off or fixed, but those given."""
    base = dict(enabled=True, iso=(100.0, 100.0), full_well_e=1e7, read_noise_e=0.0,
                f_number=(64.0, 64.0), exposure_s=(1e-4, 1e-4), shake_deg_s=(0.0, 0.0),
                vignetting=(0.0, 0.0), chromatic_px=(0.0, 0.0), white_balance=(1.0, 1.0),
                exposure_ev=(0.0, 0.0), jpeg_quality=(100, 100), sharpen=(0.0, 0.0))
    return SensorConfig(**{**base, **fields})


def test_labels_and_depth_stay_the_scene(rendered):
    _, render, photo = rendered
    for name in ("component", "damage", "depth", "crack_width"):
        assert np.array_equal(getattr(render, name), getattr(photo, name)), name
    assert not np.array_equal(render.color, photo.color)
    # The photograph is still the same view: far from the render's colours it is not.
    assert np.abs(photo.color.astype(int) - render.color).mean() < 40


def test_same_seeds_same_bytes(view, rendered):
    _, _, photo = rendered
    _, again = view.render(CAMERA)
    assert np.array_equal(photo.color, again.color)
    draws = {camera_model.draw_shot(view.config.sensor, make_rng(0, 0, Stream.SENSOR, i))
             for i in range(4)}
    assert len(draws) == 4


def test_noise_variance_is_poisson_gaussian(rendered):
    """Residual variance against the render's linear signal follows a x + b (ISO 1600)."""
    _, render, _ = rendered
    config = SensorConfig(enabled=True, full_well_e=5000.0, read_noise_e=1.0)
    a, b = camera_model.noise_parameters(config, 1600.0)
    assert a == pytest.approx(16 / 5000) and b == pytest.approx((16 * 1 / 5000) ** 2)
    linear = srgb_decode(render.color).astype(np.float32)
    normals = make_rng(0, 0, Stream.SENSOR, 7).standard_normal(linear.shape, dtype=np.float32)
    noisy = camera_model.add_sensor_noise(linear.copy(), a, b, normals)
    residual, signal = (noisy - linear).ravel(), linear.ravel()
    edges = np.quantile(signal, np.linspace(0.05, 0.95, 7))
    checked = 0
    for lo, hi in zip(edges[:-1], edges[1:]):
        inside = (signal >= lo) & (signal < hi)
        if inside.sum() < 5000 or hi - lo > 0.5 * hi:
            continue
        expected = a * signal[inside].mean() + b
        assert residual[inside].var() == pytest.approx(expected, rel=0.05)
        checked += 1
    assert checked >= 3
    # Brighter pixels are noisier, by as much as shot noise has it.
    dark, bright = signal < np.quantile(signal, 0.2), signal > np.quantile(signal, 0.8)
    predicted = (a * signal[bright].mean() + b) / (a * signal[dark].mean() + b)
    assert predicted > 1.5
    assert residual[bright].var() / residual[dark].var() == pytest.approx(predicted, rel=0.05)


def _spread_diameter(response: np.ndarray, row: int, col: int) -> float:
    """The diameter of the uniform disc whose second moment the response has:
    E[r^2] = R^2 / 2 for a disc of radius R."""
    weights = response.sum(axis=2)
    ys, xs = np.nonzero(weights > 0)
    w = weights[ys, xs]
    r2 = ((ys - row) ** 2 + (xs - col) ** 2) * w
    return 2 * math.sqrt(2 * r2.sum() / w.sum())


def test_defocus_follows_the_thin_lens(rendered):
    """A point at the focus distance stays sharp; focused elsewhere, the same point spreads
    into a disc of the thin-lens diameter f^2 |d - s| / (N (s - f) d)."""
    placement, render, _ = rendered
    camera = placement.camera
    h, w = render.depth.shape
    row, col = h // 2, w // 2
    d = float(render.depth[row, col])
    assert d < camera.zfar * 0.99  # the aimed point is a surface
    linear = srgb_decode(render.color).astype(np.float32)
    impulse = np.zeros_like(linear)
    impulse[row, col] = 1.0
    f, n = camera.focal_mm / 1000, 4.0
    pitch = camera.sensor_mm / 1000 / camera.width
    target_px = 9.0
    c = target_px * pitch  # focused before the point: s solved from the thin lens for c
    s = d * f * (f + c * n) / (f * f + c * n * d)
    assert f < s < d
    for focus, expected in ((d, 0.0), (s, target_px)):
        diameter = camera_model.blur_diameter_px(render.depth, focus, camera, n)
        assert diameter[row, col] == pytest.approx(expected, abs=1e-3)
        response = (camera_model.defocus(linear + impulse, diameter)
                    - camera_model.defocus(linear, diameter))
        spread = _spread_diameter(np.where(np.abs(response) > 1e-6, response, 0), row, col)
        if expected == 0:
            assert spread < 0.5 and response[row, col].sum() == pytest.approx(3.0, abs=1e-3)
        else:
            assert spread == pytest.approx(expected, rel=0.12)


def test_defocus_negligible_far_with_a_wide_lens(rendered):
    """At 20 m with a 24 mm lens the blur circle is under a pixel of a 1920 px frame."""
    placement, _, _ = rendered
    camera = dataclasses.replace(placement.camera, focal_mm=24.0, width=1920, height=1080)
    depth = np.array([[15.0, 20.0, 40.0]], np.float32)
    assert camera_model.blur_diameter_px(depth, 20.0, camera, 8.0).max() < 1.0


def test_motion_blur_spreads_a_point_along_the_image_velocity(rendered):
    """A drone flying sideways at 2 m/s past a surface s metres ahead, exposed 1/100 s:
    a point smears into a line fx v t / s pixels long, across the image."""
    placement, render, _ = rendered
    camera = placement.camera
    focus = camera_model.focus_distance(render.depth, camera.zfar)
    right = camera.pose[:3, 0] * 2.0  # the camera's +x, in the world
    vx, vy = camera_model.image_velocity(camera, right, focus)
    assert vx == pytest.approx(-camera.fx * 2.0 / focus) and vy == pytest.approx(0, abs=1e-9)
    path = (vx / 100, vy / 100)
    linear = srgb_decode(render.color).astype(np.float32)
    h, w = linear.shape[:2]
    impulse = np.zeros_like(linear)
    impulse[h // 2, w // 2] = 1.0
    response = (camera_model.motion_blur(linear + impulse, path)
                - camera_model.motion_blur(linear, path)).sum(axis=2)
    rows, cols = np.nonzero(np.abs(response) > 1e-6)
    assert set(rows) <= {h // 2 - 1, h // 2, h // 2 + 1}
    weights = response[rows, cols]
    spread = np.sqrt((weights * (cols - w // 2) ** 2).sum() / weights.sum())
    # A uniform line of length L has a standard deviation of L / sqrt(12).
    assert spread * math.sqrt(12) == pytest.approx(abs(path[0]), rel=0.1)
    assert response.sum() == pytest.approx(3.0, abs=1e-3)


def test_vignetting_darkens_corners_by_cos4(rendered):
    """A flat grey photographed with vignetting v only: the corners keep 1 - v (1 - cos^4 t)
    of the centre's light, t the corner's field angle from the sensor and the focal."""
    placement, render, _ = rendered
    camera = placement.camera
    grey = np.full_like(render.color, 160)
    strength = 0.8
    photo = camera_model.photograph(grey, render.depth, camera,
                                    quiet(vignetting=(strength, strength)),
                                    make_rng(0, 0, Stream.SENSOR, 0))
    linear = srgb_decode(photo)
    half_diagonal_mm = camera.sensor_mm / 2 * math.hypot(1, camera.height / camera.width)
    theta = math.atan(half_diagonal_mm / camera.focal_mm)
    promised = 1 - strength * (1 - math.cos(theta) ** 4)
    h, w = linear.shape[:2]
    centre = linear[h // 2 - 2:h // 2 + 2, w // 2 - 2:w // 2 + 2].mean()
    for corner in (linear[:2, :2], linear[:2, -2:], linear[-2:, :2], linear[-2:, -2:]):
        assert corner.mean() / centre == pytest.approx(promised, abs=0.015)
    assert promised < 0.97  # the preset's widest view shows it


def _shift(moving: np.ndarray, fixed: np.ndarray) -> tuple[float, float]:
    """The (dx, dy) that moves ``fixed`` onto ``moving``: Lucas-Kanade over the whole patch,
    on copies blurred so that a sub-pixel shift is linear in the gradient, refined twice."""
    import cv2

    a = cv2.GaussianBlur(fixed.astype(np.float32), (0, 0), 1.5)
    b = cv2.GaussianBlur(moving.astype(np.float32), (0, 0), 1.5)
    dx = dy = 0.0
    h, w = a.shape
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    for _ in range(3):
        warped = cv2.remap(a, x - np.float32(dx), y - np.float32(dy), cv2.INTER_CUBIC,
                           borderMode=cv2.BORDER_REPLICATE)
        gy, gx = np.gradient(warped)
        inner = (slice(6, -6), slice(6, -6))
        gx, gy, diff = gx[inner].ravel(), gy[inner].ravel(), (warped - b)[inner].ravel()
        m = np.array([[gx @ gx, gx @ gy], [gx @ gy, gy @ gy]])
        step = np.linalg.solve(m, np.array([gx @ diff, gy @ diff]))
        dx, dy = dx + float(step[0]), dy + float(step[1])
    return dx, dy


def test_chromatic_aberration_parts_red_and_blue_radially(rendered):
    """Red and blue of a grey copy of the render lie ``corner_px`` apart at the corners,
    radially, in proportion to the distance from the centre; green stays."""
    _, render, _ = rendered
    grey = np.repeat(srgb_decode(render.color)[..., 1:2], 3, axis=2).astype(np.float32)
    corner_px = 1.0
    shifted = camera_model.chromatic_aberration(grey.copy(), corner_px)
    assert np.array_equal(shifted[..., 1], grey[..., 1])
    h, w = grey.shape[:2]
    scale = corner_px / math.hypot((w - 1) / 2, (h - 1) / 2)
    size = 48
    corners = ((4, 4), (4, w - size - 4), (h - size - 4, 4), (h - size - 4, w - size - 4),
               ((h - size) // 2, (w - size) // 2))
    for top, left in corners:
        patch = (slice(top, top + size), slice(left, left + size))
        dx, dy = _shift(shifted[patch][..., 0], shifted[patch][..., 2])
        cx, cy = left + (size - 1) / 2 - (w - 1) / 2, top + (size - 1) / 2 - (h - 1) / 2
        assert dx == pytest.approx(cx * scale, abs=0.1)
        assert dy == pytest.approx(cy * scale, abs=0.1)


def _surface_means(color: np.ndarray, depth: np.ndarray, zfar: float) -> np.ndarray:
    linear = srgb_decode(color)
    usable = (depth < zfar * 0.999) & (linear.max(axis=2) < camera_model.AWB_CLIP)
    return linear[usable].mean(axis=0)


def test_white_balance_makes_the_surfaces_grey_then_errs_by_its_draw(rendered):
    placement, render, _ = rendered
    camera = placement.camera
    before = _surface_means(render.color, render.depth, camera.zfar)
    # The render carries the daylight's colour (skylight, the grass's bounce): not grey.
    assert np.ptp(before / before[1]) > 0.05
    for gains in ((1.0, 1.0), (1.08, 1.08), (0.92, 0.92)):
        sensor = quiet(white_balance=gains)
        photo = camera_model.photograph(render.color, render.depth, camera, sensor,
                                        make_rng(0, 0, Stream.SENSOR, 0))
        after = _surface_means(photo, render.depth, camera.zfar)
        # Red and blue over green: the drawn error, within the 8-bit round trip's 1 %.
        assert after / after[1] == pytest.approx([gains[0], 1.0, gains[1]], abs=0.01)


def test_grey_world_gains_leave_out_the_sky_and_clipped_pixels():
    linear = np.full((4, 4, 3), (0.2, 0.4, 0.1), np.float32)
    linear[0] = (0.1, 0.3, 0.9)  # sky (outside the mask)
    linear[1, :2] = (1.0, 1.0, 0.5)  # clipped
    mask = np.ones((4, 4), bool)
    mask[0] = False
    assert camera_model.grey_world_gains(linear, mask) == pytest.approx([2.0, 1.0, 4.0])
    assert camera_model.grey_world_gains(linear, np.zeros((4, 4), bool)) == pytest.approx(1.0)


def test_sharpening_rims_an_edge_as_an_unsharp_mask_does():
    """An edge between grey 60 and 180 gains a dark rim below 60 and a bright one above 180
    of amount x the step x the Gaussian's tail beyond half a pixel (to a code, for widths of
    a pixel or more, where OpenCV's sampled kernel is near the continuous one); flat ground
    stays; an amount of 0 is the image itself."""
    image = np.full((40, 40, 3), 60, np.uint8)
    image[:, 20:] = 180
    for amount, sigma in ((0.5, 1.0), (1.0, 1.3), (1.0, 2.0)):  # OpenCV samples the kernel
        out = camera_model.sharpen(image, amount, sigma)
        tail = 0.5 * math.erfc(0.5 / (sigma * math.sqrt(2)))  # the blur's share across
        rim = amount * 120 * tail
        assert out[20, 19, 0] == pytest.approx(60 - rim, abs=1.0)
        assert out[20, 20, 0] == pytest.approx(180 + rim, abs=1.0)
        assert np.array_equal(out[:, :12], image[:, :12])
        assert np.array_equal(out[:, 28:], image[:, 28:])
    assert camera_model.sharpen(image, 0.0, 1.0) is image


def test_sharpening_adds_fine_detail_to_a_photograph_and_draws_after_the_rest(view, rendered):
    """The same view photographed with and without sharpening: the same draws before it (so
    the same noise), more energy at the finest scale, the same mean."""
    placement, render, _ = rendered

    def shoot(sharpen):
        config = quiet(iso=(1600.0, 1600.0), full_well_e=20000.0, read_noise_e=3.0,
                       sharpen=sharpen, sharpen_sigma_px=(1.0, 1.0))
        return camera_model.photograph(render.color, render.depth, placement.camera, config,
                                       make_rng(0, 0, Stream.SENSOR, CAMERA)).astype(np.float32)

    plain, sharp = shoot((0.0, 0.0)), shoot((0.8, 0.8))
    detail = [cv2.Laplacian(image, cv2.CV_32F).var() for image in (plain, sharp)]
    assert detail[1] > 1.5 * detail[0]
    assert abs(sharp.mean() - plain.mean()) < 0.5
    # Sharpening only what the camera made: the difference is the unsharp mask's detail.
    blurred = cv2.GaussianBlur(plain, (0, 0), 1.0, borderType=cv2.BORDER_REFLECT)
    assert np.corrcoef((sharp - plain).ravel(), (plain - blurred).ravel())[0, 1] > 0.9


def test_disabled_sensor_is_the_render(view, rendered):
    placement, render, _ = rendered
    off = dataclasses.replace(view.config.sensor, enabled=False)
    out = camera_model.photograph(render.color, render.depth, placement.camera, off,
                                  make_rng(0, 0, Stream.SENSOR, 0))
    assert out is render.color
    assert not load_config("paper").sensor.enabled
    assert load_config("inspection").sensor.enabled and load_config("demo").sensor.enabled


@pytest.mark.parametrize("key, value, words", [
    ("iso", [1600, 100], "sensor.iso"),
    ("f_number", [0.1, 8], "sensor.f_number"),
    ("exposure_s", [0, 0.01], "sensor.exposure_s"),
    ("vignetting", [0.5, 2], "sensor.vignetting"),
    ("jpeg_quality", [70.5, 90], "sensor.jpeg_quality"),
    ("enabled", 1, "sensor.enabled"),
    ("full_well_e", -5, "sensor.full_well_e"),
    ("sharpen", [-0.5, 1], "sensor.sharpen"),
    ("sharpen_sigma_px", [0.1, 1], "sensor.sharpen_sigma_px"),
])
def test_bad_sensor_fields_are_one_line(key, value, words):
    with pytest.raises(UserError) as err:
        config_from_dict({"sensor": {key: value}})
    message = str(err.value)
    assert words in message and "\n" not in message and "[sensor]" in message
