"""Unified structural condition assessment (paper Section 4.7, Fig. 17, Table 13, Fig. 18):
damage x region of reliable damage recognition (RRDR) x component, as pure functions of maps.

Maps come from the three networks (glsynth/model/pipeline.py) or, in oracle mode, from a
dataset's ground truth; all three are at one resolution. Damage is kept only inside the RRDR
and on bridge components (everything but Nonbridge and unlabelled), attributed to the component
under it, and quantified per component as a pixel fraction and, when the focal length is known,
as an area in m^2: each pixel at depth z covers (z / f_px)^2 on a fronto-parallel surface, so
oblique surfaces are under-counted by the cosine of their tilt. Cracks kept there are measured
in millimetres when the focal length is known (glsynth.assess.cracks).
"""

import math
import os
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from glsynth.assess.cracks import (
    CrackMeasure,
    Intrinsics,
    attribute_components,
    check_grades,
    component_cracks,
    crack_picture,
    error_summary,
    grade,
    grade_range,
    measure_cracks,
    width_errors,
)
from glsynth.core.config import MAX_CRACK_WIDTH_MM
from glsynth.core.errors import UserError, named
from glsynth.core.filters import RRDR_DEPTH_RANGE_M, RRDR_PX_PER_CM, rrdr
from glsynth.core.images import nearest_resize, read_photo
from glsynth.core.labels import Component, Damage
from glsynth.core.palette import COMPONENT_RGB, DAMAGE_RGB, overlay

BRIDGE = tuple(c for c in Component if c not in (Component.UNLABELLED, Component.NONBRIDGE))
DAMAGE_CLASSES = (Damage.CONCRETE, Damage.REBAR)


def parse_range(text: str) -> tuple[float, float]:
    """'NEAR,FAR' in metres -> (near, far)."""
    try:
        near, far = (float(v) for v in text.split(","))
    except ValueError:
        raise UserError(f"{text!r}: write NEAR,FAR in metres, e.g. 0.5,20") from None
    return near, far


def parse_widths(text: str) -> tuple[float, ...]:
    """'0.2,0.3,0.5,1.0' in millimetres -> (0.2, 0.3, 0.5, 1.0)."""
    try:
        return tuple(float(v) for v in text.split(","))
    except ValueError:
        raise UserError(f"{text!r}: write widths in mm separated by commas, e.g. "
                        "0.2,0.3,0.5,1.0") from None


@dataclass(frozen=True)
class AssessSettings:
    min_px_per_cm: float = RRDR_PX_PER_CM
    """RRDR when the focal length is known: resolution at least this [px/cm]."""
    depth_range_m: tuple[float, float] = field(default=RRDR_DEPTH_RANGE_M, metadata={
        "flag": "--depth-range", "parse": parse_range, "metavar": "NEAR,FAR", "show": "0.5,20"})
    """RRDR when it is not: predicted depth within this range [m]."""
    crack_grades_mm: tuple[float, ...] = field(default=(0.2, 0.3, 0.5, 1.0), metadata={
        "parse": parse_widths, "metavar": "W1,W2,...", "show": "0.2,0.3,0.5,1.0"})
    """Crack-width grade boundaries [mm]: grade k holds widths from the k-th boundary up to
    the next (docs/design.md gives the source of the defaults)."""
    crack_elongation: float = 5.0
    """A concrete-damage region is a crack when its skeleton is at least this many times as
    long as its widest width, and spalling otherwise."""

    def __post_init__(self) -> None:
        if not (np.isfinite(self.min_px_per_cm) and self.min_px_per_cm > 0):
            raise UserError(f"--min-px-per-cm {self.min_px_per_cm}: give a positive number "
                            "(the paper uses 1.5)")
        near, far = self.depth_range_m
        if not 0 <= near < far < np.inf:
            raise UserError(f"--depth-range {near},{far}: give 0 <= NEAR < FAR (the paper uses "
                            "0.5,20)")
        grades = ",".join(f"{v:g}" for v in self.crack_grades_mm)
        if (why := check_grades(self.crack_grades_mm)) is not None:
            raise UserError(f"--crack-grades-mm {grades}: {why}")
        if not (np.isfinite(self.crack_elongation) and self.crack_elongation > 0):
            raise UserError(f"--crack-elongation {self.crack_elongation}: give a positive "
                            "ratio of length to width (default 5)")


