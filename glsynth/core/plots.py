"""Figures that people look at: trajectory statistics like the paper's Fig. 7."""

import io
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless: no display is ever needed
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from glsynth.core import design  # noqa: E402
from glsynth.core.fileio import atomic_write_bytes  # noqa: E402


def save_figure(fig: "plt.Figure", path: str | Path) -> None:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=120)
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())


def trajectory_histograms(heights_m: np.ndarray, curvatures: np.ndarray,
                          path: str | Path, title: str) -> None:
    """Histograms of viaduct height and |curvature|; red line: straight/curved boundary."""
    fig, (ax_h, ax_c) = plt.subplots(1, 2, figsize=(10, 4))
    ax_h.hist(heights_m, bins=np.arange(design.HEIGHT_MIN_M, design.HEIGHT_MAX_M + 0.25, 0.25),
              color="0.4")
    for bound in (5.5, 7.0, 8.5, 10.0, 12.0):
        ax_h.axvline(bound, color="0.7", linestyle="--", linewidth=0.8)
    ax_h.set(xlabel="viaduct height H [m] (dashed: Table 3 rows)", ylabel="viaducts")
    ax_c.hist(np.abs(curvatures) * 1e3, bins=40, color="0.4")
    ax_c.axvline(1e3 / design.STRAIGHT_RADIUS_M, color="red")
    ax_c.set(xlabel="|curvature| [1/km] (red: radius 5000 m)", ylabel="viaducts")
    fig.suptitle(title)
    fig.tight_layout()
    save_figure(fig, path)
