"""The light of one environment: a sun sampled per environment, the sky, and the ambient light
the rasterizer derives from them. No GL: the same numbers drive the GLSL shaders and the
Cycles twin (glsynth.render.cycles), so both renderers see one sky and one sun.

Sky models ([lighting] sky):
- ``preetham``: the analytic daylight model of Preetham, Shirley and Smits (1999) as Blender's
  Sky Texture node (type Preetham) evaluates it: Perez functions for luminance Y and the
  chromaticities x, y, normalised so that the zenith gets the model's zenith values; the
  luminance is scaled by 0.06 as Blender does, so one sky strength unit is the node's; xyY to
  linear Rec.709 RGB. Directions below the horizon take the horizon's value (Blender clamps
  the view angle the same way). A sun below the horizon lights nothing and the sky is
  evaluated for a sun on the horizon.
- ``uniform``: one radiance in every direction, ``sky_rgb * uniform_sky_strength``.

Ambient light for the rasterizer: the irradiance that reaches a
surface of normal n from the sky above the horizon and from the ground below it, as order-2
spherical harmonics (Ramamoorthi and Hanrahan 2001, nine coefficients per channel). The ground
is a Lambertian plane of albedo ``ground_albedo`` under the sun and the sky. Occlusion by the
scene itself is the rasterizer's (sky-visibility maps, optionally SSAO).
"""

import math
from dataclasses import dataclass

import numpy as np

from glsynth.core.config import LightingConfig
from glsynth.core.seeding import Stream, make_rng

# CIE XYZ to linear Rec.709 (sRGB primaries, D65): the matrix Blender's colour management uses
# for the sky texture.
XYZ_TO_REC709 = np.array([[3.2404542, -1.5371385, -0.4985314],
                          [-0.9692660, 1.8760108, 0.0415560],
                          [0.0556434, -0.2040259, 1.0572252]])
_HORIZON = math.pi / 2 - 0.001  # view directions are clamped to just above the horizon


@dataclass(frozen=True)
class Preetham:
    """Coefficients of one Preetham sky: zenith (Y, x, y) and Perez A-E for Y, x and y."""

    zenith: np.ndarray
    """(3,) zenith luminance (x 0.06) and chromaticities, after normalisation."""
    perez: np.ndarray
    """(3, 5) Perez coefficients A-E for Y, x, y."""

    @classmethod
    def make(cls, turbidity: float, sun: np.ndarray) -> "Preetham":
        """The sky for a turbidity and a world direction towards the sun (z up)."""
        t = float(turbidity)
        theta = min(math.acos(float(np.clip(sun[2], -1.0, 1.0))), math.pi / 2)
        th2, th3 = theta * theta, theta ** 3
        chi = (4.0 / 9.0 - t / 120.0) * (math.pi - 2.0 * theta)
        y_lum = ((4.0453 * t - 4.9710) * math.tan(chi) - 0.2155 * t + 2.4192) * 0.06
        x_chr = ((0.00166 * th3 - 0.00375 * th2 + 0.00209 * theta) * t * t
                 + (-0.02903 * th3 + 0.06377 * th2 - 0.03202 * theta + 0.00394) * t
                 + (0.11693 * th3 - 0.21196 * th2 + 0.06052 * theta + 0.25886))
        y_chr = ((0.00275 * th3 - 0.00610 * th2 + 0.00317 * theta) * t * t
                 + (-0.04214 * th3 + 0.08970 * th2 - 0.04153 * theta + 0.00516) * t
                 + (0.15346 * th3 - 0.26756 * th2 + 0.06670 * theta + 0.26688))
        perez = np.array([
            [0.1787 * t - 1.4630, -0.3554 * t + 0.4275, -0.0227 * t + 5.3251,
             0.1206 * t - 2.5771, -0.0670 * t + 0.3703],
            [-0.0193 * t - 0.2592, -0.0665 * t + 0.0008, -0.0004 * t + 0.2125,
             -0.0641 * t - 0.8989, -0.0033 * t + 0.0452],
            [-0.0167 * t - 0.2608, -0.0950 * t + 0.0092, -0.0079 * t + 0.2102,
             -0.0441 * t - 1.6537, -0.0109 * t + 0.0529]])
        at_zenith = _perez(perez, np.ones(1), np.array([theta]))[:, 0]
        zenith = np.array([y_lum, x_chr, y_chr]) / at_zenith
        return cls(zenith, perez)


def _perez(perez: np.ndarray, cos_theta: np.ndarray, gamma: np.ndarray) -> np.ndarray:
    """(3, N) Perez function values for Y, x, y."""
    a, b, c, d, e = (perez[:, i:i + 1] for i in range(5))
    return ((1.0 + a * np.exp(b / cos_theta)) *
            (1.0 + c * np.exp(d * gamma) + e * np.cos(gamma) ** 2))


