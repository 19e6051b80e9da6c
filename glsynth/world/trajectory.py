"""Random viaduct trajectories (paper Section 3.1, steps i-iii, Table 4).

Three band-limited noise sequences, one value per viaduct, come from the inverse FFT of rectangular
spectra with uniform random phase: ground-height increments, viaduct-height increments and
centre-line curvature. The curvature is scaled so that the smallest radius along the trajectory
is a sampled value. The constraints are then enforced viaduct by viaduct (a projection that
keeps the noise wherever it is feasible).

Geometry: x along the initial direction, y to the left, z up. The centre line is a chain of
circular arcs, one constant curvature per viaduct, evaluated in closed form with a sinc chord so
that straight track (curvature 0) needs no special case. Ground and deck-top elevations are
piecewise linear in arc length through the values at the viaduct centres.
"""

import functools
from dataclasses import dataclass

import numpy as np

from glsynth.core.config import EnvironmentConfig


def band_limited_noise(n: int, cutoff: float, amplitude: float,
                       rng: np.random.Generator) -> np.ndarray:
    """Inverse (unitary) FFT of a rectangular spectrum: ``amplitude`` for every frequency up to
    ``cutoff`` cycles per sample, 0 above, each with a uniform random phase."""
    freqs = np.fft.rfftfreq(n)
    phase = rng.uniform(0.0, 2.0 * np.pi, size=freqs.size)
    spectrum = np.where(freqs <= cutoff + 1e-12, amplitude, 0.0) * np.exp(1j * phase)
    return np.fft.irfft(spectrum, n=n, norm="ortho")


def _uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    """U[lo, hi], also for lo == hi == inf; always draws one number to keep streams aligned."""
    u = rng.random()
    return lo if lo == hi else lo + u * (hi - lo)


