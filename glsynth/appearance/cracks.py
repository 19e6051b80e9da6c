"""Cracks as curves with a width on a member's surface (issue 29): the data type the renderer
draws. A crack network holds straight segments in the member's mesh frame (metres) with a
width at each end; a crack turning a column's corner is two segments meeting on the shared
edge."""

from dataclasses import dataclass

import numpy as np

KINDS = ("flexural", "shear")
MAX_WIDTH_M = 0.01
"""No crack is wider than 10 mm."""


@dataclass(frozen=True)
class CrackNetwork:
    """Cracks on one member's surface, in the member's mesh frame (metres)."""

    points: np.ndarray
    """(N, 2, 3) float64: the end points of N straight segments, on the member's surface."""
    widths_m: np.ndarray
    """(N, 2) float64: the crack's width at each end point, in metres, measured across the
    crack on the surface; linear in between. 0.05 mm .. 5 mm."""
    crack: np.ndarray
    """(N,) int32: the crack (0 .. K-1) each segment belongs to."""
    kinds: tuple[str, ...]
    """(K,) per crack: "flexural" or "shear"."""

    def __post_init__(self) -> None:
        n = len(self.points) if isinstance(self.points, np.ndarray) else -1
        for name, value, shape, dtype in (("points", self.points, (n, 2, 3), np.float64),
                                          ("widths_m", self.widths_m, (n, 2), np.float64),
                                          ("crack", self.crack, (n,), np.int32)):
            if not isinstance(value, np.ndarray) or value.shape != shape or value.dtype != dtype:
                got = (value.dtype, value.shape) if isinstance(value, np.ndarray) else value
                raise ValueError(f"CrackNetwork.{name}: {got}; must be {np.dtype(dtype)} "
                                 f"of shape {shape}")
        if not (np.all(np.isfinite(self.points)) and np.all(np.isfinite(self.widths_m))):
            raise ValueError("CrackNetwork: points and widths must be finite")
        if n and not (self.widths_m.min() > 0 and self.widths_m.max() <= MAX_WIDTH_M):
            raise ValueError(f"CrackNetwork.widths_m: {self.widths_m.min()} .. "
                             f"{self.widths_m.max()} m; must lie in (0, {MAX_WIDTH_M}] m")
        if not isinstance(self.kinds, tuple) or any(k not in KINDS for k in self.kinds):
            raise ValueError(f"CrackNetwork.kinds = {self.kinds!r}: a tuple of {KINDS}")
        used = np.unique(self.crack)
        if not np.array_equal(used, np.arange(len(self.kinds))):
            raise ValueError(f"CrackNetwork.crack: ids {used.tolist()}; every crack "
                             f"0 .. {len(self.kinds) - 1} must have segments, and no other")
