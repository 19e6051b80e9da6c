"""Materials: metallic-roughness PBR parameters and maps, plus an optional damage-id mask,
crack network and damage zones.

Maps are numpy arrays: base colour and emissive (H, W, 3) uint8 sRGB; metallic (H, W) uint8,
multiplying ``metallic`` (255: the factor); normal (H, W, 3) uint8 tangent space; damage mask
(H, W) uint8 damage ids. Cracks are a CrackNetwork in the part's mesh frame. No material varies
its roughness over the surface, so there is no roughness map (the glTF export writes the
metallic map in glTF's packing). ``uv_scale`` multiplies the mesh UVs (metres), so a map
repeats every 1 / uv_scale metres. Damage zones confine a damage material's maps to
intervals along the member's axis and show the member's intact concrete elsewhere.
"""

from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from glsynth.appearance.cracks import CrackNetwork
from glsynth.appearance.town_textures import FACADE_BAY_M, IMAGES_PER_CATEGORY
from glsynth.core.config import MaterialsConfig
from glsynth.core.labels import Component, Damage
from glsynth.world.environment import Part, PartKind
from glsynth.world.others import SIGN_SIZE_M

MAX_ZONES = 4
"""Damage zones a material may have: the hinge zones at both ends of a column's two clear
spans (the renderer's uniform arrays hold this many)."""


@dataclass(frozen=True, eq=False)
class DamageZones:
    """Where a damage material's maps apply: mesh-frame z intervals (the member's axis), the
    hinge zones of docs/design.md "Damage by mechanics". Outside them the surface is the
    member's intact concrete: ``intact_map`` repeating every 1 / intact_uv_scale metres, no
    metal, no relief, no damage id."""

    intervals: tuple[tuple[float, float], ...]
    """(z0, z1) with z0 < z1, at most MAX_ZONES; a point is inside where z0 <= z <= z1."""
    intact_map: np.ndarray
    """(H, W, 3) uint8 sRGB: the member's own concrete image."""
    intact_uv_scale: float

    def __post_init__(self) -> None:
        spans = self.intervals
        if not (isinstance(spans, tuple) and 0 < len(spans) <= MAX_ZONES
                and all(len(s) == 2 and np.isfinite(s).all() and s[0] < s[1] for s in spans)):
            raise ValueError(f"DamageZones.intervals = {spans!r}: 1 to {MAX_ZONES} finite "
                             "(z0, z1) with z0 < z1")
        m = self.intact_map
        if not (isinstance(m, np.ndarray) and m.dtype == np.uint8 and m.ndim == 3
                and m.shape[2] == 3):
            raise ValueError("DamageZones.intact_map: must be uint8 (H, W, 3)")
        if not (np.isfinite(self.intact_uv_scale) and self.intact_uv_scale > 0):
            raise ValueError(f"DamageZones.intact_uv_scale = {self.intact_uv_scale!r}: "
                             "must be > 0")

    def contains(self, z: np.ndarray) -> np.ndarray:
        """Whether each mesh-frame z lies in some interval (as the shaders test it)."""
        z = np.asarray(z)
        inside = np.zeros(z.shape, bool)
        for z0, z1 in self.intervals:
            inside |= (z >= z0) & (z <= z1)
        return inside


