"""Post-processing of rendered views: the Section 3.4 filters and the region of reliable damage
recognition (RRDR, Section 4.2, and the RRDR for cracks of docs/design.md), as pure functions of
the maps. Their settings are [filters] (glsynth.core.config.FiltersConfig)."""

import cv2
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
    if is_dark(image, filters):
        return "dark"
    return label_reason(component, depth, filters)


def is_dark(image: np.ndarray, filters: FiltersConfig = PAPER_FILTERS) -> bool:
    """The first filter: the image's mean intensity under min_intensity."""
    return float(image.mean()) < filters.min_intensity


def label_reason(component: np.ndarray, depth: np.ndarray,
                 filters: FiltersConfig = PAPER_FILTERS) -> str | None:
    """removal_reason's answer for a view that is not dark: the filters after the first."""
    if _distinct(component) < filters.min_components:
        return "single_component"
    if float(depth.min()) <= filters.min_depth_m:
        return "too_close"
    return None


def _distinct(labels: np.ndarray) -> int:
    """How many different values ``labels`` holds (np.unique's size; a uint8 map by its
    histogram, cheaper than np.unique's sort or hash)."""
    if labels.dtype == np.uint8:
        return int(np.count_nonzero(np.bincount(labels.ravel(), minlength=256)))
    return int(np.unique(labels).size)


_CROSS = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
"""A pixel and its four neighbours: where the MSAA resolve takes a pixel's colours from."""


def removal_before_resolve(single_sample: np.ndarray, by_labels: str | None,
                           filters: FiltersConfig = PAPER_FILTERS) -> str | None:
    """removal_reason's answer for a view rendered with MSAA, where its single-sample colour
    (H, W, 3) uint8 decides it, given ``by_labels`` (label_reason); None where only the
    resolved colour can (the view is kept, or dark by a margin too small to call here).

    The resolve (shaders/msaa_resolve.frag, msaa_interior.frag) gives every channel of a
    pixel the mean of four values, each the single-sample colour of the pixel or of one of its
    four neighbours: it lies between their minimum and maximum. So the resolved image's mean
    lies between the means of the single-sample image eroded and dilated by that cross, and
    where the bound falls wholly on one side of min_intensity, "dark" is decided exactly."""
    threshold = filters.min_intensity
    mean = float(single_sample.mean())
    # The resolved mean lies between the eroded and the dilated one, around this one: only
    # the side this one falls on can be proved.
    if mean < threshold:
        return "dark" if float(cv2.dilate(single_sample, _CROSS).mean()) < threshold else None
    if by_labels is not None and float(cv2.erode(single_sample, _CROSS).mean()) >= threshold:
        return by_labels
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
