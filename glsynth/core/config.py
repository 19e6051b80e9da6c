"""Configuration: frozen dataclasses validated on construction, TOML files and named presets.

Units are metres and radians inside; ``_m``/``_deg``/``_mm`` suffixes name the unit at this
boundary. An invalid value raises UserError (a ValueError) naming the field, the value and the
allowed range.
"""

import dataclasses
import difflib
import math
import tomllib
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from glsynth.core import design
from glsynth.core.checks import (
    Flag,
    Interval,
    Number,
    Numbers,
    PositiveInterval,
    Vector,
    bounded,
    fail,
    validate,
)
from glsynth.core.design import StandardDesign
from glsynth.core.errors import UserError
from glsynth.core.surfaces import MAX_SLANT_DEG


@dataclass(frozen=True)
class EnvironmentConfig:
    """Random trajectories and their meshes (paper Section 3.1, Table 4)."""

    n_viaducts: int = bounded(10, Number(1, 1000, integer=True))
    """N, viaducts per environment."""
    initial_height_m: tuple[float, float] = bounded(
        (6.5, 12.0), Interval(lambda c: c.height_limits_m[0], lambda c: c.height_limits_m[1]))
    """Range of the first viaduct's height (ground to deck top at its centre)."""
    cutoff_factor: float = bounded(2.0, Number(0.0, lambda c: c.n_viaducts / 2))
    """Cutoff frequency of the rectangular spectra, as cutoff_factor / N cycles per viaduct."""
    ground_amplitude_m: float = bounded(1.0, Number(0.0, 100.0))
    """Spectrum amplitude of the ground-height increments (unitary DFT)."""
    height_amplitude_m: float = bounded(0.2, Number(0.0, 100.0))
    """Spectrum amplitude of the viaduct-height increments (unitary DFT)."""
    min_radius_m: tuple[float, float] = bounded((500.0, 5000.0), Interval(100.0, math.inf))
    """Range of the smallest radius of curvature along the trajectory; (inf, inf) is straight."""
    height_limits_m: tuple[float, float] = bounded(
        (design.HEIGHT_MIN_M, design.HEIGHT_MAX_M),
        Interval(design.HEIGHT_MIN_M, design.HEIGHT_MAX_M))
    """Table 4: 5.0 <= H <= 14 m."""
    max_slope: float = bounded(0.02, Number(0.0, 0.2, lo_open=True))
    """Table 4: |S| < 0.02 between neighbouring viaducts."""
    panel_distance_m: float = bounded(30.0, Number(15.0, 1000.0))
    """Scene panels stand this far from the centre line (paper: 30 m)."""
    panel_height_m: float = bounded(30.0, Number(1.0, 1000.0))
    end_margin_m: float = bounded(30.0, Number(0.0, 1000.0))
    """Ground and panels run on past both ends of the trajectory by this much."""
    sweep_step_m: float = bounded(1.0, Number(0.01, 6.0))
    """Arc-length step of curved sweeps (slab, rails, ground...); chord error step^2 / 8R."""
    cylinder_segments: int = bounded(12, Number(3, 256, integer=True))
    """Facets around poles and wires."""
    world: Literal["panels", "town"] = "panels"
    """What surrounds the viaducts (docs/design.md, "A town around the viaduct"): "panels",
    the paper's photo panels at panel_distance_m; "town", 3-D houses, blocks, warehouses,
    roads with vehicles, trees, utility poles and a ring of far hills under the sky
    (glsynth.world.surroundings)."""
    fences: Literal["solid", "open"] = "solid"
    """Deck-edge fences: "solid" swept rectangles (the paper's), or "open" railings of posts,
    rails and vertical bars that the background shows through (glsynth.world.fences)."""
    jacket_probability: float = bounded(0.0, Number(0.0, 1.0))
    """Others (docs/design.md, "Others"): the chance that a viaduct was retrofitted by steel
    jacketing, all of its columns. 0 (the paper): no others of any kind."""
    brace_probability: float = bounded(0.0, Number(0.0, 1.0))
    """The chance that a viaduct not jacketed has steel X braces between its rows' columns."""
    downpipe_probability: float = bounded(0.0, Number(0.0, 1.0))
    """The chance, per side of a viaduct, of a drainage downpipe down one of its columns."""
    trough_probability: float = bounded(0.0, Number(0.0, 1.0))
    """The chance, per side of a viaduct, of a cable trough under the slab overhang."""
    sign_probability: float = bounded(0.0, Number(0.0, 1.0))
    """The chance that a viaduct has a numbered plate on one of its columns."""

    def __post_init__(self) -> None:
        _validate(self)
        if math.isinf(self.min_radius_m[1]) and not math.isinf(self.min_radius_m[0]):
            _reject(self, "min_radius_m", "finite, or [inf, inf] for straight track")