@dataclass(frozen=True, eq=False)
class Material:
    base_color: tuple[float, float, float, float] = (0.8, 0.8, 0.8, 1.0)
    """Linear RGBA factor, multiplied with the base colour map."""
    metallic: float = 0.0
    roughness: float = 1.0
    emissive: tuple[float, float, float] = (0.0, 0.0, 0.0)
    uv_scale: float = 1.0
    base_color_map: np.ndarray | None = None
    metallic_map: np.ndarray | None = None
    emissive_map: np.ndarray | None = None
    normal_map: np.ndarray | None = None
    damage_mask: np.ndarray | None = None
    cracks: CrackNetwork | None = None
    """Cracks on the part's surface, in its mesh frame (glsynth.appearance.cracks)."""
    zones: DamageZones | None = None
    """Confines the maps and damage mask to these zones (needs a damage mask)."""
    detail_seed: int | None = None
    """Concrete's millimetre-scale detail (shaders/concrete_detail.glsl), drawn from this
    32-bit seed, multiplies the base colour where the surface is not metal; None: none."""
    weathering_tint: tuple[float, float, float] | None = None
    """With detail_seed: the detail is weathered (shaders/weathering.glsl), and this linear
    factor on the base colour gives the part its weathered albedo (the drawn albedo over the
    mean of its colour map); None: plain detail."""
    ground_detail: bool = False
    """With detail_seed: the detail is the ground's (shaders/ground_detail.glsl: bare soil,
    clods, stones and leaves), not concrete's."""

    def __post_init__(self) -> None:
        if self.zones is not None and (not isinstance(self.zones, DamageZones)
                                       or self.damage_mask is None):
            raise ValueError("material.zones: a DamageZones, on a material with a damage "
                             "mask")
        if self.detail_seed is not None and not (isinstance(self.detail_seed, int)
                                                 and 0 <= self.detail_seed < 2**32):
            raise ValueError(f"material.detail_seed = {self.detail_seed!r}: an int in "
                             "[0, 2**32) or None")
        if self.weathering_tint is not None and (
                self.detail_seed is None or len(self.weathering_tint) != 3
                or not all(np.isfinite(v) and v > 0 for v in self.weathering_tint)):
            raise ValueError(f"material.weathering_tint = {self.weathering_tint!r}: three "
                             "positive factors, on a material with a detail_seed, or None")
        if self.ground_detail and (self.detail_seed is None or self.weathering_tint is not None
                                   or self.cracks is not None or self.zones is not None):
            raise ValueError("material.ground_detail: on a material with a detail_seed and no "
                             "weathering_tint, cracks or zones (the ground's variant draws none)")
        if self.cracks is not None and not isinstance(self.cracks, CrackNetwork):
            raise ValueError(f"material.cracks: {type(self.cracks).__name__}; must be a "
                             "CrackNetwork or None")
        for name, channels in (("base_color_map", 3), ("metallic_map", 0),
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
        if (self.metallic_map is not None and self.base_color_map is not None
                and self.metallic_map.shape != self.base_color_map.shape[:2]):
            # The renderer samples both from one texture (colour in RGB, metallic in A).
            raise ValueError(f"material.metallic_map: shape {self.metallic_map.shape}; must "
                             f"be the base colour map's {self.base_color_map.shape[:2]}")
        if self.damage_mask is not None and self.damage_mask.size and not (
                Damage.NO_DAMAGE <= self.damage_mask.min()
                and self.damage_mask.max() <= Damage.REBAR):
            raise ValueError("material.damage_mask: must hold only damage ids 1, 2, 3")
        if not (np.isfinite(self.uv_scale) and self.uv_scale >= 0):
            raise ValueError(f"material.uv_scale = {self.uv_scale!r}: must be >= 0")


class Materials(Mapping[str, Material]):
    """Materials by part name. A deferred material is built each time it is asked for and not
    kept: a damaged column's maps are about 40 MB at 2048 px, and the renderer needs them only
    while it uploads them. ``factors`` gives any material's factors and uv_scale without
    building maps."""

    def __init__(self, ready: Mapping[str, Material],
                 deferred: Mapping[str, tuple[Material, Callable[[], Material]]]) -> None:
        """``deferred``: name -> (the material without its maps, a function building it)."""
        both = set(ready) & set(deferred)
        if both:
            raise ValueError(f"materials {sorted(both)} are both ready and deferred")
        self._ready = dict(ready)
        self._deferred = dict(deferred)

    def __getitem__(self, name: str) -> Material:
        if name in self._deferred:
            return self._deferred[name][1]()
        return self._ready[name]

    def __iter__(self) -> Iterator[str]:
        yield from self._ready
        yield from self._deferred

    def __len__(self) -> int:
        return len(self._ready) + len(self._deferred)

    def __contains__(self, name: object) -> bool:
        return name in self._ready or name in self._deferred

    def is_deferred(self, name: str) -> bool:
        return name in self._deferred

    def factors(self, name: str) -> Material:
        """The material, or a deferred one without its maps."""
        if name in self._deferred:
            return self._deferred[name][0]
        return self._ready[name]


def built_in_order(materials: Mapping[str, Material], names: Sequence[str]
                   ) -> Iterator[Material]:
    """The materials of ``names``, in order. Deferred ones are built one ahead in a background
    thread: building a damaged column's maps (numpy, which releases the GIL) then overlaps
    what the caller does with the one before (the renderer's upload), and at most two are
    alive at a time. Building is pure, so each is the same as ``materials[name]``."""
    if not isinstance(materials, Materials):
        yield from (materials[name] for name in names)
        return
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="materials") as pool:
        def build(i: int) -> Future[Material] | None:
            if i < len(names) and materials.is_deferred(names[i]):
                return pool.submit(materials.__getitem__, names[i])
            return None

        upcoming = build(0)
        for i, name in enumerate(names):
            current, upcoming = upcoming, build(i + 1)
            yield materials[name] if current is None else current.result()


