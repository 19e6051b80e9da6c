"""Shader unit tests: the colour pass's lighting functions (shaders/lighting.glsl, which
color.frag includes) run alone over random inputs through tests/shader_harness.py and match
numpy references of the same formulas (docs/design.md, "Rendering") within float32
tolerance."""

import numpy as np
import pytest
from shader_harness import GlslHarness

from glsynth.appearance.materials import srgb_decode
from glsynth.core.seeding import Stream, make_rng
from glsynth.world.lighting import sh_basis

N = 4096
RTOL = 2e-4
"""float32 arithmetic, and llvmpipe's pow, exp2 and log2 (a few ulps each), against float64."""


@pytest.fixture(scope="module")
def glsl():
    with GlslHarness("lighting.glsl") as harness:
        yield harness


def _rows(*columns: np.ndarray) -> np.ndarray:
    """Columns (n,) or (n, k) side by side, padded with zeros to (n, 4) float32."""
    out = np.hstack([np.asarray(c, np.float64).reshape(len(c), -1) for c in columns])
    return np.pad(out, ((0, 0), (0, 4 - out.shape[1]))).astype(np.float32)


def _unit(rng: np.random.Generator, n: int) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _facing(rng: np.random.Generator, n: np.ndarray) -> np.ndarray:
    """Unit directions on the side of normals ``n``, as a view direction is."""
    v = _unit(rng, len(n))
    return v * np.sign(np.sum(v * n, axis=1, keepdims=True) + 1e-12)


def ggx_specular(nl, nv, nh, vh, roughness, f0):
    """GGX (Trowbridge-Reitz) distribution, Smith-Schlick shadowing, Schlick Fresnel."""
    a2 = roughness ** 4
    d = a2 / (np.pi * (nh * nh * (a2 - 1) + 1) ** 2)
    k = (roughness + 1) ** 2 / 8
    g = (nl / (nl * (1 - k) + k)) * (nv / (nv * (1 - k) + k))
    f = f0 + (1 - f0) * (1 - vh)[:, None] ** 5
    return (d * g / np.maximum(4 * nl * nv, 1e-4))[:, None] * f


def burley_diffuse(nl, nv, lv, roughness):
    """Burley's diffuse with retro-reflection, as Cycles' Principled BSDF."""
    fl, fv = (1 - nl) ** 5, (1 - nv) ** 5
    rr = roughness * (1 + lv)
    return (1 - 0.5 * fl) * (1 - 0.5 * fv) + rr * (fl + fv + fl * fv * (rr - 1))


def _surfaces(rng: np.random.Generator) -> tuple[np.ndarray, ...]:
    """Random materials as the shader's Surface: base (n, 3), metallic, roughness, f0."""
    base = rng.uniform(0, 1, (N, 3))
    metallic = np.where(rng.uniform(size=N) < 0.3, rng.uniform(0, 1, N), 0.0)
    roughness = rng.uniform(0.04, 1.0, N)
    f0 = 0.04 * (1 - metallic[:, None]) + base * metallic[:, None]
    return base, metallic, roughness, f0


SURFACE = "Surface(in0.rgb, in0.a, in1.w, in1.rgb)"
"""The Surface of rows in0 (base, metallic) and in1 (f0, roughness)."""


def test_srgb_to_linear_is_the_exact_curve(glsl):
    codes = np.arange(256.0)
    out = glsl.run("srgb_to_linear(in0.rgb), 0.0", _rows(codes / 255.0))
    assert np.allclose(out[:, 0], srgb_decode(codes), rtol=RTOL, atol=1e-7)


def test_sh_irradiance_is_the_basis_weighted_sum_clamped_at_zero(glsl):
    rng = make_rng(11, 0, Stream.LIGHTING)
    normals = _unit(rng, N)
    coefficients = rng.normal(0, 1, (9, 3))  # negative sums too, which the shader clamps
    out = glsl.run("sh_irradiance(u_sh_sky, in0.xyz), 0.0", _rows(normals),
                   setup=lambda prog: prog["u_sh_sky"].write(coefficients.astype("f4")))
    expected = np.maximum(sh_basis(normals) @ coefficients, 0.0)
    assert (expected == 0).any() and (expected > 0).any()
    assert np.allclose(out[:, :3], expected, rtol=RTOL, atol=1e-5)


def test_ggx_and_burley_match_their_formulas(glsl):
    rng = make_rng(12, 0, Stream.LIGHTING)
    cosines = rng.uniform(1e-3, 1.0, (N, 5))  # nl, nv, nh, vh, lv
    cosines[:, 4] = rng.uniform(-1.0, 1.0, N)
    roughness = rng.uniform(0.04, 1.0, N)
    f0 = rng.uniform(0.02, 1.0, (N, 3))
    nl, nv, nh, vh, lv = cosines.T
    out = glsl.run("ggx_specular(in0.x, in0.y, in0.z, in0.w, in1.w, in1.rgb), "
                   "burley_diffuse(in0.x, in0.y, in2.x, in1.w)",
                   _rows(cosines[:, :4]), _rows(f0, roughness), _rows(lv))
    assert np.allclose(out[:, :3], ggx_specular(nl, nv, nh, vh, roughness, f0), rtol=RTOL,
                       atol=1e-6)
    assert np.allclose(out[:, 3], burley_diffuse(nl, nv, lv, roughness), rtol=RTOL)