@dataclass(frozen=True)
class CameraConfig:
    """Synthetic cameras (paper Section 3.4)."""

    n_regular: int = bounded(50, Number(0, 100000, integer=True))
    """Regular cameras per environment (global views)."""
    n_closeup: int = bounded(50, Number(0, 100000, integer=True))
    """Close-up cameras per environment (mostly columns)."""
    focal_mm: tuple[float, float] = bounded((15.0, 55.0), Interval(1.0, 1000.0))
    sensor_mm: float = bounded(36.0, Number(1.0, 100.0))
    """Sensor width; it spans the image width."""
    placement: Literal["within", "at", "faces"] = "within"
    """How D is read (docs/design.md): 'within', a camera anywhere within D of the centre line
    (lateral offset uniform in [-D, D]: under the deck, among the columns, above the track);
    'at', exactly D to one side. 'faces' is not the paper's: every camera is a close-up
    aimed at a point on a column's or a cross or tie beam's face (the inspection preset;
    glsynth.world.face_cameras), by the face_* fields below, and n_regular must be 0."""
    regular_distance_m: float = bounded(10.0, Number(0.0, 1000.0))
    """D of the regular cameras."""
    height_from: Literal["origin", "ground"] = "origin"
    """What [h0, h1] is measured from (docs/design.md): 'origin', the world's z = 0, which is
    the ground under the first viaduct (a Blender location); 'ground', the ground under the
    camera."""
    regular_height_m: tuple[float, float] = bounded((1.0, 10.0), Interval(0.0, 1000.0))
    """[h0, h1] of the regular cameras."""
    closeup_distance_m: float = bounded(5.0, Number(0.0, 1000.0))
    closeup_height_m: tuple[float, float] = bounded((1.0, 6.5), Interval(0.0, 1000.0))
    rot_x_deg: tuple[float, float] = bounded((45.0, 135.0), Interval(0.0, 180.0))
    """Blender XYZ Euler X: 90 looks horizontally."""
    rot_y_deg: tuple[float, float] = bounded((-15.0, 15.0), Interval(-180.0, 180.0))
    rot_z_deg: tuple[float, float] = bounded((-90.0, 90.0), Interval(-180.0, 180.0))
    """Relative to the direction that points to the viaduct centre line."""
    face_distance_m: tuple[float, float] = bounded((0.3, 3.0), PositiveInterval(1000.0, "metres"))
    """placement = "faces": range of the distance from the camera to the aimed point on the
    face, along the optical axis."""
    face_angle_deg: float = bounded(30.0, Number(0.0, MAX_SLANT_DEG))
    """placement = "faces": largest angle between the optical axis and the face's normal."""
    face_roll_deg: float = bounded(5.0, Number(0.0, 45.0))
    """placement = "faces": largest roll about the optical axis from level (the image's x axis
    horizontal): the camera is held upright."""
    face_crack_share: float = bounded(0.0, Number(0.0, 1.0))
    """placement = "faces": the share of cameras aimed at a point on a crack (uniform along the
    environment's cracks on inspected faces, as an inspector photographs the damage), the rest
    at a point uniform on a face. Needs [damage] model = "mechanics"; an environment without
    cracks aims every camera at a face point."""
    face_foot_share: float = bounded(0.0, Number(0.0, 1.0))
    """placement = "faces": of the cameras not aimed at a crack, the share aimed at a column's
    foot (glsynth.world.face_cameras): a point where the ground meets a column face, raised so
    that the ground fills the lower part of the frame, seen from level or above."""
    face_crack_px: float = bounded(0.0, Number(0.0, 100.0))
    """placement = "faces": a camera aimed at a crack stands no farther than makes the crack's
    width at the aimed point span this many pixels (within face_distance_m); 0: anywhere in
    face_distance_m."""

    def __post_init__(self) -> None:
        _validate(self)
        if self.face_crack_share and self.placement != "faces":
            _reject(self, "face_crack_share",
                    '0 unless placement = "faces" (only face cameras aim at cracks)')
        if self.face_foot_share and self.placement != "faces":
            _reject(self, "face_foot_share",
                    '0 unless placement = "faces" (only face cameras aim at a column\'s foot)')
        if self.placement == "faces" and self.n_regular:
            _reject(self, "n_regular", '0 under placement = "faces" (every camera is a close-up '
                    "at a member face; set n_closeup instead)")

    @property
    def total(self) -> int:
        """Cameras per environment: indices 0 .. total - 1, the regular ones first."""
        return self.n_regular + self.n_closeup


@dataclass(frozen=True)
class RenderConfig:
    """Image size, antialiasing, clip planes, shadows and ambient occlusion of the GL renderer,
    and which renderer colours the images."""

    width: int = bounded(1920, Number(1, 16384, integer=True))
    height: int = bounded(1080, Number(1, 16384, integer=True))
    msaa: Literal[0, 2, 4, 8, 16] = 4
    """Samples for the colour pass (0: none; llvmpipe supports up to 4). Labels and depth are
    never multisampled."""
    znear_m: float = bounded(0.05, Number(1e-4, 10.0))
    zfar_m: float = bounded(2000.0, Number(lambda c: c.znear_m, 1e7, lo_open=True))
    """Also the depth of pixels that see no geometry (sky)."""
    renderer: Literal["gl", "cycles"] = "gl"
    """Colour by "gl" (the rasterizer) or "cycles" (the Cycles twin, glsynth.render.cycles;
    needs Blender; [cycles]). Labels and depth always come from GL."""
    shadow_map_px: int = bounded(2048, Number(0, 16384, integer=True))
    """Side of the sun's shadow map (0: no shadows). Its texel, in metres, is the footprint of
    the shadowed range divided by this."""
    shadow_distance_m: float = bounded(60.0, Number(1.0, 1e5))
    """Shadows are drawn on surfaces nearer than this to the camera; farther ones are lit."""
    sky_visibility_maps: Literal[0, 4, 9, 16] = 16
    """Directions of the sky whose visibility the rasterizer bakes once per environment, as
    orthographic depth maps (0: off): the sky light under the deck is then occluded by it."""
    sky_visibility_px: int = bounded(1024, Number(64, 4096, integer=True))
    """Side of each sky-visibility map."""
    ao: Literal["ssao", "off"] = "off"
    """Screen-space ambient occlusion of the rasterizer: "ssao" (from the label pass's depth)
    or "off". Off by default: against Cycles it adds no accuracy at the default exposure and
    costs render time (bench/bench_lighting.py, docs/results.md); the sky-visibility maps do the
    occlusion that matters."""
    ao_radius_m: float = bounded(1.0, Number(0.01, 100.0))
    """World radius within which geometry occludes ambient light."""
    ao_samples: int = bounded(16, Number(1, 64, integer=True))

    def __post_init__(self) -> None:
        _validate(self)
        if 0 < self.shadow_map_px < 64:
            _reject(self, "shadow_map_px", "0 (no shadows) or 64 to 16384")


