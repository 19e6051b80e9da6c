"""Procedural concrete damage and exposed rebar (paper Section 3.3), as pure numpy functions.

Pipeline for one texture (all maps size x size, tileable):
1. N: 8-octave Perlin noise with first-octave feature sizes (frq_x, frq_y) drawn in 20-200 % of
   the size.
2. t: set so that exactly round(area * size^2) pixels have |N| < t.
3. P- = min(t, |N|); P = d * normalize(t - P-): depth into the surface, 0 on intact concrete,
   d at the deepest point; P = 0 everywhere when t - P- is 0 everywhere (no damage or d = 0).
4. Rebar: axial bars (vertical, radius size/200) and stirrups (horizontal, radius size/300) as
   cylinders with 10 % sinusoidal ripples, covers c_a ~ U[2.5, 7.5] cm and c_s = c_a - 2 cm,
   spacings 3-10 diameters (rounded so the tile repeats). Where P is deeper than the rebar
   surface, the rebar profile replaces the concrete profile.
5. Masks 1 no damage / 2 concrete damage / 3 exposed rebar; RGB from two concrete images and a
   steel image; metallic 1 on rebar; roughness 1; normal map from the displacement.
Depths are metres for a texture tile of ``tile_m`` metres (texture scale 1.0).
"""

from dataclasses import dataclass

import cv2
import numpy as np

from glsynth.appearance.noise import perlin
from glsynth.core.config import SEVERITIES as SEVERITIES  # re-exported for the bank and plates
from glsynth.core.config import DamageConfig
from glsynth.core.labels import Damage


@dataclass(frozen=True)
class DamageParams:
    """The sampled values behind one damage texture (recorded in metadata)."""

    severity: str
    area: float
    """Target damaged-area fraction."""
    depth_m: float
    """d, the maximum damage depth."""
    period_px: tuple[float, float]
    """(frq_x, frq_y): first-octave feature size in pixels."""
    axial_cover_m: float
    stirrup_cover_m: float
    axial_spacing_px: float
    stirrup_spacing_px: float


@dataclass(frozen=True)
class DamageMaps:
    mask: np.ndarray
    """(S, S) uint8 damage ids 1/2/3, a partition of the texture."""
    displacement_m: np.ndarray
    """(S, S) float32 depth into the surface, >= 0."""
    threshold: float


def sample_params(cfg: DamageConfig, severity: str, rng: np.random.Generator,
                  size: int | None = None) -> DamageParams:
    size = size or cfg.resolution
    area = rng.uniform(*cfg.area_range(severity))
    depth = rng.uniform(*cfg.depth_range_m(severity))
    period = tuple(float(rng.uniform(*cfg.frequency)) * size for _ in range(2))
    cover = rng.uniform(*cfg.axial_cover_cm) / 100.0
    spacing = [rng.uniform(*cfg.spacing_diameters) * 2 * r * size
               for r in (cfg.axial_radius, cfg.stirrup_radius)]
    return DamageParams(severity, float(area), float(depth), period, float(cover),
                        float(cover - cfg.stirrup_cover_offset_cm / 100.0), *map(float, spacing))


def threshold_for_area(abs_noise: np.ndarray, area: float) -> float:
    """t such that exactly round(area * n) values of |N| lie strictly below it (no ties)."""
    if not 0.0 <= area <= 1.0:
        raise ValueError(f"area = {area!r}: must be a fraction in [0, 1]")
    flat = abs_noise.ravel()
    k = int(round(area * flat.size))
    if k == 0:
        return 0.0
    if k == flat.size:
        return float(np.nextafter(flat.max(), np.inf, dtype=abs_noise.dtype))
    return float(np.partition(flat, k)[k])


def concrete_profile(noise: np.ndarray, area: float, depth_m: float
                     ) -> tuple[np.ndarray, float]:
    """Equations (1)-(2): P = d * normalize(t - min(t, |N|)); safe when the maximum is 0."""
    abs_noise = np.abs(noise)
    t = threshold_for_area(abs_noise, area)
    gap = np.float32(t) - np.minimum(np.float32(t), abs_noise)
    peak = float(gap.max())
    if peak <= 0.0 or depth_m <= 0.0:
        return np.zeros_like(abs_noise, dtype=np.float32), t
    return (gap * np.float32(depth_m / peak)).astype(np.float32), t


def _bars(n: int, spacing_px: float, radius_px: float, ripple: float, phase: float
          ) -> tuple[np.ndarray, np.ndarray]:
    """Across-bar distance to the nearest bar axis (length n) and the rippled radius along the
    bars (length n), both in pixels; the bar count is rounded so the pattern repeats."""
    count = max(1, round(n / spacing_px))
    pitch = n / count
    x = np.arange(n) + 0.5
    across = np.abs((x - phase * pitch) % pitch - pitch / 2)
    wavelength = 2.0 * radius_px  # one rib per bar diameter
    along = radius_px * (1.0 + ripple * np.sin(2 * np.pi * x / wavelength))
    return across.astype(np.float32), along.astype(np.float32)