ASSESS_DEFAULTS = AssessSettings()


@dataclass(frozen=True)
class Maps:
    component: np.ndarray
    """Component ids (H, W)."""
    damage: np.ndarray
    """Damage ids (H, W)."""
    depth_m: np.ndarray
    """Depth along the optical axis (H, W), metres."""
    focal_px: float | None
    """Focal length in pixels of the photo (the RRDR's px/cm is the photo's resolution), or
    None when unknown."""
    stride: float = 1.0
    """Photo pixels per map pixel (3 for Tokaido maps of 1920x1080 images)."""
    crack_truth_mm: np.ndarray | None = None
    """Ground-truth crack widths (H, W) [mm], 0 off cracks (oracle mode), or None."""
    crack_truth_note: str | None = None
    """Why there is no crack_truth_mm where one was looked for (oracle mode), or None."""

    def __post_init__(self) -> None:
        shapes = {a.shape for a in (self.component, self.damage, self.depth_m)}
        if len(shapes) != 1 or self.component.ndim != 2:
            raise ValueError(f"component {self.component.shape}, damage {self.damage.shape} "
                             f"and depth {self.depth_m.shape} maps must be 2-D and of one size")


@dataclass
class Assessment:
    reliable: np.ndarray
    """RRDR (bool)."""
    considered: np.ndarray
    """RRDR and a bridge component (bool): where damage is assessed."""
    damage: np.ndarray
    """Damage ids kept (1 = none, 2-3 damage) inside ``considered``, 0 elsewhere."""
    components: dict = field(default_factory=dict)
    """Per bridge component present: pixels, pixels in the RRDR, damaged pixels and fractions,
    areas in m^2 (None without a focal length)."""
    totals: dict = field(default_factory=dict)
    cracks: CrackMeasure | None = None
    """Cracks kept (inside ``considered``) measured in mm; None without a focal length."""


def pixel_area_m2(depth_m: np.ndarray, focal_px: float, stride: float = 1.0) -> np.ndarray:
    """Fronto-parallel surface area seen by each map pixel (stride x stride photo pixels);
    0 where depth is not positive or not finite."""
    d = np.where(np.isfinite(depth_m) & (depth_m > 0), depth_m, 0.0).astype(np.float64)
    return (d * stride / focal_px) ** 2


def assess(maps: Maps, settings: AssessSettings = ASSESS_DEFAULTS) -> Assessment:
    reliable = rrdr(maps.depth_m, maps.focal_px, min_px_per_cm=settings.min_px_per_cm,
                    depth_range_m=settings.depth_range_m)
    bridge = np.isin(maps.component, BRIDGE)
    considered = reliable & bridge
    damage = np.where(considered, maps.damage, Damage.UNLABELLED).astype(np.uint8)
    area = None if maps.focal_px is None else \
        pixel_area_m2(maps.depth_m, maps.focal_px, maps.stride)
    components = {}
    for comp in BRIDGE:
        on = maps.component == comp
        if not on.any():
            continue
        inside = on & reliable
        entry = {"pixels": int(on.sum()), "pixels_in_rrdr": int(inside.sum()),
                 "damaged_pixels": {}, "damaged_fraction": {}, "area_m2_in_rrdr": None,
                 "damaged_area_m2": None}
        for cls in DAMAGE_CLASSES:
            hit = inside & (damage == cls)
            name = cls.name.lower()
            entry["damaged_pixels"][name] = int(hit.sum())
            entry["damaged_fraction"][name] = float(hit.sum() / inside.sum()) \
                if inside.any() else None
        if area is not None:
            entry["area_m2_in_rrdr"] = float(area[inside].sum())
            entry["damaged_area_m2"] = {cls.name.lower(): float(area[inside & (damage == cls)]
                                                               .sum())
                                        for cls in DAMAGE_CLASSES}
        components[comp.name.lower()] = entry
    totals = {"pixels": int(maps.component.size), "bridge_pixels": int(bridge.sum()),
              "rrdr_pixels": int(reliable.sum()), "assessed_pixels": int(considered.sum()),
              "damaged_pixels": {cls.name.lower(): int((damage == cls).sum())
                                 for cls in DAMAGE_CLASSES},
              "damage_outside_rrdr_or_bridge_pixels": int(
                  (np.isin(maps.damage, DAMAGE_CLASSES) & ~considered).sum()),
              "focal_known": maps.focal_px is not None}
    cracks = None
    if maps.focal_px is not None:
        cracks = measure_cracks(damage, maps.depth_m,
                                Intrinsics.centred(maps.focal_px, damage.shape, maps.stride),
                                settings.crack_elongation)
        attribute_components(cracks, maps.component)
    return Assessment(reliable, considered, damage, components, totals, cracks)