@dataclass(frozen=True)
class LightingConfig:
    """The sun, the sky and the exposure, for both renderers (docs/design.md, Lighting). The
    ambient light of the rasterizer is always the irradiance of the sky and of the lit ground,
    as spherical harmonics; the tone map is always Blender's Standard view transform."""

    sun_elevation_deg: tuple[float, float] = bounded((20.0, 70.0), Interval(-90.0, 90.0))
    """Range of the sun's elevation, drawn once per environment."""
    sun_azimuth_deg: tuple[float, float] = bounded((0.0, 360.0), Interval(-360.0, 360.0))
    """Range of the sun's azimuth, from +x (the initial track direction), counter-clockwise."""
    sun_irradiance: tuple[float, float] = bounded((2.5, 3.5), Interval(0.0, 100.0))
    """Range of the sun's irradiance on a plane facing it (linear units; Blender's sun
    strength)."""
    sky: Literal["preetham", "uniform"] = "preetham"
    """Sky model: "preetham" (Blender's Preetham sky texture, scaled by sky_strength) or
    "uniform" (sky_rgb x uniform_sky_strength in every direction)."""
    turbidity: tuple[float, float] = bounded((2.0, 4.0), Interval(2.0, 10.0))
    """Range of the Preetham sky's turbidity (2: very clear, 10: hazy)."""
    sky_strength: float = bounded(1.0, Number(0.0, 100.0))
    """Scale of the Preetham sky (the strength of Blender's Background node)."""
    sky_rgb: tuple[float, float, float] = bounded((0.62, 0.74, 0.88), Vector(3, 0.0, 1.0))
    """Colour of the uniform sky (linear RGB)."""
    uniform_sky_strength: float = bounded(0.6, Number(0.0, 100.0))
    """Scale of the uniform sky (the strength of Blender's Background node)."""
    ground_albedo: float = bounded(0.2, Number(0.0, 1.0))
    """Albedo of the ground that lights surfaces from below in the ambient light, where the
    scene has no ground of its own (pure-texture plates); an environment uses its dressed
    ground's mean colour."""
    exposure: float = bounded(2.0, Number(0.0, 100.0, lo_open=True))
    """Scale of linear radiance before the tone map (clip, then the sRGB curve). The paper
    gives no light levels; at 2 (one stop over 1) the Section 3.4 dark filter removes about as
    many views of each camera kind as the paper's did, in GL and in Cycles alike
    (bench/bench_views.py, README "Camera placement")."""
    metering: Literal["scene", "face"] = "scene"
    """"scene": every view at exposure; "face": a view aimed at a member's face ([cameras]
    placement = "faces") is exposed as a camera's light meter sets it: the aimed face's mean
    luminance, under the sun and sky that reach it, comes out at 18 % grey, and the light on
    it is white-balanced (docs/design.md, "Metered exposure"). Other views keep exposure."""

    def __post_init__(self) -> None:
        _validate(self)


@dataclass(frozen=True)
class CyclesConfig:
    """The Cycles twin ([render] renderer = "cycles", and the benches that compare with it)."""

    samples: int = bounded(128, Number(1, 1 << 16, integer=True))
    """Samples per pixel."""

    def __post_init__(self) -> None:
        _validate(self)


SEVERITIES = ("slight", "medium", "severe")
"""Section 3.3's damage severities, in this order (seeded draws index into it)."""


MAX_CRACK_WIDTH_MM = 10.0
"""The widest crack [damage] crack_width_mm may allow."""