def factors(materials: Mapping[str, Material], name: str) -> Material:
    """``name``'s material for its factors and uv_scale, building no deferred maps."""
    return materials.factors(name) if isinstance(materials, Materials) else materials[name]


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
    Component.OTHER: ((0.40, 0.42, 0.45, 1.0), 0.6, 0.5),
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
    """For columns: {"damaged": bool, and if damaged severity, bank index, params}; under
    [damage] model = "mechanics", severity, drift and the crack list (id, member, type, length
    in m, mean and maximum width in mm), and for a spalling (medium or severe) column the
    bank's entry with its hinge zones."""


CONCRETE_KINDS = frozenset({PartKind.SLAB, PartKind.GIRDER, PartKind.CROSS_BEAM,
                            PartKind.TIE_BEAM, PartKind.COLUMN, PartKind.CRUSHED})
STEEL_KINDS = frozenset({PartKind.RAIL, PartKind.WIRE, PartKind.REBAR})
PAINTED_KINDS = frozenset({PartKind.FENCE, PartKind.POLE, PartKind.PORTAL})
TOWN_PAINTED_KINDS = frozenset({PartKind.ROOF, PartKind.VEHICLE, PartKind.BARRIER,
                                PartKind.UTILITY})
"""The town's parts painted as the fences are (repository category "painted")."""
TOWN_TEXTURED_KINDS = {PartKind.BUILDING: ("facade", 1.0 / FACADE_BAY_M),
                       PartKind.ROAD: ("asphalt", 0.25), PartKind.TREE: ("foliage", 0.5)}
"""The town's parts with their own procedural images (glsynth.appearance.town_textures):
category and uv_scale (a facade image is one bay of one storey)."""
OTHER_STEEL_KINDS = frozenset({PartKind.JACKET, PartKind.BRACE, PartKind.TROUGH})
"""Class 8 (glsynth.world.others) of plate steel: the steel category."""
OTHER_PAINTED_KINDS = frozenset({PartKind.DOWNPIPE})
"""Class 8 of painted pipe: the painted category."""