def assessment_picture(rgb: np.ndarray, component: np.ndarray,
                       result: Assessment) -> np.ndarray:
    """Fig. 17 at the photo's size: components tinted, kept damage coloured by class over
    them, and far or non-bridge regions greyed out. Maps are brought to the photo's size by
    nearest sampling."""
    shape = rgb.shape[:2]
    component = nearest_resize(component, shape)
    damage = nearest_resize(result.damage, shape)
    considered = nearest_resize(result.considered, shape)
    tinted = overlay(rgb, component, COMPONENT_RGB, 0.3, skip=(0,))
    picture = overlay(tinted, damage, DAMAGE_RGB, 0.85,
                      skip=(Damage.UNLABELLED, Damage.NO_DAMAGE))
    grey = rgb.astype(np.float32).mean(axis=2, keepdims=True) * 0.45 + 90
    return np.where(considered[..., None], picture, grey).round().astype(np.uint8)


@dataclass(frozen=True)
class Photo:
    name: str
    """Output stem; unique within a batch."""
    load: Callable[[], tuple[np.ndarray, Maps]]
    """Returns the photo (RGB uint8 at its own size) and its maps; may raise ValueError or
    OSError, which fail this photo only."""


def assess_photos(photos: Iterable[Photo], out: Path,
                  settings: AssessSettings = ASSESS_DEFAULTS) -> dict:
    """Assess each photo: <name>_assessment.png (Fig. 17), <name>_cracks.png (cracks coloured
    by width, when measured) and <name>.json per photo, and summary.json across them. A photo
    that fails is reported and the others go on."""
    from glsynth.core.fileio import atomic_write_bytes, atomic_write_json, png_bytes

    per_component: dict[str, dict] = {}
    crack_totals: dict[str, dict] = {}
    errors: list[dict] = []
    notes: set[str] = set()
    done, failed = [], []
    for photo in photos:
        try:
            rgb, maps = photo.load()
            result = assess(maps, settings)
            picture = assessment_picture(rgb, maps.component, result)
            cracks, crack_png, error = _crack_report(rgb, maps, result, settings)
        except (ValueError, OSError) as err:
            failed.append({"image": photo.name, "error": str(err)})
            continue
        report = {"image": photo.name, "maps_size": list(result.damage.shape[::-1]),
                  "focal_px": maps.focal_px, "settings": _settings_json(settings),
                  "totals": result.totals, "components": result.components, "cracks": cracks}
        atomic_write_json(out / f"{photo.name}.json", report)
        atomic_write_bytes(out / f"{photo.name}_assessment.png", png_bytes(picture))
        if crack_png is not None:
            atomic_write_bytes(out / f"{photo.name}_cracks.png", png_bytes(crack_png))
        done.append(photo.name)
        _add_damage(per_component, result.components)
        _add_cracks(crack_totals, cracks.get("components", {}))
        errors += [error] if error is not None else []
        notes |= {maps.crack_truth_note} if maps.crack_truth_note else set()
    for agg in per_component.values():
        agg["damaged_fraction"] = {k: (v / agg["pixels_in_rrdr"] if agg["pixels_in_rrdr"]
                                       else None) for k, v in agg["damaged_pixels"].items()}
    summary = {"assessed": done, "failed": failed, "settings": _settings_json(settings),
               "components": per_component,
               "cracks": {"components": _crack_summary(crack_totals, settings.crack_grades_mm),
                          "truth": error_summary(errors) if errors else
                          (sorted(notes) or None)}}
    atomic_write_json(out / "summary.json", summary)
    return summary