@dataclass(frozen=True)
class DamageConfig:
    """Procedural concrete damage and exposed rebar of the columns (paper Section 3.3).

    The paper's numbers are kept as written. Reading (docs/design.md): slight damage is 0-1 %
    damaged area; for medium and severe, the paper's [90 %, 99 %] and [70 %, 90 %] are the intact
    share, i.e. the quantile of |noise| at which the threshold t sits: 1-10 % and 10-30 % damaged
    area.
    """

    resolution: int = bounded(1024, Number(16, 8192, integer=True))
    """Damage texture size in pixels (paper: 2048; the paper preset uses 2048)."""
    octaves: int = bounded(8, Number(1, 16, integer=True))
    frequency: tuple[float, float] = bounded((0.2, 2.0), Interval(0.001, 100.0))
    """First-octave feature size as a fraction of the texture size (paper: 20-200 %)."""
    tile_m: float = bounded(1.0, Number(0.0, 100.0, lo_open=True))
    """Physical size of one damage texture at texture scale 1.0."""
    slight_area: tuple[float, float] = bounded((0.0, 0.01), Interval(0.0, 1.0))
    slight_depth_cm: tuple[float, float] = bounded((1.0, 2.0), Interval(0.0, 1000.0))
    medium_intact: tuple[float, float] = bounded((0.90, 0.99), Interval(0.0, 1.0))
    medium_depth_cm: tuple[float, float] = bounded((1.0, 10.0), Interval(0.0, 1000.0))
    severe_intact: tuple[float, float] = bounded((0.70, 0.90), Interval(0.0, 1.0))
    severe_depth_cm: tuple[float, float] = bounded((2.0, 10.0), Interval(0.0, 1000.0))
    axial_cover_cm: tuple[float, float] = bounded((2.5, 7.5), Interval(0.0, 1000.0))
    stirrup_cover_offset_cm: float = bounded(2.0, Number(0.0, lambda c: c.axial_cover_cm[0]))
    """c_s = c_a - 2 cm."""
    axial_radius: float = bounded(1 / 200, Number(0.0, 0.25, lo_open=True))
    """Rebar radius as a fraction of the texture size."""
    stirrup_radius: float = bounded(1 / 300, Number(0.0, 0.25, lo_open=True))
    spacing_diameters: tuple[float, float] = bounded((3.0, 10.0), Interval(1.0, 1000.0))
    ripple: float = bounded(0.1, Number(0.0, 0.9))
    """Sinusoidal ripple amplitude as a fraction of the bar radius."""
    undamaged_probability: float = bounded(0.1, Number(0.0, 1.0))
    scale: tuple[float, float] = bounded((0.2, 1.0), Interval(0.0, 100.0))
    """Texture scale of a damaged column (the texture repeats every 1/scale * tile_m metres)."""
    bank_size: int = bounded(1000, Number(1, 10**6, integer=True))
    """Damage textures per severity (made lazily, on first use, and cached)."""
    model: Literal["paper", "mechanics"] = "paper"
    """Where damage goes (docs/design.md, "Damage by mechanics"): "paper", Section 3.3's noise
    textures spread uniformly over a column; "mechanics", crack networks with a width in mm on
    the columns and the cross and tie beams, placed by their moment and shear in double
    curvature under a drift. The fields below apply to "mechanics" only."""
    crack_width_mm: tuple[float, float] = bounded(
        (0.05, 5.0), PositiveInterval(MAX_CRACK_WIDTH_MM, "mm"))
    """Range of crack widths: a crack tapers to the lower bound at its tips, and no crack is
    wider than the upper bound."""
    slight_drift_pct: tuple[float, float] = bounded((0.2, 0.5), Interval(0.0, 20.0))
    """Lateral drift ratio of a slightly damaged column, in %: first cracking to about yield
    (a Table 3 column yields at about 0.3-0.7 %)."""
    medium_drift_pct: tuple[float, float] = bounded((0.5, 2.0), Interval(0.0, 20.0))
    """Of a medium one: past yield, up to cover spalling (about 2 %, Berry and Eberhard
    2003)."""
    severe_drift_pct: tuple[float, float] = bounded((2.0, 5.0), Interval(0.0, 20.0))
    """Of a severe one: spalling, up to bar buckling (about 5-6 %, Berry and Eberhard 2003)."""
    fy_mpa: float = bounded(345.0, Number(100.0, 2000.0))
    """Yield strength of the longitudinal bars (SD345, JIS G 3112)."""
    bar_diameter_mm: float = bounded(25.0, Number(1.0, 100.0))
    """Diameter d_b of the longitudinal bars (D25), for the hinge length's strain penetration."""
    stirrup_spacing_m: tuple[float, float] = bounded((0.10, 0.30), Interval(0.01, 2.0))
    """Range of the hoop spacing of a column, which sets the crack spacing: hoops at about
    300 mm in the 1960s Tokaido designs, 100-150 mm in later ones."""
    hinge_span_factor: float = bounded(0.08, Number(0.0, 1.0))
    """Plastic-hinge length Lp = hinge_span_factor L + hinge_bar_factor fy d_b (Priestley and
    Park 1987), L the shear span."""
    hinge_bar_factor: float = bounded(0.022, Number(0.0, 1.0))
    """Strain-penetration term of Lp, per MPa of fy (d_b in m)."""
    cracking_moment_ratio: float = bounded(0.4, Number(0.0, 1.0, lo_open=True))
    """M_cr / M_y of a column section: flexural cracks form where the moment exceeds it."""
    shear_span_ratio: float = bounded(2.5, Number(0.0, 100.0))
    """Shear governs a column whose shear span over effective depth, a / d, is below this
    (Kani's valley: about 2.5)."""
    branch_probability: float = bounded(0.5, Number(0.0, 1.0))
    """Chance that a crack forks once."""
    echelon_probability: float = bounded(0.3, Number(0.0, 1.0))
    """Chance that a crack runs en echelon: as 2-4 parallel pieces, each stepped a few mm to a
    few cm across the crack from the last and overlapping it by a few cm, some joined by a
    short bridge (docs/design.md, "Cracks"); such a crack does not fork."""
    leachate_share: float = bounded(0.0, Number(0.0, 1.0))
    """Share of cracks that leach: white efflorescence or, more often on wider cracks, rust
    running down the face below them, and a damp band beside them (colour only: no label,
    width or depth changes; docs/design.md, "Cracks"). 0: none (the default; the demo and
    inspection presets set 0.3)."""
    beam_service_moment_ratio: float = bounded(0.5, Number(0.0, 1.0))
    """M / M_y of a beam's midspan section under the service load (gravity): allowable-stress
    design keeps the bars' service stress near half their yield strength."""
    severities: tuple[str, ...] = SEVERITIES
    """The severities a damaged member draws from, with equal chance: all three, as Section 3.3
    draws them, or a subset (the inspection preset: "slight" only)."""
    spalling_severities: tuple[str, ...] = ("medium", "severe")
    """The severities whose columns also spall in their hinge zones (the bank's texture of the
    severity, confined to the zones): medium and severe, past cover spalling's onset; the
    inspection preset adds "slight" for the early spalling of long-term monitoring."""
    geometry: bool = bounded(False, Flag())
    """Severe columns lose cover and core concrete in their hinge zones as geometry, with
    buckled longitudinal bars and broken hoops (glsynth.world.severe); false: severe damage is
    only the texture on an intact prism (the paper's)."""

    def __post_init__(self) -> None:
        _validate(self)
        if self.scale[0] <= 0:
            _reject(self, "scale", "an interval of positive scales")
        if (not isinstance(self.severities, tuple) or not self.severities
                or len(set(self.severities)) != len(self.severities)
                or not set(self.severities) <= set(SEVERITIES)):
            _reject(self, "severities", f"a list of distinct names from {list(SEVERITIES)}")
        if (not isinstance(self.spalling_severities, tuple)
                or len(set(self.spalling_severities)) != len(self.spalling_severities)
                or not set(self.spalling_severities) <= set(SEVERITIES)):
            _reject(self, "spalling_severities",
                    f"a list of distinct names from {list(SEVERITIES)} (may be empty)")
        if self.model == "paper" and self.severities != SEVERITIES:
            _reject(self, "severities",
                    f'{list(SEVERITIES)} under model = "paper" (Section 3.3 draws all three)')

    def area_range(self, severity: str) -> tuple[float, float]:
        """Damaged-area fraction range of a severity, under the documented reading."""
        if severity == "slight":
            return self.slight_area
        if severity in ("medium", "severe"):
            lo, hi = getattr(self, f"{severity}_intact")
            return (1.0 - hi, 1.0 - lo)
        raise UserError(f"severity = {severity!r}: choose slight, medium or severe")

    def depth_range_m(self, severity: str) -> tuple[float, float]:
        self.area_range(severity)  # validates the name
        lo, hi = getattr(self, f"{severity}_depth_cm")
        return (lo / 100.0, hi / 100.0)

    @property
    def crack_width_m(self) -> tuple[float, float]:
        """crack_width_mm in metres, the unit of the crack networks."""
        lo, hi = self.crack_width_mm
        return (lo / 1e3, hi / 1e3)

    def drift_range(self, severity: str) -> tuple[float, float]:
        """Lateral drift ratio range (not %) of a severity under ``model = "mechanics"``."""
        self.area_range(severity)  # validates the name
        lo, hi = getattr(self, f"{severity}_drift_pct")
        return (lo / 100.0, hi / 100.0)

    def texture_settings(self) -> dict[str, Any]:
        """The fields the damage textures depend on (the damage bank's cache key): the crack
        settings are left out, so changing them keeps the cached textures."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                if f.name not in _CRACK_FIELDS}


_DAMAGE_FIELDS = [f.name for f in dataclasses.fields(DamageConfig)]
_CRACK_FIELDS = frozenset(_DAMAGE_FIELDS[_DAMAGE_FIELDS.index("model"):])
"""DamageConfig's fields from ``model`` on: the crack model's, not the textures'."""


