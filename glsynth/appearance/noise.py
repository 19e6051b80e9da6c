"""Noise for procedural textures, vectorised in numpy and periodic (tileable) by construction.

``perlin`` is classic gradient (Perlin) noise with octaves, as the paper's damage uses
(Section 3.3: 8 octaves, base frequency 20-200 % of the texture size). Each octave is computed
with per-axis gathers: the fade weights and offsets depend on x or on y only, so the four
corner terms reduce to row gathers of (grid rows x W) tables instead of per-pixel lookups.
``spectral`` is 1/f^beta noise by FFT filtering, for texture repository images.
"""

import numpy as np


def _fade(t: np.ndarray) -> np.ndarray:
    return t * t * t * (t * (t * 6.0 - 15.0) + 10.0)


def _axis(n: int, cells: int, offset: float, start: int = 0, stop: int | None = None
          ) -> tuple[np.ndarray, ...]:
    """Per-pixel cell indices of both corners (wrapped), fade weights and offsets along one axis,
    for pixels [start, stop)."""
    u = (np.arange(start, n if stop is None else stop) + 0.5) * (cells / n) + offset
    i0 = np.floor(u).astype(np.int64)
    t = (u - i0).astype(np.float32)
    w1 = _fade(t)
    return i0 % cells, (i0 + 1) % cells, 1.0 - w1, w1, t, t - 1.0


def _octave_tables(width: int, cells_y: int, cells_x: int, rng: np.random.Generator
                   ) -> tuple[np.ndarray, np.ndarray, float]:
    """Random gradients of one octave folded with the x axis: tables over (grid row, column)."""
    angle = rng.uniform(0.0, 2.0 * np.pi, size=(cells_y, cells_x))
    gx, gy = np.cos(angle).astype(np.float32), np.sin(angle).astype(np.float32)
    oy, ox = rng.uniform(0.0, 1.0, size=2)
    ix0, ix1, wx0, wx1, dx0, dx1 = _axis(width, cells_x, ox * cells_x)
    gxw = gx[:, ix0] * (wx0 * dx0) + gx[:, ix1] * (wx1 * dx1)  # x-gradient terms
    gyw = gy[:, ix0] * wx0 + gy[:, ix1] * wx1                  # y-gradient terms (times dy)
    return gxw, gyw, float(oy * cells_y)


def _accumulate(total: np.ndarray, height: int, start: int, cells_y: int, tables: tuple,
                amplitude: float) -> None:
    """Add one octave's rows [start, start + len(total)) into ``total`` in place."""
    gxw, gyw, offset = tables
    jy0, jy1, wy0, wy1, dy0, dy1 = _axis(height, cells_y, offset, start, start + len(total))
    for j, w, d in ((jy0, wy0, dy0), (jy1, wy1, dy1)):
        term = np.take(gyw, j, axis=0)
        term *= (w * d * amplitude)[:, None]
        total += term
        term = np.take(gxw, j, axis=0)
        term *= (w * amplitude)[:, None]
        total += term


def perlin(size: int, period_x: float, period_y: float, octaves: int,
           rng: np.random.Generator, persistence: float = 0.5, lacunarity: float = 2.0,
           workers: int = 2) -> np.ndarray:
    """Fractal Perlin noise on a size x size tile, values roughly in [-1, 1], float32.

    period_x/y: feature size of the first octave in pixels (the paper's frq_x, frq_y). Cell
    counts are rounded to whole numbers so that the tile repeats seamlessly; octaves whose cells
    would be smaller than 2 pixels add nothing visible and are skipped. Rows are computed in
    cache-sized blocks on ``workers`` threads (numpy releases the GIL); the result does not
    depend on the number of workers.
    """
    if size < 2 or octaves < 1 or period_x <= 0 or period_y <= 0:
        raise ValueError(f"perlin(size={size}, period=({period_x}, {period_y}), "
                         f"octaves={octaves}): need size >= 2, octaves >= 1, periods > 0")
    plan = []  # (cells_y, tables, amplitude), drawn in octave order so rng use is fixed
    amplitude, norm = 1.0, 0.0
    for k in range(octaves):
        scale = lacunarity ** k
        cx = max(1, round(size * scale / period_x))
        cy = max(1, round(size * scale / period_y))
        if size / max(cx, cy) < 2.0:
            break
        plan.append((cy, _octave_tables(size, cy, cx, rng), amplitude))
        norm += amplitude
        amplitude *= persistence
    total = np.zeros((size, size), np.float32)
    block = max(1, (1 << 19) // size)  # about 2 MB of float32 per block

    def fill(start: int) -> None:
        rows = total[start:start + block]
        for cy, tables, amp in plan:
            _accumulate(rows, size, start, cy, tables, amp)

    starts = range(0, size, block)
    if workers > 1 and size >= 512:
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(workers) as pool:
            list(pool.map(fill, starts))
    else:
        for start in starts:
            fill(start)
    total *= np.float32(1.0 / (norm * 0.7071))  # gradient noise peaks near +-sqrt(2)/2
    return total


def spectral(shape: tuple[int, int], beta: float, rng: np.random.Generator,
             anisotropy: float = 1.0) -> np.ndarray:
    """Periodic 1/f^beta noise normalised to [0, 1]; anisotropy > 1 stretches features along x."""
    h, w = shape
    fy = np.fft.fftfreq(h)[:, None]
    fx = np.fft.rfftfreq(w)[None, :] * anisotropy
    f = np.sqrt(fx * fx + fy * fy)
    f[0, 0] = 1.0
    spectrum = np.fft.rfft2(rng.standard_normal((h, w))) / f ** (beta / 2.0)
    spectrum[0, 0] = 0.0
    out = np.fft.irfft2(spectrum, s=(h, w))
    lo, hi = out.min(), out.max()
    return ((out - lo) / (hi - lo if hi > lo else 1.0)).astype(np.float32)