def _add_damage(per_component: dict[str, dict], components: dict[str, dict]) -> None:
    """Add one photo's damage per component to the batch's sums."""
    for name, entry in components.items():
        agg = per_component.setdefault(name, {"images": 0, "pixels_in_rrdr": 0,
                                              "damaged_pixels": dict.fromkeys(
                                                  ("concrete", "rebar"), 0),
                                              "damaged_area_m2": None})
        agg["images"] += 1
        agg["pixels_in_rrdr"] += entry["pixels_in_rrdr"]
        for cls, n in entry["damaged_pixels"].items():
            agg["damaged_pixels"][cls] += n
        if entry["damaged_area_m2"] is not None:
            area = agg["damaged_area_m2"] or dict.fromkeys(("concrete", "rebar"), 0.0)
            agg["damaged_area_m2"] = {k: area[k] + v
                                      for k, v in entry["damaged_area_m2"].items()}


def _crack_report(rgb: np.ndarray, maps: Maps, result: Assessment, settings: AssessSettings
                  ) -> tuple[dict, np.ndarray | None, dict | None]:
    """One photo's cracks for its JSON, its crack picture and, with ground truth, its width
    errors (None, None without a focal length)."""
    if result.cracks is None:
        return {"measured": False, "reason": "focal length unknown: crack widths in mm need "
                                             "it (--focal-mm)"}, None, None
    measure, grades = result.cracks, settings.crack_grades_mm
    cracks = [dict(c, grade=None if c["max_width_mm"] is None else
                   grade(c["max_width_mm"], grades)) for c in measure.cracks]
    report = {"measured": True, "count": len(cracks),
              "spalling_regions": measure.spalling_regions,
              "components": component_cracks(measure.cracks, grades), "cracks": cracks,
              "truth": maps.crack_truth_note}
    errors = None
    if maps.crack_truth_mm is not None:
        errors = width_errors(measure, maps.crack_truth_mm)
        report["truth"] = error_summary([errors])
    return report, crack_picture(rgb, measure, grades), errors


def _add_cracks(totals: dict[str, dict], components: dict[str, dict]) -> None:
    """Add one photo's cracks per component to the batch's sums."""
    for name, entry in components.items():
        agg = totals.setdefault(name, {"images": 0, "cracks": 0, "length_m": 0.0,
                                       "width_x_length": 0.0, "measured_length_m": 0.0,
                                       "max_width_mm": None})
        agg["images"] += 1
        agg["cracks"] += entry["cracks"]
        agg["length_m"] += entry["length_m"]
        if entry["mean_width_mm"] is not None:
            agg["width_x_length"] += entry["mean_width_mm"] * entry["length_m"]
            agg["measured_length_m"] += entry["length_m"]
        if entry["max_width_mm"] is not None:
            agg["max_width_mm"] = max(agg["max_width_mm"] or 0.0, entry["max_width_mm"])


def _crack_summary(totals: dict[str, dict], grades: tuple[float, ...]) -> dict[str, dict]:
    out = {}
    for name, agg in totals.items():
        widest = agg["max_width_mm"]
        k = None if widest is None else grade(widest, grades)
        out[name] = {"images": agg["images"], "cracks": agg["cracks"],
                     "length_m": agg["length_m"],
                     "mean_width_mm": agg["width_x_length"] / agg["measured_length_m"]
                     if agg["measured_length_m"] > 0 else None,
                     "max_width_mm": widest, "grade": k,
                     "grade_range": None if k is None else grade_range(k, grades)}
    return out


def _settings_json(settings: AssessSettings) -> dict:
    return {"min_px_per_cm": settings.min_px_per_cm,
            "depth_range_m": list(settings.depth_range_m),
            "crack_grades_mm": list(settings.crack_grades_mm),
            "crack_elongation": settings.crack_elongation}