TEXTURE_PX = (4, 8192)
"""Sides a texture may have, in pixels: the procedural ones (glsynth textures, builtin_size) and
the repository's images once resized (texture_size)."""


@dataclass(frozen=True)
class MaterialsConfig:
    """Texture repository and the per-component PBR rules (paper Sections 2.3, 3.2)."""

    repository: str = ""
    """Folder with concrete/, steel/, painted/, wood/, ground/, scene/ images; empty: the
    built-in procedural repository (generated once and cached)."""
    texture_size: int = bounded(512, Number(*TEXTURE_PX, integer=True))
    """Repository images are resized to this many pixels square."""
    builtin_size: int = bounded(1024, Number(*TEXTURE_PX, integer=True))
    """Pixel size the built-in repository is generated at. Every texture_size is resized
    from these same images, so quality presets differ in resolution, not in content."""
    images_per_category: int = bounded(12, Number(1, 10000, integer=True))
    """Size of the built-in procedural repository."""
    repository_seed: int = bounded(0, Number(0, 2**63 - 1, integer=True))
    """Seed of the built-in procedural repository."""
    concrete_scale: tuple[float, float] = bounded((0.1, 1.0), Interval(0.0, 100.0))
    """Slabs, beams, undamaged columns, sleepers, rails, wires, fences, poles."""
    ground_scale: tuple[float, float] = bounded((0.0, 0.1), Interval(0.0, 100.0))
    """Ground (a scale of 0 shows a single texel colour)."""
    steel_roughness: tuple[float, float] = bounded((0.0, 1.0), Interval(0.0, 1.0))
    painted_metallic: tuple[float, float] = bounded((0.0, 1.0), Interval(0.0, 1.0))
    painted_roughness: tuple[float, float] = bounded((0.0, 1.0), Interval(0.0, 1.0))
    panel_emission: float = bounded(0.5, Number(0.0, 100.0))
    """Emission strength of the scene panels (paper: 0.5)."""
    concrete_detail: Literal["off", "flights", "on"] = "flights"
    """Concrete's millimetre-scale detail on the concrete parts (cement paste, sand, pores,
    bug holes, formwork joints and tie holes; docs/design.md, "Concrete detail"): "flights"
    draws it in glsynth fly's frames alone, where COLMAP needs features at 1-4 mm a pixel,
    and leaves generate's and render's images as the repository makes them; "on" draws it
    everywhere, "off" nowhere."""
    weathering: bool = bounded(False, Flag())
    """Where concrete detail is drawn, also weather the concrete (docs/design.md, "Weathered
    concrete"): a mean albedo from concrete_albedo in place of the repository image's own,
    mottling at 0.1-2 m, dirt collecting at the foot of each face, water streaks running down
    from its top edge, the formwork's joints and tie holes, efflorescence and patch repairs."""
    ground_detail: bool = bounded(False, Flag())
    """The ground's centimetre detail on the ground's parts (docs/design.md, "The ground up
    close"): its cover worn through to bare, partly damp soil in patches, with clods, stones
    and leaves, as a camera near it sees it; off (every preset), the repository image alone."""
    concrete_albedo: tuple[float, float] = bounded((0.22, 0.38), Interval(0.02, 0.9))
    """Under weathering, the range a concrete part's mean albedo (Rec. 709 luminance of its
    linear base colour) is drawn from, uniformly: weathered concrete's published visible and
    solar reflectance (docs/design.md, "Weathered concrete")."""

    def __post_init__(self) -> None:
        if not isinstance(self.repository, str):
            _reject(self, "repository", "a folder path (string)")
        _validate(self)
        if self.weathering and self.concrete_detail == "off":
            _reject(self, "weathering",
                    'false while concrete_detail = "off" (weathering is drawn with the detail)')


@dataclass(frozen=True)
class DatasetConfig:
    """How many environments a run makes and which are held out."""

    n_environments: int = bounded(200, Number(1, 10**6, integer=True))
    """Paper: 200 environments."""
    n_test_environments: int = bounded(25, Number(0, lambda c: c.n_environments, integer=True))
    """The last ones are the test split (paper: 25 of 200)."""
    n_plates: int = bounded(3000, Number(0, 10**7, integer=True))
    """Pure-texture plate images (paper: 3,000)."""
    n_test_plates: int = bounded(300, Number(0, lambda c: c.n_plates, integer=True))
    """The last ones are the test split (paper: 300)."""
    plates_per_task: int = bounded(50, Number(1, 10**6, integer=True))
    """Plates per unit of work (a unit is resumed or redone as a whole)."""

    def __post_init__(self) -> None:
        _validate(self)


@dataclass(frozen=True)
class FiltersConfig:
    """Which rendered views ``generate`` keeps (Section 3.4) and where their damage labels count:
    the region of reliable damage recognition, RRDR (Section 4.2; docs/design.md)."""

    min_intensity: float = bounded(30.0, Number(0.0, 255.0))
    """A view whose mean intensity (0-255) is below this is removed (paper: 30)."""
    min_components: int = bounded(2, Number(1, 9, integer=True))
    """A view showing fewer component labels is removed (paper: 2, i.e. views of a single
    label go); 1 keeps a close-up that one member fills."""
    min_depth_m: float = bounded(0.5, Number(0.0, 100.0))
    """A view whose nearest pixel is this near or nearer is removed (paper: 0.5 m)."""
    rrdr_px_per_cm: float = bounded(1.5, Number(0.0, 1000.0, lo_open=True))
    """The paper's RRDR: a pixel is reliable where the image resolves at least this many
    pixels per cm on a fronto-parallel surface, f_px / (100 depth)."""
    rrdr_crack_mm: float = bounded(0.0, Number(0.0, 10.0))
    """0: the paper's RRDR. Above 0, the RRDR for cracks replaces it: a pixel is reliable
    where its footprint, depth / f_px, is at most rrdr_footprint_factor times this crack
    width, the narrowest crack of interest."""
    rrdr_footprint_factor: float = bounded(2.0, Number(0.0, 100.0, lo_open=True))
    """k of the RRDR for cracks: a crack of width w is resolved by pixels of footprint up to
    k w, i.e. where it covers at least 1/k of a pixel's width (docs/design.md)."""

    def __post_init__(self) -> None:
        _validate(self)