def preetham_radiance(sky: Preetham, sun: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Linear Rec.709 radiance (N, 3) of unit world directions (N, 3), strength 1."""
    d = np.asarray(directions, float).reshape(-1, 3)
    s = _sky_sun(sun)
    gamma = np.arccos(np.clip(d @ s, -1.0, 1.0))
    cos_theta = np.cos(np.minimum(np.arccos(np.clip(d[:, 2], -1.0, 1.0)), _HORIZON))
    lum, x, y = sky.zenith[:, None] * _perez(sky.perez, cos_theta, gamma)
    with np.errstate(divide="ignore", invalid="ignore"):
        xyz = np.stack([np.where(y != 0, x / y * lum, 0.0), lum,
                        np.where(y != 0, (1.0 - x - y) / y * lum, 0.0)], axis=1)
    return xyz @ XYZ_TO_REC709.T


def _sky_sun(sun: np.ndarray) -> np.ndarray:
    """The sun direction the sky is evaluated for: a sun below the horizon is put on it."""
    s = np.asarray(sun, float).copy()
    if s[2] < 0.0:
        s[2] = 0.0
        s /= np.linalg.norm(s) if np.linalg.norm(s) > 0 else 1.0
    return s


@dataclass(frozen=True, kw_only=True)
class Lighting:
    """Everything both renderers need to light one environment."""

    sun_elevation_deg: float
    sun_azimuth_deg: float
    sun_irradiance: float
    """Irradiance on a plane facing the sun (0 when the sun is below the horizon)."""
    sky: str
    turbidity: float
    sky_strength: float
    """Scale of the sky: [lighting] sky_strength for Preetham's, uniform_sky_strength for the
    uniform one."""
    sky_rgb: tuple[float, float, float]
    """Colour of the uniform sky (sky = "uniform"); its radiance is sky_rgb x sky_strength."""
    ground_albedo: tuple[float, float, float]
    """Linear RGB albedo of the ground that lights surfaces from below (the dressed ground's
    mean, glsynth.appearance.materials.surface_albedo; [lighting] ground_albedo without one)."""
    exposure: float
    white_balance: tuple[float, float, float] = (1.0, 1.0, 1.0)
    """Per-channel gains on top of the exposure (a camera's white balance:
    glsynth.appearance.metering); the GL renderer applies them, Cycles and the export do not."""

    @property
    def sun_direction(self) -> np.ndarray:
        """World-space unit vector towards the sun (world z up, azimuth from +x)."""
        el, az = math.radians(self.sun_elevation_deg), math.radians(self.sun_azimuth_deg)
        return np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])

    @property
    def sky_sun_direction(self) -> np.ndarray:
        return _sky_sun(self.sun_direction)

    def preetham(self) -> Preetham:
        return Preetham.make(self.turbidity, self.sun_direction)

    def sky_radiance(self, directions: np.ndarray) -> np.ndarray:
        """Linear RGB radiance (N, 3) of the sky in unit world directions (N, 3)."""
        d = np.asarray(directions, float).reshape(-1, 3)
        if self.sky == "uniform":
            return np.tile(np.array(self.sky_rgb) * self.sky_strength, (len(d), 1))
        return self.sky_strength * preetham_radiance(self.preetham(), self.sun_direction, d)

    def irradiance_sh(self, rows: int = 64) -> tuple[np.ndarray, np.ndarray]:
        """Two (9, 3) coefficient sets, from the sky above the horizon and from the lit ground
        below it: the irradiance on a plane of world normal n is sum_i c_i Y_i(n) (sh_basis)
        of their sum. They are apart so that the rasterizer can occlude the sky alone."""
        dirs, weights = _sphere_grid(rows)
        up = dirs[:, 2] > 0
        sky = np.zeros((len(dirs), 3))
        sky[up] = self.sky_radiance(dirs[up])
        sky_on_ground = (sky[up] * (dirs[up, 2] * weights[up])[:, None]).sum(0)
        sun_on_ground = self.sun_irradiance * max(self.sun_direction[2], 0.0)
        ground = np.zeros((len(dirs), 3))
        ground[~up] = np.asarray(self.ground_albedo) / math.pi * (sky_on_ground + sun_on_ground)
        lobe = np.repeat(_COSINE_LOBE, [1, 3, 5])[:, None]
        basis = sh_basis(dirs).T * weights
        return basis @ sky * lobe, basis @ ground * lobe


LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
"""Rec. 709 luminance weights of linear RGB."""

_COSINE_LOBE = np.array([math.pi, 2.0 * math.pi / 3.0, math.pi / 4.0])
"""Convolution of radiance with the clamped cosine, per SH band (Ramamoorthi and Hanrahan)."""


def sh_basis(dirs: np.ndarray) -> np.ndarray:
    """Real SH basis Y_0..Y_8 of unit directions (N, 3) -> (N, 9); same order as the shader."""
    x, y, z = dirs[:, 0], dirs[:, 1], dirs[:, 2]
    return np.stack([np.full_like(x, 0.282095), 0.488603 * y, 0.488603 * z, 0.488603 * x,
                     1.092548 * x * y, 1.092548 * y * z, 0.315392 * (3 * z * z - 1),
                     1.092548 * x * z, 0.546274 * (x * x - y * y)], axis=1)


def _sphere_grid(rows: int) -> tuple[np.ndarray, np.ndarray]:
    """Cell centres of an equal-angle grid on the sphere and their solid angles (sum 4 pi)."""
    theta_edges = np.linspace(0.0, math.pi, rows + 1)
    theta = (theta_edges[:-1] + theta_edges[1:]) / 2
    phi = (np.arange(2 * rows) + 0.5) * math.pi / rows
    t, p = np.meshgrid(theta, phi, indexing="ij")
    dirs = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).reshape(-1, 3)
    band = (np.cos(theta_edges[:-1]) - np.cos(theta_edges[1:])) * math.pi / rows
    return dirs, np.repeat(band, 2 * rows)


def environment_lighting(config: LightingConfig, root_seed: int, env: int, item: int = 0,
                         ground_albedo: np.ndarray | None = None) -> Lighting:
    """The lighting of environment ``env`` (item 0; pure-texture plate N uses env 0, item
    N + 1): sun elevation, azimuth and irradiance and the sky's turbidity drawn uniformly from
    their [lighting] ranges (a range [a, a] fixes the value). ``ground_albedo`` (linear RGB) is
    the scene's own ground's; without one, [lighting] ground_albedo in grey."""
    rng = make_rng(root_seed, env, Stream.LIGHTING, item)
    elevation, azimuth, irradiance, turbidity = (
        float(rng.uniform(*r)) for r in (config.sun_elevation_deg, config.sun_azimuth_deg,
                                         config.sun_irradiance, config.turbidity))
    albedo = (config.ground_albedo,) * 3 if ground_albedo is None else ground_albedo
    return Lighting(
        sun_elevation_deg=elevation, sun_azimuth_deg=azimuth,
        sun_irradiance=irradiance if elevation > 0 else 0.0,
        sky=config.sky, turbidity=turbidity,
        sky_strength=(config.sky_strength if config.sky == "preetham"
                      else config.uniform_sky_strength),
        sky_rgb=config.sky_rgb, ground_albedo=tuple(float(c) for c in albedo),
        exposure=config.exposure)


SKY_MIN_ELEVATION_DEG = 8.0
"""The sky-visibility directions start this high: lower, the maps would graze the ground."""


def sky_solid_angle(count: int, min_elevation_deg: float = SKY_MIN_ELEVATION_DEG) -> float:
    """Solid angle of each of ``count`` sky_directions."""
    return 2.0 * math.pi * (1.0 - math.sin(math.radians(min_elevation_deg))) / count


def sky_directions(count: int, min_elevation_deg: float = SKY_MIN_ELEVATION_DEG) -> np.ndarray:
    """``count`` world directions spread evenly over the sky above ``min_elevation_deg``
    (equal solid angle per direction: uniform in z, golden-angle azimuths), (count, 3)."""
    z0 = math.sin(math.radians(min_elevation_deg))
    z = z0 + (1.0 - z0) * (np.arange(count) + 0.5) / count
    phi = np.arange(count) * math.pi * (3.0 - math.sqrt(5.0))
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def occlusion_matrices(corners: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """For each direction (K, 3), the orthographic clip-from-world matrix (4x4) whose view
    along it holds every point of ``corners`` (N, 3) with a 1 % margin; depth -1 is the sky
    side. The sky-visibility maps of the rasterizer are drawn with these (K, 4, 4)."""
    from glsynth.world.sunlight import light_frame

    out = []
    for d in directions:
        frame = light_frame(d)
        local = corners @ frame.T
        lo, hi = local.min(0), local.max(0)
        half = (hi[:2] - lo[:2]) / 2 * 1.01 + 1e-3
        c = (lo[:2] + hi[:2]) / 2
        near, far = hi[2] + 1.0, lo[2] - 1.0
        ortho = np.array([[1 / half[0], 0, 0, -c[0] / half[0]],
                          [0, 1 / half[1], 0, -c[1] / half[1]],
                          [0, 0, -2 / (near - far), (near + far) / (near - far)],
                          [0, 0, 0, 1.0]])
        light = np.eye(4)
        light[:3, :3] = frame
        out.append(ortho @ light)
    return np.array(out)