def oracle_photos(root: Path, split: str = "test", sensor_mm: float = 36.0,
                  limit: int | None = None) -> list[Photo]:
    """Ground-truth maps of a Tokaido-layout split in place of the networks, to check the
    post-processing on its own. The focal length comes from the manifest (mm, on a sensor
    ``sensor_mm`` wide; glsynth's cameras use 36 mm). Ground-truth crack widths come from
    ``synthetic/{split}/crackwidth/`` where the dataset has it."""
    from glsynth.data.readers import map_size, read_depth_map, read_label_map
    from glsynth.data.tokaido import decode_depth, read_manifest

    rows = read_manifest(root, f"files_{split}.csv")[:limit]

    def loader(row) -> Callable[[], tuple[np.ndarray, Maps]]:
        def load() -> tuple[np.ndarray, Maps]:
            rgb = read_photo(root / row.image)
            size = map_size(root / row.image)
            component = read_label_map(root / row.component, "component", size)
            damage = read_label_map(root / row.damage, "damage", size)
            depth = decode_depth(read_depth_map(root / row.depth, size))
            focal_px = None if row.focal_mm is None else row.focal_mm / sensor_mm * rgb.shape[1]
            truth, note = crack_truth(root, row.damage)
            return rgb, Maps(component, damage, depth, focal_px, rgb.shape[1] / component.shape[1],
                             truth, note)
        return load

    return [Photo(Path(r.image).stem.removesuffix("_Scene"), loader(r)) for r in rows]


def render_folders(root: Path) -> list[Path]:
    """The ``glsynth render`` outputs under ``root``: root itself where it holds a
    camera.json, else its subfolders that do (render with several cameras), in name order."""
    if (root / "camera.json").is_file():
        return [root]
    if not root.is_dir():
        return []
    return sorted(d for d in root.iterdir() if (d / "camera.json").is_file())


def render_photos(folders: list[Path], limit: int | None = None) -> list[Photo]:
    """The full-size ground truth of ``glsynth render`` outputs (image.png, component.png,
    damage.png, depth.npy, crack_width.npy, camera.json) in place of the networks: the maps
    are the image's size, and the focal length in pixels is camera.json's K."""
    from glsynth.data.readers import read_float_map, read_label_map

    def loader(folder: Path) -> Callable[[], tuple[np.ndarray, Maps]]:
        def load() -> tuple[np.ndarray, Maps]:
            rgb = read_photo(folder / "image.png")
            size = (rgb.shape[1], rgb.shape[0])
            maps = Maps(read_label_map(folder / "component.png", "component", size),
                        read_label_map(folder / "damage.png", "damage", size),
                        read_float_map(folder / "depth.npy", "depth map", size),
                        _render_focal_px(folder / "camera.json"), 1.0,
                        read_float_map(folder / "crack_width.npy", "crack-width map", size,
                                       high=MAX_CRACK_WIDTH_MM))
            return rgb, maps
        return load

    return [Photo(folder.name, loader(folder)) for folder in folders[:limit]]


def _render_focal_px(path: Path) -> float:
    """fx of a render's camera.json K (3x3, pixels), checked."""
    from glsynth.data.readers import read_json

    fix = "write it again with glsynth render"
    k = read_json(path, {"K": list}, fix)["K"]
    try:
        fx = float(np.asarray(k, dtype=np.float64).reshape(3, 3)[0, 0])
    except (TypeError, ValueError):
        fx = math.nan
    if not 0 < fx < math.inf:
        raise UserError(f"{named(path)}: K = {str(k)[:60]} is not a 3x3 matrix with a focal "
                        f"length > 0 in pixels; {fix}")
    return fx


def crack_truth(root: Path, damage_rel: str) -> tuple[np.ndarray | None, str | None]:
    """The ground-truth crack widths beside a damage label, ``synthetic/{split}/crackwidth/
    <stem>.png`` (uint16, 0.01 mm steps) in mm, or None and why it is missing."""
    from glsynth.data.readers import read_crack_width_map
    from glsynth.data.tokaido import crack_width_path, decode_crack_width

    path = root / crack_width_path(damage_rel)
    folder = path.parent
    if not folder.is_dir():
        return None, (f"no ground-truth crack widths: {folder} does not exist (the released "
                      "dataset and glsynth's from before crack widths have none)")
    if not os.path.lexists(path):
        return None, f"no ground-truth crack widths: {path} is missing"
    return decode_crack_width(read_crack_width_map(path)), None