@dataclass(frozen=True)
class FlightConfig:
    """An inspection flight (glsynth fly; glsynth.world.flights): the path, its overlap and
    the camera. The image size is [render]'s, the sensor width [cameras]'."""

    plan: Literal["orbit", "facade", "underdeck"] = "orbit"
    """"orbit": rings around one column; "facade": a lawnmower along one side of a viaduct,
    columns and beams; "underdeck": along the centre line under the deck."""
    column: int = bounded(0, Number(0, 100000, integer=True))
    """Orbit: the column, counted over the environment in build order (viaduct by viaduct,
    row by row, left then right)."""
    viaduct: int = bounded(0, Number(0, 1000, integer=True))
    """Facade and underdeck: the viaduct flown along."""
    side: Literal["left", "right"] = "left"
    """Facade: the side of the track (walking along it) the drone flies."""
    standoff_m: float = bounded(2.0, Number(0.0, 1000.0, lo_open=True))
    """Distance to the inspected surface: orbit, to the column's edges (its nearest points);
    facade, across to the outermost column or girder face; underdeck, down from the slab's
    underside. Columns stand 6 m apart across and along the track ([design]
    column_spacing_m), so with the default clearance an orbit wider than 4 m meets a
    neighbouring column and is refused (seed 0, environment 0: 4 m passes, 4.5 m not)."""
    heights_m: tuple[float, ...] = bounded(
        (1.5, 3.0), Numbers(0.0, 1000.0, "a non-empty list of heights in metres"))
    """Orbit: the rings' heights above the column's foot, flown in this order. flight.json
    reports how much consecutive rings overlap (ring_overlap_pct; side_overlap_pct does not
    place them)."""
    arc_deg: float = bounded(360.0, Number(0.0, 360.0))
    """Orbit: the angle each ring sweeps (360: a closed ring; 0: one frame per ring)."""
    length_m: float = bounded(math.inf, Number(0.0, math.inf))
    """Facade and underdeck: distance flown along the track from the viaduct's start, cut at
    its end (0: one frame per row)."""
    forward_overlap_pct: float = bounded(80.0, Number(0.0, 99.0))
    """Overlap of consecutive frames along the path, at the stand-off."""
    side_overlap_pct: float = bounded(60.0, Number(0.0, 99.0))
    """Facade: overlap of neighbouring rows, at the stand-off."""
    speed_mps: float = bounded(2.0, Number(0.0, 100.0, lo_open=True))
    """Flight speed; a frame's time is its distance along the path over this."""
    frame_rate_hz: float = bounded(30.0, Number(0.0, 1000.0, lo_open=True))
    """The camera's highest frame rate: the spacing over the speed may not be shorter."""
    gimbal_pitch_deg: float = bounded(0.0, Number(-90.0, 90.0))
    """Camera pitch above the horizontal (90 looks straight up, -90 down)."""
    focal_mm: float = bounded(24.0, Number(1.0, 1000.0))
    """Focal length (the sensor is [cameras] sensor_mm wide)."""
    camera_model: Literal["PINHOLE", "SIMPLE_RADIAL", "OPENCV"] = "PINHOLE"
    """COLMAP's camera model of the frames: a pinhole, or radial distortion (k1; OPENCV also
    k2) applied to colour by resampling and to labels and depth by nearest lookup
    (glsynth.world.lens)."""
    k1: float = bounded(0.0, Number(-1.0, 1.0))
    """Radial distortion: x_d = x (1 + k1 r^2 + k2 r^4) on normalized coordinates (< 0:
    barrel)."""
    k2: float = bounded(0.0, Number(-1.0, 1.0))
    """OPENCV only."""
    clearance_m: float = bounded(1.0, Number(0.01, 100.0))
    """Least distance from the path to any mesh; a plan that comes closer is refused."""
    max_frames: int = bounded(0, Number(0, 10**6, integer=True))
    """Stop after this many frames (0: fly the whole plan)."""
    exposure: Literal["metered", "scene"] = "metered"
    """"metered": the camera exposes once for the whole flight, so that the median pixel of
    four frames spread along the path is 18 % grey (an orbit in the deck's shade meters about
    1.4 stops above the scene's exposure); "scene": [lighting] exposure, as glsynth render
    uses (glsynth.data.flight.exposed)."""
    point_stride_px: int = bounded(4, Number(1, 1024, integer=True))
    """points.ply: every point_stride_px-th pixel of each frame, in both directions."""
    point_spacing_m: float = bounded(0.05, Number(1e-4, 100.0))
    """points.ply: at most one point per cube of this side (the first frame's, in order)."""

    def __post_init__(self) -> None:
        _validate(self)
        if self.camera_model != "OPENCV" and self.k2 != 0.0:
            _reject(self, "k2", '0 unless camera_model = "OPENCV"')
        if self.camera_model == "PINHOLE" and self.k1 != 0.0:
            _reject(self, "k1", '0 unless camera_model is "SIMPLE_RADIAL" or "OPENCV"')