def sample_assignment(kind: PartKind, cfg: MaterialsConfig, rng: np.random.Generator,
                      sleeper_category: str, count: Callable[[str], int]) -> Assignment:
    """Section 3.2 for one part (columns here are the undamaged case)."""
    u = rng.uniform
    if kind in CONCRETE_KINDS:
        return Assignment("concrete", int(rng.integers(count("concrete"))), 0.0, 1.0,
                          u(*cfg.concrete_scale))
    if kind is PartKind.SLEEPER:
        steel = sleeper_category == "steel"
        return Assignment(sleeper_category, int(rng.integers(count(sleeper_category))),
                          1.0 if steel else 0.0, u(*cfg.steel_roughness) if steel else 1.0,
                          u(*cfg.concrete_scale))
    if kind in STEEL_KINDS or kind in OTHER_STEEL_KINDS:
        return Assignment("steel", int(rng.integers(count("steel"))), 1.0,
                          u(*cfg.steel_roughness), u(*cfg.concrete_scale))
    if kind in PAINTED_KINDS or kind in OTHER_PAINTED_KINDS:
        return Assignment("painted", int(rng.integers(count("painted"))),
                          u(*cfg.painted_metallic), u(*cfg.painted_roughness),
                          u(*cfg.concrete_scale))
    if kind in TOWN_PAINTED_KINDS:
        return Assignment("painted", int(rng.integers(count("painted"))),
                          u(*cfg.painted_metallic), u(*cfg.painted_roughness),
                          u(*cfg.concrete_scale))
    if kind in TOWN_TEXTURED_KINDS:
        category, scale = TOWN_TEXTURED_KINDS[kind]
        return Assignment(category, int(rng.integers(IMAGES_PER_CATEGORY)), 0.0, 1.0, scale)
    if kind is PartKind.SIGN:  # an enamel plate: its image is its number (dressing)
        return Assignment("painted", int(rng.integers(count("painted"))), 0.0,
                          u(*cfg.painted_roughness), 1.0 / SIGN_SIZE_M[0])
    if kind in (PartKind.GROUND, PartKind.TERRAIN):
        return Assignment("ground", int(rng.integers(count("ground"))), 0.0, 1.0,
                          u(*cfg.ground_scale))
    if kind is PartKind.SCENE:
        return Assignment("scene", int(rng.integers(count("scene"))), 0.0, 1.0, 1.0)
    raise ValueError(f"part kind {kind!r} has no material rule")


def srgb_decode(encoded: np.ndarray) -> np.ndarray:
    """uint8 sRGB to linear [0, 1], by the exact curve (as Blender and color.frag decode)."""
    c = np.asarray(encoded, np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def surface_albedo(parts: Sequence[Part], materials: Mapping[str, Material],
                   samples: int = 4096) -> np.ndarray:
    """Mean linear base colour (3,) over the surface of ``parts``: ``samples`` points per part,
    spread evenly by area (systematic over the faces' cumulative area, an R2 low-discrepancy
    sequence inside them: no generator, the same points every time), each reading its texel at
    the UVs the renderer uses; parts are weighted by their area."""
    k = np.arange(samples)
    total, area = np.zeros(3), 0.0
    for part in parts:
        mesh, mat = part.mesh, materials[part.name]
        cumulative = np.cumsum(mesh.area_faces)
        faces = np.minimum(np.searchsorted(cumulative, (k + 0.5) / samples * cumulative[-1]),
                           len(mesh.faces) - 1)
        a, b = (0.5 + k * 0.7548776662466927) % 1.0, (0.5 + k * 0.5698402909980532) % 1.0
        flip = a + b > 1  # fold the square onto the triangle
        a[flip], b[flip] = 1 - a[flip], 1 - b[flip]
        uv = mesh.visual.uv[mesh.faces[faces]] * mat.uv_scale  # (samples, 3, 2)
        uv = uv[:, 0] + a[:, None] * (uv[:, 1] - uv[:, 0]) + b[:, None] * (uv[:, 2] - uv[:, 0])
        colour = np.ones((samples, 3))
        if mat.base_color_map is not None:
            h, w = mat.base_color_map.shape[:2]
            # uv (0, 0) is the image's bottom-left corner; the map repeats.
            col = np.floor(uv[:, 0] % 1.0 * w).astype(int) % w
            row = (h - 1 - np.floor(uv[:, 1] % 1.0 * h).astype(int)) % h
            colour = srgb_decode(mat.base_color_map[row, col])
        total += colour.mean(0) * np.asarray(mat.base_color[:3]) * mesh.area
        area += mesh.area
    return total / area if area > 0 else total
