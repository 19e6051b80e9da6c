"""Post-processing of rendered views: the Section 3.4 filters and the region of reliable damage
recognition (RRDR, Section 4.2, and the RRDR for cracks of docs/design.md), as pure functions of
the maps. Their settings are [filters] (glsynth.core.config.FiltersConfig)."""

import numpy as np

from glsynth.core.config import FiltersConfig
from glsynth.core.labels import Damage

PAPER_FILTERS = FiltersConfig()
RRDR_PX_PER_CM = PAPER_FILTERS.rrdr_px_per_cm
RRDR_DEPTH_RANGE_M = (0.5, 20.0)


def removal_reason(image: np.ndarray, component: np.ndarray, depth: np.ndarray,
                   filters: FiltersConfig = PAPER_FILTERS) -> str | None:
    """Why an image is filtered out (Section 3.4), or None to keep it. Checked in the paper's
    order: mean intensity < 30, a single component label (fewer than min_components), minimum
    depth not larger than 0.5 m."""
    if float(image.mean()) < filters.min_intensity:
        return "dark"
    if np.unique(component).size < filters.min_components:
        return "single_component"
    if float(depth.min()) <= filters.min_depth_m:
        return "too_close"
    return None


def pixels_per_cm(depth_m: np.ndarray, focal_px: float) -> np.ndarray:
    """Image resolution on a fronto-parallel surface: f_px / (100 depth). Depth <= 0 or not
    finite gives 0 (no reliable resolution), never inf or NaN."""
    d = np.asarray(depth_m, dtype=np.float64)
    valid = np.isfinite(d) & (d > 0)
    out = np.zeros(d.shape)
    np.divide(focal_px, 100.0 * d, out=out, where=valid)
    return out


def rrdr(depth_m: np.ndarray, focal_px: float | None, *,
         min_px_per_cm: float = RRDR_PX_PER_CM,
         depth_range_m: tuple[float, float] = RRDR_DEPTH_RANGE_M) -> np.ndarray:
    """Boolean map of reliable damage recognition: >= 1.5 px/cm when the focal length (in
    pixels of this map) is known, else depth within [0.5, 20] m."""
    if focal_px is None:
        d = np.asarray(depth_m)
        return np.isfinite(d) & (d >= depth_range_m[0]) & (d <= depth_range_m[1])
    if not np.isfinite(focal_px) or focal_px <= 0:
        raise ValueError(f"focal_px = {focal_px!r}: must be a positive number of pixels")
    return pixels_per_cm(depth_m, focal_px) >= min_px_per_cm


def pixel_footprint_m(depth_m: np.ndarray, focal_px: float) -> np.ndarray:
    """Width one pixel covers on a fronto-parallel surface, depth / f_px, in metres. Depth <= 0
    or not finite gives inf (no resolution), never NaN."""
    d = np.asarray(depth_m, dtype=np.float64)
    valid = np.isfinite(d) & (d > 0)
    out = np.full(d.shape, np.inf)
    np.divide(d, focal_px, out=out, where=valid)
    return out


def crack_rrdr(depth_m: np.ndarray, focal_px: float, width_mm: float,
               factor: float) -> np.ndarray:
    """The RRDR for cracks: where a crack of ``width_mm`` is resolved, i.e. the pixel
    footprint is at most ``factor`` times the width (docs/design.md, "RRDR for cracks")."""
    if not np.isfinite(focal_px) or focal_px <= 0:
        raise ValueError(f"focal_px = {focal_px!r}: must be a positive number of pixels")
    return pixel_footprint_m(depth_m, focal_px) <= factor * (width_mm / 1000.0)


def view_rrdr(filters: FiltersConfig, depth_m: np.ndarray, focal_px: float) -> np.ndarray:
    """The RRDR that [filters] asks for: the paper's, or the one for cracks."""
    if filters.rrdr_crack_mm > 0:
        return crack_rrdr(depth_m, focal_px, filters.rrdr_crack_mm,
                          filters.rrdr_footprint_factor)
    return rrdr(depth_m, focal_px, min_px_per_cm=filters.rrdr_px_per_cm)


def mask_damage(damage: np.ndarray, reliable: np.ndarray) -> np.ndarray:
    """Section 4.2: damage labels outside the RRDR become 0 (unlabelled, ignored). Whether an
    image has damage in the RRDR is read from the map as written (after downsampling)."""
    if damage.shape != reliable.shape:
        raise ValueError(f"damage map {damage.shape} and RRDR {reliable.shape} differ in size")
    out = damage.copy()
    out[(damage >= Damage.CONCRETE) & ~reliable] = Damage.UNLABELLED
    return out