@dataclass(frozen=True)
class SensorConfig:
    """The photograph: lens, sensor and encoder applied to the rendered colour
    (glsynth.render.camera_model; docs/design.md, "The camera model"). Named [sensor], not
    [camera], because [cameras] already places the cameras. Each range is drawn per view from
    the view's own generator (Stream.SENSOR); [a, a] fixes a value. Off in the paper preset,
    whose images stay the paper's pinhole renders; on in the others."""

    enabled: bool = bounded(False, Flag())
    iso: tuple[float, float] = bounded((100.0, 1600.0), Interval(25.0, 102400.0))
    """ISO speed: the gain over base ISO 100, which scales shot and read noise alike."""
    full_well_e: float = bounded(20000.0, Number(100.0, 1e7))
    """Electrons that fill a pixel at base ISO (linear 1.0): shot noise variance x / this."""
    read_noise_e: float = bounded(3.0, Number(0.0, 1000.0))
    """Read noise, electrons RMS at base ISO."""
    f_number: tuple[float, float] = bounded((2.8, 11.0), Interval(0.7, 64.0))
    """Aperture N of the thin lens: blur-circle diameter f^2 |d - s| / (N (s - f) d)."""
    exposure_s: tuple[float, float] = bounded((1 / 1000, 1 / 60),
                                              PositiveInterval(30.0, "seconds"))
    """Exposure time; motion blur is the image velocity times it."""
    shake_deg_s: tuple[float, float] = bounded((0.0, 2.0), Interval(0.0, 90.0))
    """Handheld shake: angular speed of the camera (fly uses the drone's path instead)."""
    vignetting: tuple[float, float] = bounded((0.3, 1.0), Interval(0.0, 1.0))
    """Strength v: a pixel at field angle t keeps 1 - v (1 - cos^4 t) of its light."""
    chromatic_px: tuple[float, float] = bounded((0.0, 1.5), Interval(0.0, 10.0))
    """Lateral chromatic aberration: red and blue shifted apart by this much at the corners."""
    white_balance: tuple[float, float] = bounded((0.92, 1.08), Interval(0.5, 2.0))
    """The automatic white balance's error: gains of red and blue over green (each drawn on
    its own), after the grey-world gains (glsynth.render.camera_model)."""
    exposure_ev: tuple[float, float] = bounded((-0.5, 0.5), Interval(-4.0, 4.0))
    """Exposure error in stops."""
    jpeg_quality: tuple[int, int] = bounded((70, 95), Interval(1, 100))
    """Quality of the JPEG round trip the saved image takes (the files stay PNG)."""
    sharpen: tuple[float, float] = bounded((0.2, 1.0), Interval(0.0, 5.0))
    """The processing's unsharp mask on the encoded image: the share of the detail finer
    than sharpen_sigma_px added back (0: none), as a camera's processor sharpens."""
    sharpen_sigma_px: tuple[float, float] = bounded((0.6, 1.4), Interval(0.3, 5.0))
    """The unsharp mask's Gaussian, in pixels."""

    def __post_init__(self) -> None:
        _validate(self)
        if any(not float(q).is_integer() for q in self.jpeg_quality):
            _reject(self, "jpeg_quality", "two whole numbers in [1, 100]")


@dataclass(frozen=True)
class Config:
    environment: EnvironmentConfig = field(default_factory=EnvironmentConfig)
    design: StandardDesign = field(default_factory=StandardDesign)
    dataset: DatasetConfig = field(default_factory=DatasetConfig)
    cameras: CameraConfig = field(default_factory=CameraConfig)
    render: RenderConfig = field(default_factory=RenderConfig)
    lighting: LightingConfig = field(default_factory=LightingConfig)
    cycles: CyclesConfig = field(default_factory=CyclesConfig)
    damage: DamageConfig = field(default_factory=DamageConfig)
    materials: MaterialsConfig = field(default_factory=MaterialsConfig)
    filters: FiltersConfig = field(default_factory=FiltersConfig)
    flight: FlightConfig = field(default_factory=FlightConfig)
    sensor: SensorConfig = field(default_factory=SensorConfig)

    def __post_init__(self) -> None:
        half_deck = self.design.deck_width_m / 2
        if self.environment.panel_distance_m <= half_deck + 1.0:
            _reject(self.environment, "panel_distance_m",
                    f"more than half the deck width plus 1 m ({half_deck + 1.0})")
        if self.cameras.face_crack_share and self.damage.model != "mechanics":
            _reject(self.cameras, "face_crack_share",
                    '0 unless [damage] model = "mechanics" (the paper model makes no cracks)')


_WEATHERED = {"concrete_detail": "on", "weathering": True}
"""Concrete as a camera at 0.3-3 m sees it (issue 39): every preset but the paper's, whose
bytes stay those of Section 3.2's repository images. (The ground's detail is off in every
preset: docs/results.md, "Foot views on the ground up close".)"""

_SURROUNDINGS = {"world": "town", "fences": "open", "jacket_probability": 0.3,
                 "brace_probability": 0.2, "downpipe_probability": 0.5,
                 "trough_probability": 0.5, "sign_probability": 0.5}
"""Issue 40 for every preset but the paper's, whose views keep Section 3.1's photo panels,
solid fences and no class 8: a 3-D town around the viaducts, see-through railings, and
class 8's others (docs/design.md, "Others")."""

PRESETS: dict[str, dict[str, dict[str, Any]]] = {
    # The paper's full configuration (200 environments, 25 of them test).
    "paper": {"damage": {"resolution": 2048}},
    # A small but complete run for the README's main job and for tests, with damage where
    # mechanics puts it (docs/design.md, "Damage by mechanics"); the paper preset keeps
    # Section 3.3's noise damage.
    "demo": {"dataset": {"n_environments": 3, "n_test_environments": 1, "n_plates": 12,
                         "n_test_plates": 2, "plates_per_task": 6},
             "environment": _SURROUNDINGS, "cameras": {"n_regular": 6, "n_closeup": 6},
             "damage": {"resolution": 512, "model": "mechanics", "geometry": True,
                        "leachate_share": 0.3},
             "materials": _WEATHERED, "sensor": {"enabled": True}},
    # Close-range inspection (issue 29, the paper's future work iv; docs/design.md,
    # "Inspection preset"): 4 environments (1 test) x 24 cameras at member faces = 96 views,
    # three in four aimed at a crack from where its width spans 18 pixels (6 in the 640x360
    # labels) or more; slight and medium cracks of 0.05-3 mm by mechanics with early spalling
    # in the hinge zones, the RRDR for cracks of 0.2 mm and more. No plates: they show
    # Section 3.3's noise damage of every severity, not cracks.
    "inspection": {
        "environment": _SURROUNDINGS,
        "dataset": {"n_environments": 4, "n_test_environments": 1, "n_plates": 0,
                    "n_test_plates": 0},
        "cameras": {"placement": "faces", "n_regular": 0, "n_closeup": 24,
                    "focal_mm": (24.0, 105.0), "face_distance_m": (0.3, 3.0),
                    "face_angle_deg": 30.0, "face_roll_deg": 5.0, "face_crack_share": 0.75,
                    "face_crack_px": 18.0},
        "damage": {"resolution": 512, "model": "mechanics", "severities": ("slight", "medium"),
                   "spalling_severities": ("slight",), "undamaged_probability": 0.2,
                   "crack_width_mm": (0.05, 3.0), "geometry": True, "leachate_share": 0.3},
        "filters": {"min_components": 1, "min_depth_m": 0.1, "rrdr_crack_mm": 0.2,
                    "rrdr_footprint_factor": 2.0},
        "materials": _WEATHERED, "lighting": {"metering": "face"},
        "sensor": {"enabled": True}},
}

