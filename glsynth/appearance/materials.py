"""Materials: metallic-roughness PBR parameters and maps, plus an optional damage-id mask.

Maps are numpy arrays: base colour and emissive (H, W, 3) uint8 sRGB; metallic-roughness
(H, W, 3) uint8 packed as glTF does (G roughness, B metallic); normal (H, W, 3) uint8 tangent
space; damage mask (H, W) uint8 damage ids. ``uv_scale`` multiplies the mesh UVs (metres), so a
map repeats every 1 / uv_scale metres.
"""

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from glsynth.core.config import MaterialsConfig
from glsynth.core.labels import Component, Damage


@dataclass(frozen=True, eq=False)
class Material:
    base_color: tuple[float, float, float, float] = (0.8, 0.8, 0.8, 1.0)
    """Linear RGBA factor, multiplied with the base colour map."""
    metallic: float = 0.0
    roughness: float = 1.0
    emissive: tuple[float, float, float] = (0.0, 0.0, 0.0)
    uv_scale: float = 1.0
    base_color_map: np.ndarray | None = None
    metallic_roughness_map: np.ndarray | None = None
    emissive_map: np.ndarray | None = None
    normal_map: np.ndarray | None = None
    damage_mask: np.ndarray | None = None

    def __post_init__(self) -> None:
        for name, channels in (("base_color_map", 3), ("metallic_roughness_map", 3),
                               ("emissive_map", 3), ("normal_map", 3), ("damage_mask", 0)):
            value = getattr(self, name)
            if value is None:
                continue
            shape_ok = value.ndim == 2 if channels == 0 else (value.ndim == 3
                                                              and value.shape[2] == channels)
            if value.dtype != np.uint8 or not shape_ok:
                want = "(H, W)" if channels == 0 else f"(H, W, {channels})"
                raise ValueError(f"material.{name}: dtype {value.dtype}, shape {value.shape}; "
                                 f"must be uint8 {want}")
        if self.damage_mask is not None and self.damage_mask.size and not (
                Damage.NO_DAMAGE <= self.damage_mask.min()
                and self.damage_mask.max() <= Damage.REBAR):
            raise ValueError("material.damage_mask: must hold only damage ids 1, 2, 3")
        if not (np.isfinite(self.uv_scale) and self.uv_scale >= 0):
            raise ValueError(f"material.uv_scale = {self.uv_scale!r}: must be >= 0")


# Untextured stand-ins per component (linear base colour, metallic, roughness); the texture
# repository of Section 3.2 replaces them.
_PLAIN = {
    Component.NONBRIDGE: ((0.30, 0.33, 0.22, 1.0), 0.0, 1.0),
    Component.SLAB: ((0.55, 0.55, 0.52, 1.0), 0.0, 1.0),
    Component.BEAM: ((0.50, 0.49, 0.46, 1.0), 0.0, 1.0),
    Component.COLUMN: ((0.60, 0.58, 0.55, 1.0), 0.0, 1.0),
    Component.NONSTRUCTURAL: ((0.20, 0.30, 0.45, 1.0), 0.5, 0.5),
    Component.RAIL: ((0.45, 0.43, 0.42, 1.0), 1.0, 0.35),
    Component.SLEEPER: ((0.35, 0.30, 0.25, 1.0), 0.0, 1.0),
}


def plain_material(component: Component, *, emissive: bool = False) -> Material:
    color, metallic, roughness = _PLAIN[component]
    if emissive:  # scene panels: emission only (paper: emission shader, intensity 0.5)
        return Material(base_color=(0.0, 0.0, 0.0, 1.0), emissive=(0.5, 0.6, 0.45))
    return Material(color, metallic, roughness)


@dataclass(frozen=True)
class Assignment:
    """What was sampled for one part (recorded in per-image metadata)."""

    category: str
    image: int
    metallic: float
    roughness: float
    scale: float
    damage: dict | None = None
    """For columns: {"damaged": bool, and if damaged severity, bank index, params}."""


def part_kind(name: str) -> str:
    """slab, beam, column, sleeper, rail, wire, painted (fence, pole, portal), ground, scene."""
    prefix = name.split("_")[0]
    if prefix == "nonstructural":
        return "wire" if "_wire_" in name else "painted"
    return prefix


def sample_assignment(kind: str, cfg: MaterialsConfig, rng: np.random.Generator,
                      sleeper_category: str, count: Callable[[str], int]) -> Assignment:
    """Section 3.2 for one part (columns here are the undamaged case)."""
    u = rng.uniform
    if kind in ("slab", "beam", "column"):
        return Assignment("concrete", int(rng.integers(count("concrete"))), 0.0, 1.0,
                          u(*cfg.concrete_scale))
    if kind == "sleeper":
        steel = sleeper_category == "steel"
        return Assignment(sleeper_category, int(rng.integers(count(sleeper_category))),
                          1.0 if steel else 0.0, u(*cfg.steel_roughness) if steel else 1.0,
                          u(*cfg.concrete_scale))
    if kind in ("rail", "wire"):
        return Assignment("steel", int(rng.integers(count("steel"))), 1.0,
                          u(*cfg.steel_roughness), u(*cfg.concrete_scale))
    if kind == "painted":
        return Assignment("painted", int(rng.integers(count("painted"))),
                          u(*cfg.painted_metallic), u(*cfg.painted_roughness),
                          u(*cfg.concrete_scale))
    if kind == "ground":
        return Assignment("ground", int(rng.integers(count("ground"))), 0.0, 1.0,
                          u(*cfg.ground_scale))
    if kind == "scene":
        return Assignment("scene", int(rng.integers(count("scene"))), 0.0, 1.0, 1.0)
    raise ValueError(f"part kind {kind!r} has no material rule")