def enforce_constraints(ground_inc: np.ndarray, height_inc: np.ndarray, initial_height: float,
                        length_m: float, height_limits: tuple[float, float], max_slope: float
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Ground elevations and viaduct heights at the viaduct centres that satisfy Table 4.

    Viaduct i proposes ground G_i = G_{i-1} + g_i and height H_i = H_{i-1} + h_i. The deck top
    G_i + H_i must lie within the slope window around the previous deck top; the ground is first
    moved only if no height within the limits can reach that window, then H_i is clamped to the
    window and the limits. Heights are kept as their own array (not deck - ground) so that they
    sit exactly inside the limits. |S| < max_slope stays strict through a relative margin of 1e-9.
    """
    lo_h, hi_h = height_limits
    n = ground_inc.size
    ground = np.zeros(n)
    height = np.empty(n)
    height[0] = initial_height
    rise = max_slope * length_m * (1.0 - 1e-9)
    for i in range(1, n):
        deck_prev = ground[i - 1] + height[i - 1]
        z_lo, z_hi = deck_prev - rise, deck_prev + rise
        g = min(max(ground[i - 1] + ground_inc[i], z_lo - hi_h), z_hi - lo_h)
        h = min(max(height[i - 1] + height_inc[i], z_lo - g), z_hi - g)
        ground[i], height[i] = g, min(max(h, lo_h), hi_h)
    return ground, height


@dataclass(frozen=True)
class Trajectory:
    """A trajectory of N viaducts of length L, viaduct i spanning arc length [iL, (i+1)L]."""

    length_m: float
    curvature: np.ndarray
    """Signed curvature per viaduct [1/m]; positive turns left."""
    ground_m: np.ndarray
    """Ground elevation at the viaduct centres."""
    heights_m: np.ndarray
    """Viaduct height H: ground to deck top at the viaduct centre (Table 3's H)."""
    min_radius_m: float
    initial_height_m: float

    def __post_init__(self) -> None:
        for name in ("curvature", "ground_m", "heights_m"):
            getattr(self, name).setflags(write=False)

    @property
    def n(self) -> int:
        return self.curvature.size

    @property
    def total_length_m(self) -> float:
        return self.n * self.length_m

    @property
    def deck_m(self) -> np.ndarray:
        """Deck-top elevation at the viaduct centres."""
        return self.ground_m + self.heights_m

    @property
    def radii_m(self) -> np.ndarray:
        """Radius of curvature per viaduct; inf where the curvature is exactly 0."""
        with np.errstate(divide="ignore"):
            return 1.0 / np.abs(self.curvature)

    @property
    def slopes(self) -> np.ndarray:
        """Deck slope between neighbouring viaduct centres."""
        return np.diff(self.deck_m) / self.length_m

    @property
    def centres_s(self) -> np.ndarray:
        return (np.arange(self.n) + 0.5) * self.length_m

    @functools.cached_property
    def _segments(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Start arc length, heading, xy and curvature of each arc, plus a straight lead-out;
        found once (the fields are frozen and read-only): frame() is called hundreds of
        times an environment, and remaking them at each call was a sixth of a build."""
        kappa = np.append(self.curvature, 0.0)
        s0 = np.arange(self.n + 1) * self.length_m
        theta0 = np.concatenate([[0.0], np.cumsum(self.curvature * self.length_m)])
        xy0 = np.zeros((self.n + 1, 2))
        for i in range(self.n):
            xy0[i + 1] = xy0[i] + _arc_offset(theta0[i], kappa[i], self.length_m)
        for array in (s0, theta0, xy0, kappa):
            array.setflags(write=False)
        return s0, theta0, xy0, kappa

    def frame(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Centre-line points (xy, z = deck top), unit tangents and left normals at arc lengths s.

        Before s = 0 and after the last viaduct the centre line runs on straight.
        """
        s = np.asarray(s, dtype=float)
        s0, theta0, xy0, kappa = self._segments
        seg = np.clip(np.searchsorted(s0, s, side="right") - 1, 0, self.n)
        ds = s - s0[seg]
        k = np.where(ds < 0, 0.0, kappa[seg])  # before s = 0: straight on the initial heading
        xy = xy0[seg] + _arc_offset(theta0[seg], k, ds)
        theta = theta0[seg] + k * ds
        tangent = np.stack([np.cos(theta), np.sin(theta), np.zeros_like(theta)], axis=-1)
        normal = np.stack([-np.sin(theta), np.cos(theta), np.zeros_like(theta)], axis=-1)
        points = np.concatenate([xy, self.deck_at(s)[..., None]], axis=-1)
        return points, tangent, normal

    def heading(self, s: np.ndarray) -> np.ndarray:
        _, tangent, _ = self.frame(s)
        return np.arctan2(tangent[..., 1], tangent[..., 0])

    def deck_at(self, s: np.ndarray) -> np.ndarray:
        return np.interp(s, self.centres_s, self.deck_m)

    def ground_at(self, s: np.ndarray) -> np.ndarray:
        return np.interp(s, self.centres_s, self.ground_m)


def _arc_offset(theta0: np.ndarray, kappa: np.ndarray, ds: np.ndarray) -> np.ndarray:
    """xy displacement after arc length ds from heading theta0 with curvature kappa.

    The chord has length ds * sinc(kappa ds / 2) in direction theta0 + kappa ds / 2: exact for
    arcs and finite at kappa = 0 (np.sinc(x) = sin(pi x) / (pi x)).
    """
    half = 0.5 * np.asarray(kappa) * ds
    chord = ds * np.sinc(half / np.pi)
    direction = theta0 + half
    return np.stack([chord * np.cos(direction), chord * np.sin(direction)], axis=-1)


def generate_trajectory(cfg: EnvironmentConfig, length_m: float,
                        rng: np.random.Generator) -> Trajectory:
    """Steps (i)-(iii) of Section 3.1. Draw order is fixed: initial height, minimum radius, then
    the phases of the ground, height and curvature spectra."""
    n = cfg.n_viaducts
    initial_height = _uniform(rng, *cfg.initial_height_m)
    min_radius = _uniform(rng, *cfg.min_radius_m)
    cutoff = cfg.cutoff_factor / n
    ground_inc = band_limited_noise(n, cutoff, cfg.ground_amplitude_m, rng)
    height_inc = band_limited_noise(n, cutoff, cfg.height_amplitude_m, rng)
    shape = band_limited_noise(n, cutoff, 1.0, rng)
    peak = np.abs(shape).max()
    if np.isinf(min_radius) or peak == 0.0:
        curvature = np.zeros(n)
    else:
        curvature = shape / (peak * min_radius)
    ground, heights = enforce_constraints(ground_inc, height_inc, initial_height, length_m,
                                          cfg.height_limits_m, cfg.max_slope)
    return Trajectory(length_m, curvature, ground, heights, float(min_radius),
                      float(initial_height))