_SECTIONS: dict[str, type] = typing.get_type_hints(Config)
"""The config file's sections: Config's fields, by name."""
_SECTION_OF = {cls: name for name, cls in _SECTIONS.items()}


def _validate(section: Any) -> None:
    """Every field of a section against the rule in its metadata (glsynth.core.checks)."""
    validate(section, _SECTION_OF[type(section)])


def _reject(section: Any, name: str, expected: str) -> typing.NoReturn:
    """A section's field breaks a rule its metadata cannot state (one that reads other fields
    or another section)."""
    fail(_SECTION_OF[type(section)], name, getattr(section, name), expected)


def _as_float(value: Any) -> Any:
    """A TOML integer as the float a field holds; one too large for a float stays an integer
    (its field's bound refuses it, naming it)."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) < 2 ** 1023:
        return float(value)
    return value


def _coerce(cls: type, key: str, value: Any) -> Any:
    hint = typing.get_type_hints(cls)[key]
    if isinstance(value, list):
        return tuple(_as_float(v) for v in value)
    if hint is float:
        return _as_float(value)
    return value


_MOVED_FROM_RENDER = {
    **{f.name: ("lighting", f.name) for f in dataclasses.fields(LightingConfig)},
    "sun_intensity": ("lighting", "sun_irradiance"),
    "ambient_intensity": ("lighting", "uniform_sky_strength"),
    "cycles_samples": ("cycles", "samples"),
}
"""Keys that [render] once held, and where they are now."""

_REMOVED_FROM_RENDER = {
    "ambient": "the ambient light is always the sky's and the lit ground's irradiance as "
               "spherical harmonics, occluded by [render] sky_visibility_maps",
    "tone_map": "the tone map is always Blender's Standard view transform (radiance x "
                "[lighting] exposure, clipped, then the sRGB curve)",
}
"""Keys of retired lighting modes, and what glsynth does instead."""


def _check_keys(section: str, values: dict[str, Any], cls: type) -> None:
    """One line for the first key ``section`` does not hold: where it moved, why it was
    removed, or the keys it does hold."""
    if section == "render":
        for key in values:
            if key in _MOVED_FROM_RENDER:
                new_section, new_key = _MOVED_FROM_RENDER[key]
                raise UserError(f"[render] {key} moved: write it as [{new_section}] {new_key}")
            if key in _REMOVED_FROM_RENDER:
                raise UserError(f"[render] {key} was removed: {_REMOVED_FROM_RENDER[key]}; "
                                "delete the line")
    allowed = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(values) - allowed)
    if unknown:
        # A file can hold any number of keys of any length: name the first few, shortened.
        listed = [k if len(k) <= 30 else f"{k[:24]}..." for k in unknown[:2]]
        more = f" and {len(unknown) - 2} more" if len(unknown) > 2 else ""
        keys = ", ".join(sorted(allowed))
        if len(keys) > 120:  # a long section: the nearest keys, so the line stays short
            near = difflib.get_close_matches(unknown[0], sorted(allowed), n=3, cutoff=0)
            keys = f"{len(allowed)} keys, the nearest {', '.join(near)}"
        raise UserError(f"unknown key(s) {listed}{more} in [{section}]: allowed keys are {keys}")


def config_from_dict(data: dict[str, Any], base: Config | None = None) -> Config:
    """Overlay ``{section: {key: value}}`` on ``base`` (default: the built-in defaults)."""
    base = base or Config()
    sections = {}
    for section, values in data.items():
        if section not in _SECTIONS:
            name = section if len(section) <= 40 else f"{section[:30]}..."
            raise UserError(f"unknown config section [{name}]: "
                            f"allowed sections are {sorted(_SECTIONS)}")
        cls = _SECTIONS[section]
        if not isinstance(values, dict):
            raise UserError(f"config section [{section}] must be a table of key = value")
        _check_keys(section, values, cls)
        coerced = {k: _coerce(cls, k, v) for k, v in values.items()}
        sections[section] = dataclasses.replace(getattr(base, section), **coerced)
    return dataclasses.replace(base, **sections)


def load_config(preset: str = "paper", path: str | Path | None = None) -> Config:
    """A named preset, optionally overlaid with a TOML file."""
    if preset not in PRESETS:
        raise UserError(f"preset = {preset!r}: choose one of {sorted(PRESETS)}")
    config = config_from_dict(PRESETS[preset])
    if path is not None:
        from glsynth.core.reading import MAX_TOML_BYTES, read_bytes

        path = Path(path)
        text = read_bytes(path, "config file", MAX_TOML_BYTES, "give a .toml file")
        try:
            decoded = text.decode("utf-8")
        except UnicodeDecodeError as err:
            raise UserError(f"config file {str(path)!r} is not UTF-8 text (byte {err.start}); "
                            "save it as UTF-8") from None
        config = config_from_dict(parse_toml(decoded, f"config file {str(path)!r}"), config)
    return config


def parse_toml(text: str, what: str) -> dict[str, Any]:
    """A config file's text as tables; ``what`` names it in the one-line refusal of text that
    is not TOML or nests deeper than Python's stack (tomllib recurses per level)."""
    try:
        return tomllib.loads(text)
    except RecursionError:
        raise UserError(f"{what} nests too deeply") from None
    except tomllib.TOMLDecodeError as err:
        raise UserError(f"{what} is not valid TOML: {' '.join(str(err).split())}") from None


def config_to_dict(config: Config) -> dict[str, Any]:
    """Plain JSON-able form (inf stays a float; json writes it as Infinity)."""
    return dataclasses.asdict(config)