def test_sun_light_is_the_brdf_times_the_sun_and_the_cosine(glsl):
    rng = make_rng(13, 0, Stream.LIGHTING)
    base, metallic, roughness, f0 = _surfaces(rng)
    n = _unit(rng, N)
    v = _facing(rng, n)
    sun = np.array([0.3, -0.5, 0.8])
    sun_color = np.array([3.0, 2.5, 2.0])

    def setup(prog):
        prog["u_sun_dir"].value = tuple(sun)
        prog["u_sun_color"].value = tuple(sun_color)
    out = glsl.run(f"sun_light({SURFACE}, in2.xyz, in3.xyz), 0.0", _rows(base, metallic),
                   _rows(f0, roughness), _rows(n), _rows(v), setup=setup)
    s = sun / np.linalg.norm(sun)
    h = (s + v) / np.linalg.norm(s + v, axis=1, keepdims=True)
    nl, nv = np.maximum(n @ s, 0.0), np.maximum(np.sum(n * v, axis=1), 1e-4)
    nh, vh = (np.maximum(np.sum(x * h, axis=1), 0.0) for x in (n, v))
    diffuse = (burley_diffuse(nl, nv, v @ s, roughness) * (1 - metallic))[:, None] * base / np.pi
    expected = (diffuse + ggx_specular(nl, nv, nh, vh, roughness, f0)) * sun_color * nl[:, None]
    assert (nl == 0).any() and (nl > 0.5).any()  # both sides of the terminator
    assert np.allclose(out[:, :3], expected, rtol=RTOL, atol=1e-5)


def test_ambient_light_weighs_sky_and_ground_by_visibility(glsl):
    rng = make_rng(14, 0, Stream.LIGHTING)
    base, metallic, roughness, f0 = _surfaces(rng)
    n = _unit(rng, N)
    v = _facing(rng, n)
    vis = rng.uniform(0, 1, (N, 2))
    hidden = rng.uniform(0, 0.5, (N, 3))
    sky, ground = rng.uniform(0, 1, (9, 3)), rng.uniform(0, 0.3, (9, 3))
    sky[0], ground[0] = 3.0, 1.0  # mostly positive, as a real sky's
    angle = 0.7
    world_from_view = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0],
                                [-np.sin(angle), 0, np.cos(angle)]])

    def setup(prog):
        prog["u_sh_sky"].write(sky.astype("f4"))
        prog["u_sh_ground"].write(ground.astype("f4"))
        prog["u_world_from_view"].write(world_from_view.T.astype("f4").tobytes())  # by columns
        prog["u_has_ao"].value = False
    out = glsl.run(f"ambient_light({SURFACE}, in2.xyz, in3.xyz, in4.xy, in5.rgb), 0.0",
                   _rows(base, metallic), _rows(f0, roughness), _rows(n), _rows(v),
                   _rows(vis), _rows(hidden), setup=setup)
    assert np.allclose(out[:, :3], _ambient(base, metallic, roughness, f0, n, v, vis, hidden,
                                            sky, ground, world_from_view),
                       rtol=RTOL, atol=1e-5)


def _ambient(base, metallic, roughness, f0, n, v, vis, hidden, sky, ground, world_from_view):
    """ambient_light's formula: SH irradiance of sky (through its visibility) and ground
    (through the mean openness, at least a quarter), plus the hiding parts' light, diffuse
    by the normal and specular by the reflected direction."""
    def irradiance(coefficients, d):
        return np.maximum(sh_basis(d @ world_from_view.T) @ coefficients, 0.0)
    r = 2 * np.sum(n * v, axis=1, keepdims=True) * n - v
    ground_share = (0.25 + 0.75 * vis[:, 1])[:, None]
    sky_vis = vis[:, :1]
    env_diffuse = (irradiance(sky, n) * sky_vis + irradiance(ground, n) * ground_share
                   + hidden) / np.pi
    env_specular = (irradiance(sky, r) * sky_vis + irradiance(ground, r) * ground_share) / np.pi
    nv = np.maximum(np.sum(n * v, axis=1), 1e-4)[:, None]
    f_env = f0 + (np.maximum(1 - roughness[:, None], f0) - f0) * (1 - nv) ** 5
    return ((1 - metallic[:, None]) * base * env_diffuse
            + f_env * env_specular * (1 - 0.7 * roughness[:, None]))