def rebar_depth(size: int, params: DamageParams, cfg: DamageConfig,
                rng: np.random.Generator) -> np.ndarray:
    """Depth of the rebar surface below the concrete surface (metres); inf where no bar."""
    px_m = cfg.tile_m / size
    out = np.full((size, size), np.inf, np.float32)
    for spacing, frac, cover, vertical in (
            (params.axial_spacing_px, cfg.axial_radius, params.axial_cover_m, True),
            (params.stirrup_spacing_px, cfg.stirrup_radius, params.stirrup_cover_m, False)):
        radius = frac * size
        across, along = _bars(size, spacing, radius, cfg.ripple, rng.uniform())
        # Axial bars run along the texture's v (image rows); stirrups along u (columns).
        rho = across[None, :] if vertical else across[:, None]
        r = along[:, None] if vertical else along[None, :]
        inside = rho < r
        half_chord = np.sqrt(np.where(inside, r * r - rho * rho, 0.0))
        # Cover is measured to the outermost rib: the bar axis lies at cover + r (1 + ripple).
        axis = cover + radius * (1.0 + cfg.ripple) * px_m
        depth = np.float32(axis) - half_chord * np.float32(px_m)
        np.minimum(out, np.where(inside, depth, np.inf), out=out)
    return out


def damage_maps(params: DamageParams, cfg: DamageConfig, rng: np.random.Generator,
                size: int | None = None) -> DamageMaps:
    size = size or cfg.resolution
    noise = perlin(size, params.period_px[0], params.period_px[1], cfg.octaves, rng)
    concrete, t = concrete_profile(noise, params.area, params.depth_m)
    rebar = rebar_depth(size, params, cfg, rng)
    exposed = concrete > rebar
    mask = np.full((size, size), Damage.NO_DAMAGE, np.uint8)
    mask[concrete > 0] = Damage.CONCRETE
    mask[exposed] = Damage.REBAR
    displacement = np.where(exposed, rebar, concrete).astype(np.float32)
    return DamageMaps(mask, displacement, t)


def _periodic_diff(h: np.ndarray, axis: int) -> np.ndarray:
    """h[i + 1] - h[i - 1] along ``axis``, wrapping around (the texture tiles)."""
    out = np.empty_like(h)
    a = np.moveaxis(h, axis, 0)
    o = np.moveaxis(out, axis, 0)
    np.subtract(a[2:], a[:-2], out=o[1:-1])
    np.subtract(a[1:2], a[-1:], out=o[:1])
    np.subtract(a[:1], a[-2:-1], out=o[-1:])
    return out


def _unit_normals(nx: np.ndarray, ny: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit normals (x, y, z) from the slopes -dh/du and -dh/dv (float32, changed in place)."""
    inv = nx * nx
    inv += ny * ny
    inv += 1.0
    np.sqrt(inv, out=inv)
    np.reciprocal(inv, out=inv)
    nx *= inv
    ny *= inv
    return nx, ny, inv


def normal_components(displacement_m: np.ndarray, pixel_m: float
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit tangent-space normal (x, y, z planes, float32) of the surface height -displacement;
    x along u (image columns), y along v (up, towards row 0); periodic central differences."""
    k = np.float32(1.0 / (2.0 * pixel_m))
    nx = _periodic_diff(displacement_m.astype(np.float32), 1)
    nx *= k                      # -dh/du with h = -displacement
    ny = _periodic_diff(displacement_m.astype(np.float32), 0)
    ny *= -k                     # -dh/dv, v running up the image
    return _unit_normals(nx, ny)


def encode_normals(nx: np.ndarray, ny: np.ndarray, nz: np.ndarray) -> np.ndarray:
    """Normal planes in [-1, 1] to an (S, S, 3) uint8 normal map."""
    out = np.empty(nx.shape + (3,), np.uint8)
    tmp = np.empty_like(nx)
    for c, plane in enumerate((nx, ny, nz)):
        np.multiply(plane, 127.5, out=tmp)
        tmp += 128.0  # round half up: the cast truncates non-negative values
        out[..., c] = tmp
    return out


def normal_map(displacement_m: np.ndarray, pixel_m: float) -> np.ndarray:
    """``encode_normals(*normal_components(displacement_m, pixel_m))``, byte for byte, computed
    only where the surface is not flat. Damage covers 0-30 % of a texture, and a flat pixel's
    normal (0, 0, 1) always encodes as (128, 128, 255); the same float32 operations in the
    same order on the rest give the same bytes (tested against the dense path)."""
    d = displacement_m.astype(np.float32, copy=False)
    k = np.float32(1.0 / (2.0 * pixel_m))
    dx, dy = _periodic_diff(d, 1), _periodic_diff(d, 0)
    where = np.flatnonzero(np.logical_or(dx != 0, dy != 0))
    nx = dx.ravel()[where]
    nx *= k
    ny = dy.ravel()[where]
    ny *= -k
    out = np.empty(d.shape + (3,), np.uint8)
    # One flat row copied down the image: 6x faster than broadcasting a pixel.
    out.reshape(d.shape[0], -1)[:] = np.tile(np.array([128, 128, 255], np.uint8), d.shape[1])
    out.reshape(-1, 3)[where] = encode_normals(*_unit_normals(nx, ny))
    return out


def compose_rgb(mask: np.ndarray, intact: np.ndarray, damaged: np.ndarray,
                steel: np.ndarray) -> np.ndarray:
    """(RGB-1..3): overlay the three images (each (S, S, 3) uint8) with the masks."""
    out = np.array(intact, copy=True, order="C")
    for damage_id, image in ((Damage.CONCRETE, damaged), (Damage.REBAR, steel)):
        # OpenCV's masked copy: 10x faster than numpy's boolean indexing at 2048 px.
        cv2.copyTo(np.ascontiguousarray(image), (mask == damage_id).view(np.uint8), out)
    return out


def metallic_map(mask: np.ndarray) -> np.ndarray:
    """The metallic map: 255 on exposed rebar, 0 elsewhere."""
    return np.where(mask == Damage.REBAR, np.uint8(255), np.uint8(0))
