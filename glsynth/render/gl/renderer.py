"""Offscreen renderer: draws a glsynth RenderScene (a pyrender Scene) with glsynth's programs.

``load`` uploads a scene and bakes its sky-visibility maps (depth maps of the whole scene seen
from 16 sky directions, when [render] sky_visibility_maps > 0). ``render`` then runs one pass
per method, in this order; each writes its own targets:
1. sky visibility (for colour, when the scene has sky-visibility maps): the 16 sky-map
   lookups at every second pixel in each direction, into half-size targets the colour pass
   upsamples within each surface (shaders/sky_visibility.frag), after a depth-only draw so
   that each pixel's nearest surface alone is shaded;
2. shadow (for colour, when [render] shadow_map_px > 0 and the sun is up): depth from the sun
   into a depth texture fitted to this camera's view (glsynth.world.sunlight);
3. labels: one draw per part into one RGBA32F texture holding (component id, damage id, linear
   depth, hit), single-sampled; the ids are then exact and depth is float32 along the optical
   axis. In a view that shows a part with cracks, every part is drawn by the crack variant of
   the program, which also writes each pixel's crack width (mm) and the share of the pixel
   that cracks cover into an RG32F texture;
4. ambient occlusion (for colour, when [render] ao = "ssao"): from the label texture's depth,
   then a 4x4 blur, into a one-channel texture the colour pass reads per pixel;
5. colour: PBR into an RGBA8 texture, lit by the environment's Lighting
   (glsynth.world.lighting), tested against the label pass's depth so that each pixel is shaded
   once; parts with cracks through the crack variant, which darkens them by the label pass's
   crack coverage; the sky is drawn last, where no geometry was;
6. MSAA (when msaa > 0): the geometry again into multisampled targets that keep each sample's
   surface (shaders/msaa.frag); a fullscreen pass gives a pixel whose samples all lie on its
   centre's surface that centre's colour (shaders/msaa_interior.frag), and a second, only at
   the other pixels, gives each sample the colour shaded at a pixel centre on its own surface
   and the pixel the mean of its samples (shaders/msaa_resolve.frag);
7. read-back: the label texture and the (resolved) colour into numpy arrays.
Only the passes asked for (and those they need) are drawn, and each draws only the parts whose
boxes may be in its frustum (the camera's; the sun's shadow map and the sky-visibility maps,
in x and y), which changes no byte. Pixels with no geometry read component 1 (Nonbridge),
damage 1 (no damage) and depth = zfar.

Cracks (a material's CrackNetwork) are packed by glsynth.render.cracks_index into three
textures per part, uploaded the first time a view shows the part (packing is most of a cracked
scene's load: an interactive viewer opens it sooner, and a render packs only what its cameras
see; the bytes are the same), and evaluated in the fragment shader
(shaders/cracks.glsl); the crack code is compiled only into the programs' crack variants
(programs.Variant.CRACKS), which only views and parts with cracks use, so a scene without cracks
runs the very programs it ran before. Likewise a material's damage zones (a spalled column's
hinge zones) are drawn by the zone variants (Variant.SPALL), which confine its damage mask and
damaged material to mesh-frame z intervals and show its intact concrete elsewhere.
"""

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace

import cv2
import moderngl
import numpy as np
import pyrender

from glsynth.appearance.cracks import CrackNetwork
from glsynth.appearance.materials import MAX_ZONES, Material, built_in_order, srgb_decode
from glsynth.core.config import RenderConfig
from glsynth.core.errors import UserError
from glsynth.core.interrupts import RenderInterrupted
from glsynth.core.labels import Component, Damage
from glsynth.core.memory import available_bytes
from glsynth.render.cracks_index import CrackIndex, crack_contrast, pack_cracks
from glsynth.render.gl.context import check_render_size, create_context
from glsynth.render.gl.programs import (
    MAX_VIS,
    ProgramKey,
    Programs,
    TextureUnits,
    Variant,
    settings_constants,
)
from glsynth.render.leachate_index import LeachateIndex, pack_leachate
from glsynth.render.passes import DRAWN, LABEL_PASSES
from glsynth.render.scene import PartInfo, RenderScene
from glsynth.world.cameras import Camera
from glsynth.world.lighting import (
    LUMINANCE,
    Lighting,
    occlusion_matrices,
    sky_directions,
    sky_solid_angle,
)
from glsynth.world.sunlight import shadow_matrix, shadow_texel_m
from glsynth.world.visibility import box_corners, in_clip_xy, seen_by

PASSES = DRAWN
"""The passes render draws (glsynth.render.passes)."""
_GL_DEPTH_CLAMP = 0x864F  # core since GL 3.2; moderngl has no flag for it
_DEPTH_MAP_OFFSET = (2.0, 4.0)
"""Slope-scaled polygon offset of the depth maps (sun, sky) against acne on grazed surfaces."""
PROBE_SIZE = (64, 64)
"""The image size a Renderer's targets are first made at (see Renderer.__init__)."""
_ATTRIBUTES = {"color": ("3f 3f 2f", "in_position", "in_normal", "in_uv"),
               "labels": ("3f 12x 2f", "in_position", "in_uv"),
               "shadow": ("3f 20x", "in_position"),
               "msaa": ("3f 3f 8x", "in_position", "in_normal"),
               "sky_visibility": ("3f 3f 8x", "in_position", "in_normal")}
"""The vertex layout and attributes each mesh program reads of (position, normal, uv)."""
_REVERSED = ("color", "sky_visibility")
"""The mesh programs that draw parts and triangles in reverse order, against a depth drawn
before them (_color_pass)."""
_NO_COLOUR, _ALL_COLOUR = ((False,) * 4,), ((True,) * 4,)
"""One colour attachment's write mask, off and on (Framebuffer.color_mask takes one each)."""
_CRACK_SAMPLERS = ("u_crack_segments", "u_crack_cells", "u_crack_entries")
_LEACH_SAMPLERS = ("u_leach_items", "u_leach_cells", "u_leach_entries")
_MATERIAL_SAMPLERS = {"base": "u_base_color_map", "emissive": "u_emissive_map",
                      "normal": "u_normal_map", "intact": "u_intact_map", "spall": "u_spall_map"}
"""A draw's texture slot -> the colour programs' sampler that reads it."""
_CLIP_TO_TEXTURE = np.array([[0.5, 0, 0, 0.5], [0, 0.5, 0, 0.5], [0, 0, 0.5, 0.5], [0, 0, 0, 1.0]])


@dataclass(frozen=True)
class RenderOutput:
    color: np.ndarray | None = None
    """(H, W, 3) uint8 sRGB."""
    component: np.ndarray | None = None
    """(H, W) uint8 component ids."""
    damage: np.ndarray | None = None
    """(H, W) uint8 damage ids."""
    depth: np.ndarray | None = None
    """(H, W) float32 metres along the optical axis; zfar where nothing was hit."""
    crack_width: np.ndarray | None = None
    """(H, W) float32 millimetres, with ``damage``: at each pixel a crack labels (concrete
    damage by the crack rule of docs/design.md), the width of the nearest such crack there;
    0 elsewhere, and everywhere in a view without cracks."""


@dataclass(frozen=True, eq=False)
class CrackTextures:
    """A part's crack network on the GPU (glsynth.render.cracks_index.CrackIndex)."""
    textures: tuple[moderngl.Texture, moderngl.Texture, moderngl.Texture]
    """Segments, cells, entries: shaders/cracks.glsl's three samplers, in this order."""
    origin: tuple[float, float, float]
    cell_m: float
    dims: tuple[int, int, int]
    rough: bool
    footprint_m: float
    """The grid's uniforms; the index's arrays are not kept (the textures hold them, and a
    demo environment's would add 155 MB to the RSS)."""
    contrast: float
    """The share of the reflected light the network's cracks take away (crack_contrast)."""
    leach: tuple[moderngl.Texture, moderngl.Texture, moderngl.Texture] | None = None
    """The leaching cracks' items, cells, entries (glsynth.render.leachate_index), or None."""
    leach_grid: tuple[tuple[float, float, float], float, tuple[int, int, int]] | None = None
    """Their grid's origin (relative to ``origin``), cell edge and dims."""

    @property
    def all(self) -> tuple[moderngl.Texture, ...]:
        """Every texture, to release."""
        return self.textures + (self.leach or ())

    def bind_colour(self, prog: moderngl.Program, units: TextureUnits) -> None:
        """A colour program's crack grid origin, the cracks' contrast and their leachate
        (shaders/crack_leachate.glsl), with the crack segments whose paths it follows."""
        prog["u_crack_origin"].value = self.origin
        prog["u_crack_contrast"].value = self.contrast
        prog["u_has_leach"].value = self.leach is not None
        if self.leach is None:
            return
        units.bind(_CRACK_SAMPLERS[0], self.textures[0])  # the paths the leachate follows
        prog["u_crack_rough"].value = self.rough
        for name, texture in zip(_LEACH_SAMPLERS, self.leach, strict=True):
            units.bind(name, texture)
        origin, cell, dims = self.leach_grid
        prog["u_leach_origin"].value = origin
        prog["u_leach_cell_m"].value = cell
        prog["u_leach_dims"].value = dims

    def bind(self, prog: moderngl.Program, units: TextureUnits) -> None:
        """Bind the textures to their samplers' units and set ``prog``'s crack uniforms."""
        for name, texture in zip(_CRACK_SAMPLERS, self.textures, strict=True):
            units.bind(name, texture)
        # Read by the vertex stage (shaders/mesh.vert); a program of cracks.glsl alone (the
        # shader harness) takes positions relative to the origin and has no such uniform.
        origin = prog.get("u_crack_origin", None)
        if origin is not None:
            origin.value = self.origin
        prog["u_crack_cell_m"].value = self.cell_m
        prog["u_crack_dims"].value = self.dims
        prog["u_crack_rough"].value = self.rough
        prog["u_crack_footprint_m"].value = self.footprint_m


@dataclass(frozen=True, eq=False)
class ZoneUniforms:
    """A part's damage zones (glsynth.appearance.materials.DamageZones) as its programs'
    zone variants read them."""
    zones: bytes
    """MAX_ZONES (z0, z1) float32 pairs, zero-padded."""
    count: int
    intact_uv_ratio: float
    """The intact map's uv_scale over the damage material's (the part's UVs carry the
    latter)."""

    def set(self, prog: moderngl.Program) -> None:
        prog["u_zones"].write(self.zones)
        prog["u_zone_count"].value = self.count


def zone_uniforms(material: Material) -> ZoneUniforms:
    zones = material.zones
    pairs = np.zeros((MAX_ZONES, 2), np.float32)
    pairs[:len(zones.intervals)] = zones.intervals
    return ZoneUniforms(pairs.tobytes(), len(zones.intervals),
                        zones.intact_uv_scale / material.uv_scale)


@dataclass(frozen=True)
class DetailUniforms:
    """A part's concrete or ground detail (Material.detail_seed) as the colour pass's detail
    variants read it."""
    seed: int
    origin: tuple[float, float, float]
    """The part's box's lower corner in its mesh frame: shaders/mesh.vert subtracts it, so
    that a girder's fragments, hundreds of metres from its frame's origin, keep sub-mm
    steps."""
    top: float
    """The box's height: weathering's rain runs down from there."""
    tint: tuple[float, float, float] | None
    """Material.weathering_tint; None: the detail is not weathered."""
    ground: bool = False
    """Material.ground_detail: the ground's variant, which reads the seed and origin alone."""

    def set(self, prog: moderngl.Program) -> None:
        prog["u_detail_seed"].value = self.seed
        prog["u_detail_origin"].value = self.origin
        if self.ground:
            return
        prog["u_weathering"].value = self.tint is not None
        prog["u_detail_tint"].value = self.tint or (1.0, 1.0, 1.0)
        prog["u_detail_top"].value = self.top


@dataclass
class _Draw:
    name: str
    pose: np.ndarray
    vaos: dict[ProgramKey, moderngl.VertexArray]
    buffers: tuple[moderngl.Buffer, ...]
    """Vertex and index buffers: the VAOs use them, the scene owns them (release_scene)."""
    material: Material
    """Its factors (the maps are in ``textures``)."""
    textures: dict[str, moderngl.Texture]
    component: float
    damage_mask: moderngl.Texture | None
    center: np.ndarray
    """World-space centre of the bounding box, for front-to-back ordering."""
    radiance: np.ndarray
    """Mean emitted radiance (3,), linear: the light it sends where it hides the sky."""
    corners: np.ndarray
    """(8, 3) world-space corners of the box, for the frustum tests."""
    cracks: CrackNetwork | None = None
    """The part's cracks, packed and uploaded into ``crack_textures`` when a view first
    shows the part (Renderer.prepare_cracks)."""
    crack_textures: CrackTextures | None = None
    zones: ZoneUniforms | None = None
    """Where the part's damage material applies (textures "intact" and "spall" with it)."""
    detail: DetailUniforms | None = None

    def program(self, base: str, view_has_cracks: bool) -> ProgramKey:
        """The variant of ``base`` that draws this part: with crack code in a view with
        cracks (labels) or for a part with cracks (colour), with zone code for a part with
        zones, and (colour) with detail code for a part with concrete or ground detail."""
        if base == "labels":
            return base, Variant.of(view_has_cracks, self.zones is not None)
        return base, Variant.of(self.cracks is not None, self.zones is not None,
                                self.detail is not None,
                                self.detail is not None and self.detail.ground)


@dataclass(frozen=True)
class _Placed:
    """A draw that the camera may see, with its matrices for that camera (float32 bytes),
    computed once for every pass of the view."""
    draw: _Draw
    modelview: bytes
    normal: bytes


@dataclass(frozen=True, eq=False)
class _SkyMaps:
    """The loaded scene's sky-visibility maps, baked once per scene (one tile of the atlas
    each)."""
    atlas_from_world: np.ndarray
    """(N, 4, 4) world to each map's atlas texture coordinates and depth, all in [0, 1]."""
    directions: np.ndarray
    """(N, 3) unit world directions towards the sky, one per map."""
    weights: np.ndarray
    """(N,) the sky's luminance in each direction (at least 1e-6)."""
    texel_m: float
    """The largest map texel, in metres: lookups move 1.5 of it along the normal."""


def _gl_matrix(matrix: np.ndarray) -> bytes:
    """A matrix, or a stack of them (..., N, N), as GLSL reads a mat: float32, column by
    column."""
    return np.swapaxes(np.asarray(matrix).astype("f4"), -1, -2).tobytes()


@contextmanager
def _depth_state(ctx: moderngl.Context, depth_func: str = "<", offset: bool = False,
                 clamp: bool = False) -> Iterator[None]:
    """Depth-tested drawing of both faces by ``depth_func``; ``offset``: the depth maps'
    slope-scaled offset (_DEPTH_MAP_OFFSET); ``clamp``: depth clamping. Afterwards the depth
    function is "<" again, with no offset and no clamping."""
    ctx.enable(moderngl.DEPTH_TEST)
    ctx.disable(moderngl.CULL_FACE)
    ctx.depth_func = depth_func
    ctx.polygon_offset = _DEPTH_MAP_OFFSET if offset else (0.0, 0.0)
    if clamp:
        ctx.enable_direct(_GL_DEPTH_CLAMP)
    try:
        yield
    finally:
        if clamp:
            ctx.disable_direct(_GL_DEPTH_CLAMP)
        ctx.polygon_offset = (0.0, 0.0)
        ctx.depth_func = "<"


def _atlas_from_clip(matrices: np.ndarray, tiles: int) -> np.ndarray:
    """(N, 4, 4): each sky map's clip-from-world matrix ``matrices`` into atlas texture
    coordinates, the tile's [0, 1] square scaled into its place (map k at column k % tiles,
    row k // tiles)."""
    atlas = []
    for k, light in enumerate(matrices):
        tile = np.eye(4)
        tile[0, 0] = tile[1, 1] = 1.0 / tiles
        tile[0, 3], tile[1, 3] = (k % tiles, k // tiles) / np.float64(tiles)
        atlas.append(tile @ _CLIP_TO_TEXTURE @ light)
    return np.array(atlas)


def texture_data(array: np.ndarray, alpha: np.ndarray | None = None) -> np.ndarray:
    """The bytes to upload for image ``array`` (H, W[, C]) uint8, with ``alpha`` (H, W) as a
    fourth channel if given. Image rows run top to bottom and GL's t bottom to top: the rows
    are flipped so that uv (0, 0) is the image's bottom-left corner, as glTF and Blender
    define it. OpenCV's flip and channel copies, faster than numpy's strided ones
    (docs/results.md, "Measurements behind code choices"), give the same bytes."""
    if alpha is None:
        return cv2.flip(array, 0)
    data = cv2.cvtColor(cv2.flip(array, 0), cv2.COLOR_RGB2RGBA)
    cv2.mixChannels([cv2.flip(alpha, 0)], [data], [0, 3])
    return data


def _emitted(material: Material) -> np.ndarray:
    """Mean emitted radiance (3,) of a material, linear."""
    emissive = np.asarray(material.emissive, np.float64)
    if material.emissive_map is None or not emissive.any():
        return emissive
    return emissive * srgb_decode(material.emissive_map).mean((0, 1))


def _texel_textures(ctx: moderngl.Context, arrays: tuple[np.ndarray, np.ndarray, np.ndarray]
                    ) -> tuple[moderngl.Texture, moderngl.Texture, moderngl.Texture]:
    """Items (RGBA32F), cells (RG32I) and entries (R32I) of a packing, read texel by texel."""
    textures = []
    for data, channels, dtype in zip(arrays, (4, 2, 1), ("f4", "i4", "i4"), strict=True):
        texture = ctx.texture(data.shape[1::-1], channels, data.tobytes(), dtype=dtype)
        texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        textures.append(texture)
    return tuple(textures)


def upload_cracks(ctx: moderngl.Context, index: CrackIndex, contrast: float,
                  leach: LeachateIndex | None = None) -> CrackTextures:
    """A packed crack network's textures, and its leaching cracks' if any (the caller
    releases them); ``contrast``: its cracks' (crack_contrast)."""
    textures = _texel_textures(ctx, (index.segments, index.cells, index.entries))
    leach_textures = leach_grid = None
    if leach is not None:
        leach_textures = _texel_textures(ctx, (leach.items, leach.cells, leach.entries))
        leach_grid = (tuple(float(v) for v in leach.origin), leach.cell_m, leach.dims)
    return CrackTextures(textures, tuple(float(v) for v in index.origin), index.cell_m,
                         index.dims, index.rough, index.footprint_m, contrast, leach_textures,
                         leach_grid)


class Renderer:
    """One GL context, its programs and targets; load a scene, then render cameras. A context
    manager: ``with Renderer(config) as r:`` releases the context on leaving; library callers
    that keep one longer call ``release()``."""

    def __init__(self, config: RenderConfig, platform: str | None = None) -> None:
        self.config = config
        self.ctx, self.platform = create_context(platform)
        most = self.ctx.max_samples
        if config.msaa > most:
            self.ctx.release()
            raise UserError(f"[render] msaa = {config.msaa}: this GL ({self.platform}) "
                            f"supports at most {most} samples; set msaa to {most} or less")
        try:
            check_render_size(self.ctx, self.platform, config.width, config.height,
                              config.msaa, config.shadow_map_px)
        except UserError:
            self.ctx.release()
            raise
        self.units = TextureUnits(self.ctx.default_texture_unit)
        self.programs = Programs(self.ctx, self.units, settings_constants(config))
        # The image-sized targets are made small first: what they take a pixel is then
        # measured, and the full size checked against the free memory before it is allocated.
        self.size = PROBE_SIZE
        self._draws: list[_Draw] = []
        # Uploaded textures by the ids of their source arrays (colour, alpha); the arrays are
        # kept with it so that no other array can take an id while the entry exists. A texture
        # whose sources are all read-only (the texture repository's images: they cannot change
        # under the cache) outlives its scene; the next load reuses it if its scene draws the
        # same arrays and frees it if not, as pyrender diffs its scene against the context.
        self._textures: dict[tuple[int, int], tuple[tuple[np.ndarray, np.ndarray | None],
                                                    moderngl.Texture]] = {}
        self._used: set[tuple[int, int]] = set()
        """Keys of the textures the loaded scene draws."""
        self._scene_textures: list[moderngl.Texture] = []
        """Textures of the loaded scene whose arrays were let go (see _detach)."""
        self._defaults = {
            "white": self._make_texture(np.full((1, 1, 3), 255, np.uint8)),
            "flat": self._make_texture(np.array([[[128, 128, 255]]], np.uint8)),
        }
        self._default_maps = {"base": self._defaults["white"],
                              "emissive": self._defaults["white"], "normal": self._defaults["flat"]}
        """What a colour draw binds where its part has no such map."""
        self.lighting: Lighting | None = None
        self._sky_maps: _SkyMaps | None = None
        self._radiance_scale = 1.0
        """The loaded scene's brightest emitted radiance: the sky maps' radiance is over it."""
        self._make_targets()
        # Fullscreen passes: one triangle from gl_VertexID, no vertex buffer.
        self._fullscreen_vaos = {name: self.ctx.vertex_array(self.programs.get(name), [])
                                 for name in ("sky", "ssao", "ssao_blur", "msaa_interior",
                                              "msaa_resolve")}
        try:
            self.resize(config.width, config.height)
        except UserError:
            self.release()
            raise

    def __enter__(self) -> "Renderer":
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.release()

    # --- targets, one builder per pass ------------------------------------------------------
    def _make_targets(self) -> None:
        self._make_sky_map_targets()
        self._make_shadow_targets()
        self._make_sized_targets()

    def _make_sized_targets(self) -> None:
        """The targets whose size is the image's."""
        # The colour pass tests against the label pass's depth: they share its depth buffer.
        label_depth = self.ctx.depth_renderbuffer(self.size)
        self._make_sky_visibility_targets()
        self._make_label_targets(label_depth)
        self._make_ao_targets()
        self._make_color_targets(label_depth)
        if self.config.msaa:
            self._make_msaa_targets()

    def _sized_framebuffers(self) -> list[moderngl.Framebuffer]:
        fbos = [self.sky_fbo, self.label_fbo, self.crack_fbo, self.label_crack_fbo,
                self.ao_raw_fbo, self.ao_fbo, self.color_fbo]
        return fbos + ([self.msaa_fbo, self.resolve_fbo] if self.config.msaa else [])

    def resize(self, width: int, height: int) -> None:
        """Render ``width`` x ``height`` images from now on, on the same context and with the
        loaded scene (an interactive viewer alternates a small size while the camera moves
        and the full one when it stops). The sky and shadow maps do not depend on it."""
        if (width, height) == self.size:
            return
        self.check_size(width, height)
        targets = self._sized_targets()
        for fbo in self._sized_framebuffers():
            fbo.release()
        for target in targets:
            target.release()
        self.size = (width, height)
        self._make_sized_targets()

    def _sized_targets(self) -> list[moderngl.Texture | moderngl.Renderbuffer]:
        """Every target whose size follows the image's, once each."""
        # The normal target is attached to no framebuffer without MSAA: named here, or each
        # size change would leave one behind (4 MB at 960x540).
        attachments: dict[int, moderngl.Texture | moderngl.Renderbuffer] = {
            id(self.normal_target): self.normal_target}
        for fbo in self._sized_framebuffers():
            for target in (*fbo.color_attachments, fbo.depth_attachment):
                if target is not None:
                    attachments[id(target)] = target
        return list(attachments.values())

    def check_size(self, width: int, height: int) -> None:
        """Refuse (UserError, before anything is allocated) an image size beyond this GL's
        limits, or whose targets would take more memory than the machine has free (what the
        targets take a pixel now, times the new size; what they take now is freed first)."""
        self.make_current()
        # The trial allocation is the constructor's alone: a viewer resizes on every stop.
        check_render_size(self.ctx, self.platform, width, height, self.config.msaa,
                          self.config.shadow_map_px, trial=False)
        held = sum(t.width * t.height * t.components * max(t.samples, 1)
                   * int(t.dtype[1:]) for t in self._sized_targets())  # "f2": 2 bytes
        need = held / (self.size[0] * self.size[1]) * width * height
        free = available_bytes()
        if free is not None and need > free + held:
            raise UserError(f"[render] {width}x{height}: its render targets take "
                            f"{need / 2**30:.1f} GiB, and {(free + held) / 2**30:.1f} GiB are "
                            "free; lower width and height, or msaa")

    def _nearest_texture(self, size: tuple[int, int], channels: int,
                         dtype: str = "f1") -> moderngl.Texture:
        """A render target read texel by texel."""
        target = self.ctx.texture(size, channels, dtype=dtype)
        target.filter = (moderngl.NEAREST, moderngl.NEAREST)
        return target

    def _depth_map(self, side: int) -> moderngl.Texture:
        """A square depth texture read through sampler2DShadow: the hardware compares (and
        filters 2x2 of) the results; lookups beyond its sides take its edge."""
        depth = self.ctx.depth_texture((side, side))
        depth.compare_func = "<="
        depth.filter = (moderngl.LINEAR, moderngl.LINEAR)
        depth.repeat_x = depth.repeat_y = False
        return depth

    def _make_sky_map_targets(self) -> None:
        """The baked sky-visibility maps: tiles x tiles maps of sky_visibility_px in one depth
        atlas and, beside each map's depth, the emitted radiance of the part it sees, over the
        scene's brightest (8 bits are plenty for the panels' low-contrast light)."""
        count = self.config.sky_visibility_maps
        self.vis_tiles = round(count ** 0.5)
        side = self.vis_tiles * self.config.sky_visibility_px if count else 1
        self.vis_map = self._depth_map(side)
        self.vis_radiance = self.ctx.texture((side, side), 4)
        self.vis_radiance.repeat_x = self.vis_radiance.repeat_y = False
        self.vis_fbo = self.ctx.framebuffer([self.vis_radiance], depth_attachment=self.vis_map)

    def _make_sky_visibility_targets(self) -> None:
        """Each camera's sky visibility at every second pixel in each direction: the light, the
        surface (normal, depth) and the mean openness (sky_visibility.frag)."""
        width, height = self.size
        half = ((width + 1) // 2, (height + 1) // 2) if self.config.sky_visibility_maps \
            else (1, 1)
        self.sky_targets = [self._nearest_texture(half, channels, "f4")
                            for channels in (4, 4, 1)]
        self.sky_fbo = self.ctx.framebuffer(self.sky_targets, self.ctx.depth_renderbuffer(half))

    def _make_shadow_targets(self) -> None:
        # Without shadows a 1x1 map stays bound, so the shadow sampler always has a depth texture.
        self.shadow_map = self._depth_map(self.config.shadow_map_px or 1)
        self.shadow_fbo = self.ctx.framebuffer(depth_attachment=self.shadow_map)

    def _make_label_targets(self, label_depth: moderngl.Renderbuffer) -> None:
        """The labels and, drawn only in views with cracks, the crack widths beside them."""
        self.label_target = self._nearest_texture(self.size, 4, "f4")
        self.label_fbo = self.ctx.framebuffer([self.label_target], label_depth)
        self.crack_target = self._nearest_texture(self.size, 2, "f4")
        """(crack width mm, coverage) per pixel: read back, and darkened by in colour."""
        self.crack_fbo = self.ctx.framebuffer([self.crack_target])
        self.label_crack_fbo = self.ctx.framebuffer([self.label_target, self.crack_target],
                                                    label_depth)
        self._view_has_cracks = False
        """Whether the last label pass drew cracks (read-back then reads their widths)."""
        self._deferred: tuple[Camera, list[_Placed]] | None = None
        """The camera and draws of a render(defer_colour=True) whose MSAA pass waits."""
        self._single: np.ndarray | None = None
        """Its single-sample colour, once read back."""

    def _make_ao_targets(self) -> None:
        self.ao_raw, self.ao = (self.ctx.texture(self.size, 1, dtype="f2") for _ in range(2))
        self.ao_raw_fbo = self.ctx.framebuffer([self.ao_raw])
        self.ao_fbo = self.ctx.framebuffer([self.ao])

    def _make_color_targets(self, label_depth: moderngl.Renderbuffer) -> None:
        """Colour, and under MSAA the shading normals the multisampled pass resolves by."""
        self.color_target = self._nearest_texture(self.size, 4)
        self.normal_target = self._nearest_texture(self.size, 4, "f2")
        self.color_fbo = self.ctx.framebuffer(
            [self.color_target, self.normal_target][:2 if self.config.msaa else 1], label_depth)

    def _make_msaa_targets(self) -> None:
        ctx, size, samples = self.ctx, self.size, self.config.msaa
        # Each sample's surface (normal and coverage, linear depth) for the resolve pass.
        self.sample_targets = [ctx.texture(size, 4, samples=samples, dtype="f2"),
                               ctx.texture(size, 1, samples=samples, dtype="f4")]
        self.msaa_fbo = ctx.framebuffer(self.sample_targets,
                                        ctx.depth_renderbuffer(size, samples=samples))
        # Its depth marks the pixels the full resolve weighs (msaa_interior.frag).
        self.resolve_fbo = ctx.framebuffer([ctx.renderbuffer(size, 4)],
                                           ctx.depth_renderbuffer(size))

    # --- scene ------------------------------------------------------------------------------
    def _make_texture(self, data: np.ndarray, *, integer: bool = False) -> moderngl.Texture:
        """A repeating texture of ``data`` (H, W[, C]) uint8, rows bottom to top: nearest and
        unsigned integer, or mipmapped and trilinear."""
        h, w = data.shape[:2]
        channels = 1 if data.ndim == 2 else data.shape[2]
        if integer:
            tex = self.ctx.texture((w, h), channels, data, dtype="u1", alignment=1)
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        else:
            tex = self.ctx.texture((w, h), channels, data, alignment=1)
            tex.build_mipmaps()
            tex.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        tex.repeat_x = tex.repeat_y = True
        return tex

    def _upload_texture(self, array: np.ndarray, *, integer: bool = False,
                        alpha: np.ndarray | None = None) -> moderngl.Texture:
        """A texture of image ``array`` (H, W[, C]) uint8, or of (H, W, 3) colour with
        ``alpha`` (H, W) in a fourth channel; uploaded once per source array."""
        key = (id(array), id(alpha))
        self._used.add(key)
        if key in self._textures:
            return self._textures[key][1]
        tex = self._make_texture(texture_data(array, alpha), integer=integer)
        self._textures[key] = ((array, alpha), tex)
        return tex

    def _detach(self, material: Material) -> None:
        """Let go of ``material``'s arrays: its textures stay with the scene, not the cache."""
        maps = {id(a) for a in (material.base_color_map, material.metallic_map,
                                material.emissive_map, material.normal_map,
                                material.damage_mask) if a is not None}
        for key in [k for k in self._textures if k[0] in maps or k[1] in maps]:
            self._scene_textures.append(self._textures.pop(key)[1])

    def _free_textures(self, keep: Callable[[tuple[int, int], tuple], bool]) -> None:
        """Release the cached textures for which ``keep(key, sources)`` is false."""
        for key, (sources, tex) in list(self._textures.items()):
            if not keep(key, sources):
                tex.release()
                del self._textures[key]

    def _base_texture(self, material: Material) -> moderngl.Texture | None:
        """Base colour in RGB and the metallic map in A: one texture, one lookup."""
        base, metal = material.base_color_map, material.metallic_map
        if metal is None:
            return None if base is None else self._upload_texture(base)
        if base is None:
            base = np.full(metal.shape + (3,), 255, np.uint8)
        return self._upload_texture(base, alpha=metal)

    def load(self, render_scene: RenderScene, lighting: Lighting,
             extent: np.ndarray | None = None,
             interrupt: Callable[[], bool] | None = None) -> None:
        """Upload the geometry and textures of every mesh node (replacing any earlier scene),
        lit by ``lighting``. The sky-visibility maps are fitted to the points ``extent`` (N, 3)
        (default: the uploaded meshes' boxes). ``interrupt()``, asked before each part: True
        frees what was uploaded and raises RenderInterrupted (a viewer stopping mid-upload)."""
        self.make_current()
        self.release_scene()
        self.lighting = lighting
        self._set_lighting(lighting)
        scene = render_scene.scene
        nodes = sorted(scene.mesh_nodes, key=lambda n: n.name)
        # Deferred materials are built here, the next one while this one uploads.
        built = built_in_order(render_scene.materials, [n.name for n in nodes])
        for node, material in zip(nodes, built, strict=True):
            if interrupt is not None and interrupt():
                built.close()  # its builder thread finishes the material it has begun
                self.release_scene()
                raise RenderInterrupted("the upload was interrupted")
            info = render_scene.parts[node.name]
            pose = scene.get_pose(node)
            for primitive in node.mesh.primitives:
                self._draws.append(self._upload_primitive(node.name, primitive, pose,
                                                          material, info))
            if material is not info.material:
                # Built for this upload: its maps go now, one column's at a time.
                self._detach(material)
        if any(d.cracks is not None for d in self._draws):
            # A view with cracks draws every part's labels through a crack variant.
            for draw in self._draws:
                key = draw.program("labels", True)
                draw.vaos[key] = self._vertex_array(key, draw.buffers[0], draw.buffers[1])
        # Kept textures of earlier scenes that this one does not draw.
        self._free_textures(lambda key, _: key in self._used)
        self._bake_sky_visibility(extent)

    def _upload_primitive(self, name: str, primitive: pyrender.Primitive, pose: np.ndarray,
                          material: Material, info: PartInfo) -> _Draw:
        """One mesh primitive's buffers, vertex arrays and textures (``info``: its part's
        RenderScene entry, whose material holds the factors)."""
        data = np.hstack([primitive.positions, primitive.normals,
                          primitive.texcoord_0]).astype(np.float32)
        vbo = self.ctx.buffer(data.tobytes())
        triangles = primitive.indices.astype(np.uint32).reshape(-1, 3)
        ibo = self.ctx.buffer(triangles.tobytes())
        # The colour pass draws the parts and their triangles in reverse order (see
        # _color_pass), each triangle's corners as they are.
        reversed_ibo = self.ctx.buffer(triangles[::-1].tobytes())
        vaos = self._vertex_arrays(vbo, ibo, reversed_ibo)
        textures = {slot: self._upload_texture(array) for slot, array in (
            ("emissive", material.emissive_map), ("normal", material.normal_map))
            if array is not None}
        zones = None
        if material.zones is not None:
            zones = zone_uniforms(material)
            textures |= self._zone_textures(material)
            vaos["labels", Variant.SPALL] = self._vertex_array(("labels", Variant.SPALL), vbo,
                                                               ibo)
        detail = None
        if material.detail_seed is not None:
            low, high = primitive.positions.min(0), primitive.positions.max(0)
            detail = DetailUniforms(material.detail_seed, tuple(float(v) for v in low),
                                    float(high[2] - low[2]), material.weathering_tint,
                                    material.ground_detail)
        if material.cracks is not None or zones is not None or detail is not None:
            key = ("color", Variant.of(material.cracks is not None, zones is not None,
                                       detail is not None, material.ground_detail))
            vaos[key] = self._vertex_array(key, vbo, reversed_ibo)
        base = self._base_texture(material)
        if base is not None:
            textures["base"] = base
        mask = (self._upload_texture(material.damage_mask, integer=True)
                if material.damage_mask is not None else None)
        box = np.array([primitive.positions.min(0), primitive.positions.max(0)])
        return _Draw(name=name, pose=pose, vaos=vaos, buffers=(vbo, ibo, reversed_ibo),
                     material=info.material, textures=textures,
                     component=float(info.component), damage_mask=mask,
                     center=pose[:3, :3] @ box.mean(0) + pose[:3, 3],
                     radiance=_emitted(material), corners=box_corners(box, pose),
                     cracks=material.cracks, zones=zones, detail=detail)

    def _zone_textures(self, material: Material) -> dict[str, moderngl.Texture]:
        """The zone variant's textures: the intact concrete (a repository image, cached like
        any map) and the share of each texel that is spalled or rebar, from the damage mask
        (the scene owns it)."""
        spalled = np.where(material.damage_mask >= Damage.CONCRETE, np.uint8(255), np.uint8(0))
        spall = self._make_texture(texture_data(spalled))
        self._scene_textures.append(spall)
        return {"intact": self._upload_texture(material.zones.intact_map), "spall": spall}


    def _vertex_array(self, program: ProgramKey, vbo: moderngl.Buffer,
                      indices: moderngl.Buffer) -> moderngl.VertexArray:
        """A primitive's vertex array for ``program``, reading the attributes it needs from
        the interleaved position, normal and uv."""
        layout, *names = _ATTRIBUTES[program[0]]
        return self.ctx.vertex_array(self.programs.get(*program), [(vbo, layout, *names)],
                                     indices, 4)

    def _vertex_arrays(self, vbo: moderngl.Buffer, ibo: moderngl.Buffer,
                       reversed_ibo: moderngl.Buffer) -> dict[ProgramKey, moderngl.VertexArray]:
        """One primitive's vertex array for each program that draws meshes, in its plain form
        (those of the passes that shade against a depth pre-pass with the triangles
        reversed)."""
        return {(name, Variant.NONE): self._vertex_array(
                    (name, Variant.NONE), vbo, reversed_ibo if name in _REVERSED else ibo)
                for name in _ATTRIBUTES}

    def make_current(self) -> None:
        """This renderer's context becomes the thread's current one: another Renderer in the
        process (created, or released, since) may have left its own current, and drawing into
        a context that is not current crashes the driver."""
        self.ctx.__enter__()

    def release_scene(self) -> None:
        """Free every GL object the loaded scene created (moderngl frees nothing that Python
        drops: its default gc_mode is None), except the textures of read-only arrays, which
        the next load reuses or frees."""
        self.make_current()
        for draw in self._draws:
            for vao in draw.vaos.values():
                vao.release()
            for buffer in draw.buffers:
                buffer.release()
            for texture in (draw.crack_textures.all if draw.crack_textures else ()):
                texture.release()
        self._free_textures(lambda _, sources: not any(
            a is not None and a.flags.writeable for a in sources))
        for tex in self._scene_textures:
            tex.release()
        self._scene_textures = []
        self._draws = []
        self._used = set()
        self._deferred = self._single = None

    def release(self) -> None:
        """Free the scene, the cached textures and the context (``with`` does it on leaving)."""
        self.release_scene()
        self._free_textures(lambda *_: False)
        for tex in self._defaults.values():
            tex.release()
        self.ctx.release()

    def relight(self, lighting: Lighting) -> None:
        """Light the loaded scene by ``lighting`` instead: the same images as loading it again
        under ``lighting``, without the upload (the sky maps' depth depends on no light; only
        their weights do)."""
        self.make_current()
        self.lighting = lighting
        self._set_lighting(lighting)
        if self._sky_maps is not None:
            self._sky_maps = replace(self._sky_maps,
                                     weights=self._sky_weights(self._sky_maps.directions))

    def _sky_weights(self, directions: np.ndarray) -> np.ndarray:
        return np.maximum(self.lighting.sky_radiance(directions) @ LUMINANCE, 1e-6)

    def _set_lighting(self, lighting: Lighting) -> None:
        """The uniforms that stay the same for every camera of an environment: all of them
        from ``lighting`` (the SH ambient light, the sky, the sun's strength, the exposure)."""
        sky = self.programs.get("sky")
        gains = tuple(lighting.exposure * w for w in lighting.white_balance)
        sky["u_exposure"].value = gains
        sky_sh, ground_sh = lighting.irradiance_sh()
        for _, color in self.programs.variants("color"):
            color["u_exposure"].value = gains
            color["u_sun_color"].value = (lighting.sun_irradiance,) * 3
            color["u_sh_sky"].write(sky_sh.astype("f4").tobytes())
            color["u_sh_ground"].write(ground_sh.astype("f4").tobytes())
        sky["u_sky_model"].value = 0 if lighting.sky == "preetham" else 1
        sky["u_sky_strength"].value = lighting.sky_strength
        sky["u_sky_uniform"].value = tuple(lighting.sky_strength * np.array(lighting.sky_rgb))
        model = lighting.preetham()
        sky["u_sky_zenith"].value = tuple(model.zenith)
        sky["u_sky_perez"].write(model.perez.astype("f4").tobytes())
        sky["u_sky_sun"].value = tuple(lighting.sky_sun_direction)

    def _bake_sky_visibility(self, extent: np.ndarray | None) -> None:
        """Depth maps of the whole loaded scene seen from sky directions, once per scene."""
        self._sky_maps = None
        if not self.vis_tiles or not self._draws:
            return
        px = self.config.sky_visibility_px
        directions = sky_directions(self.vis_tiles ** 2)
        corners = extent if extent is not None else np.concatenate(
            [d.corners for d in self._draws])
        matrices = occlusion_matrices(corners, directions)
        self._radiance_scale = max(1e-6, max(float(d.radiance.max()) for d in self._draws))
        self.vis_fbo.use()
        self.vis_fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        with _depth_state(self.ctx, offset=True):
            for k, light in enumerate(matrices):
                tx, ty = k % self.vis_tiles, k // self.vis_tiles
                self.vis_fbo.viewport = (tx * px, ty * px, px, px)
                self._draw_depth(light, self._draws)
        self.vis_fbo.viewport = (0, 0, *self.vis_map.size)
        self._sky_maps = _SkyMaps(
            atlas_from_world=_atlas_from_clip(matrices, self.vis_tiles), directions=directions,
            weights=self._sky_weights(directions),
            texel_m=max(shadow_texel_m(m, px) for m in matrices))

    # --- one view ---------------------------------------------------------------------------
    def render(self, camera: Camera, passes: frozenset[str] | set[str] = PASSES,
               interrupt: Callable[[], bool] | None = None, bands: int = 1,
               defer_colour: bool = False) -> RenderOutput:
        """``passes`` of ``camera``. The passes run in this order, each into its own targets:
        sky visibility, shadow, labels, ambient occlusion, colour, MSAA, read-back (the module
        docstring says what each draws, and when it is skipped).

        With ``interrupt``, the GL work is finished after each pass and after each of the
        colour pass's ``bands`` bands of rows, and RenderInterrupted is raised as soon as
        ``interrupt()`` is true there (the work already queued cannot be stopped, so a band is
        the longest wait); the image is the same bytes however it is cut.

        ``defer_colour``: stop after the colour pass, before MSAA, and read back no colour;
        deferred_colour() then reads it, resolved or not (a caller that may drop the view on
        the single-sample colour spares the MSAA pass)."""
        self._check_request(camera, passes)
        self.make_current()
        draws = self._front_to_back(camera)
        placed = self._place(camera, draws)
        self._deferred = self._single = None
        self.prepare_cracks([item.draw for item in placed])
        check = self._checkpoint(interrupt)
        color = "color" in passes
        ao = color and self.config.ao == "ssao"
        shadow = None
        if color:
            self._sky_visibility_pass(camera, placed)
            check()
            shadow = self._shadow_pass(camera, draws)  # parts out of view cast shadows too
        self._label_pass(camera, placed)  # the colour pass tests against its depth
        check()
        if ao:
            self._ao_pass(camera)
        if color:
            self._color_pass(camera, placed, shadow, ao, bands, check)
            if defer_colour:
                self._deferred = (camera, placed)
                return self._read_back(passes - {"color"})
            if self.config.msaa:
                self._msaa_pass(camera, placed)
                check()
        return self._read_back(passes)

    def deferred_colour(self, resolved: bool = True) -> np.ndarray:
        """(H, W, 3) uint8: the colour of the view the last render(defer_colour=True) drew.
        ``resolved``: as render gives it (the MSAA pass runs now, once); otherwise the
        single-sample colour pass's, from which msaa_resolve.frag takes each sample's colour
        (a pixel's own or one of its four neighbours'). Without MSAA both are the same
        array, read back once."""
        if self._deferred is None:
            raise ValueError("no deferred colour: call render(camera, defer_colour=True) first")
        self.make_current()
        if not (resolved and self.config.msaa):
            if self._single is None:
                self._single = self._read_colour(self.color_fbo)
            return self._single
        self._msaa_pass(*self._deferred)
        # The colour pass's targets now hold the resolve's inputs only.
        self._deferred = self._single = None
        return self._read_colour(self.resolve_fbo)

    def _checkpoint(self, interrupt: Callable[[], bool] | None) -> Callable[[], None]:
        """What render calls between pieces of work: nothing without ``interrupt``; with it,
        wait for the GL work so far, then raise RenderInterrupted if ``interrupt()``."""
        def check() -> None:
            if interrupt is not None:
                self.ctx.finish()
                if interrupt():
                    raise RenderInterrupted("the render was interrupted")
        return check

    def prepare_cracks(self, draws: list[_Draw] | None = None, limit: int | None = None
                       ) -> int:
        """Pack and upload the cracks of ``draws`` (default: the loaded scene's), at most
        ``limit`` parts' of them, that are not uploaded yet; the number of the scene's parts
        still waiting after. A view does it for the parts it shows; an interactive caller
        calls it in idle time, so that a part's first view does not wait for it."""
        waiting = [d for d in (self._draws if draws is None else draws)
                   if d.cracks is not None and d.crack_textures is None]
        if waiting[:limit]:
            self.make_current()
        for draw in waiting[:limit]:
            index = pack_cracks(draw.cracks)
            draw.crack_textures = upload_cracks(self.ctx, index, crack_contrast(draw.cracks),
                                                pack_leachate(draw.cracks, index.origin))
        return sum(d.cracks is not None and d.crack_textures is None for d in self._draws)

    def _check_request(self, camera: Camera, passes: frozenset[str] | set[str]) -> None:
        unknown = set(passes) - PASSES
        if unknown:
            raise ValueError(f"passes {sorted(unknown)}: choose from {sorted(PASSES)}")
        if (camera.width, camera.height) != self.size:
            raise ValueError(f"camera size {camera.width}x{camera.height} differs from the "
                             f"renderer's {self.size[0]}x{self.size[1]}: make the camera with "
                             "the same [render] width and height")
        if self.lighting is None:
            raise ValueError("no scene loaded: call load(scene, lighting) first")

    def _front_to_back(self, camera: Camera) -> list[_Draw]:
        """Nearest parts first: llvmpipe's early depth test then skips hidden fragments."""
        eye = camera.pose[:3, 3]
        return sorted(self._draws, key=lambda d: float(np.sum((d.center - eye) ** 2)))

    @staticmethod
    def _place(camera: Camera, draws: list[_Draw]) -> list[_Placed]:
        """The draws whose boxes may be in the camera's view, with their matrices: parts wholly
        outside it make no fragment."""
        view = camera.view()
        seen = seen_by(np.stack([d.corners for d in draws]), camera) if draws else []
        placed = []
        for draw in (d for d, s in zip(draws, seen, strict=True) if s):
            modelview = view @ draw.pose  # float64, then float32 for GL
            normal = np.linalg.inv(modelview[:3, :3]).T
            placed.append(_Placed(draw, _gl_matrix(modelview), _gl_matrix(normal)))
        return placed

    def _fullscreen(self, program: str) -> None:
        self._fullscreen_vaos[program].render(moderngl.TRIANGLES, vertices=3)

    @staticmethod
    def _intrinsics(camera: Camera) -> tuple[float, float, float, float]:
        k = camera.K
        return (float(k[0, 0]), float(k[1, 1]), float(k[0, 2]), float(k[1, 2]))

    def _draw_depth(self, light: np.ndarray, draws: list[_Draw]) -> None:
        """Depth of ``draws`` through the clip-from-world matrix ``light`` into the bound
        framebuffer (sun shadows, sky visibility)."""
        prog = self.programs.get("shadow")
        # Parts wholly beyond the map's sides make no fragment.
        inside = in_clip_xy(np.stack([d.corners for d in draws]), light) if draws else []
        for draw in (d for d, keep in zip(draws, inside, strict=True) if keep):
            prog["u_light_mvp"].write(_gl_matrix(light @ draw.pose))
            prog["u_radiance"].value = tuple(draw.radiance / self._radiance_scale)
            draw.vaos["shadow", Variant.NONE].render()

    def _draw_surfaces(self, program: str, camera: Camera, placed: list[_Placed]) -> None:
        """``placed`` through ``program`` (mesh.vert, positions and normals) from ``camera``,
        into the bound framebuffer, with no per-part uniforms beyond the matrices."""
        prog = self.programs.get(program)
        prog["u_projection"].write(_gl_matrix(camera.projection()))
        for item in placed:
            prog["u_modelview"].write(item.modelview)
            prog["u_normal_matrix"].write(item.normal)
            item.draw.vaos[program, Variant.NONE].render()

    # --- the passes, in render's order ------------------------------------------------------
    def _sky_visibility_pass(self, camera: Camera, placed: list[_Placed]) -> None:
        """The sky visibility of the surfaces seen at every second pixel (sky_targets): their
        depth first, then the shading of only the nearest surface at each pixel."""
        if self._sky_maps is None:
            return
        self.sky_fbo.use()
        self.sky_fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        self._sky_depth(camera, placed)
        self._set_sky_uniforms(camera)
        # Against the depth just drawn, unchanged, as in the colour pass: each pixel is shaded
        # once, and drawn in reverse order the surface kept where depths tie is the first
        # drawn, the one a single front-to-back pass with "<" keeps: the same bytes as that
        # pass, for less work (docs/results.md, "Dataset generation").
        with _depth_state(self.ctx, depth_func="<="):
            self._draw_surfaces("sky_visibility", camera, placed[::-1])

    def _sky_depth(self, camera: Camera, placed: list[_Placed]) -> None:
        """The depth of ``placed`` into the bound sky framebuffer, nothing else: llvmpipe's
        early depth test then skips every hidden block of the costly sky shader. mesh.vert's
        invariant position gives the sky program the same depths to the bit."""
        self.sky_fbo.color_mask = _NO_COLOUR * len(self.sky_targets)
        try:
            with _depth_state(self.ctx):
                self._draw_surfaces("msaa", camera, placed)  # the cheapest mesh.vert program
        finally:
            self.sky_fbo.color_mask = _ALL_COLOUR * len(self.sky_targets)

    def _set_sky_uniforms(self, camera: Camera) -> None:
        """The sky-visibility program's maps and uniforms for ``camera``."""
        maps = self._sky_maps
        prog = self.programs.get("sky_visibility")
        self.units.bind("u_vis_map", self.vis_map)
        self.units.bind("u_vis_radiance", self.vis_radiance)
        count = len(maps.directions)
        pad = MAX_VIS - count  # the shader's arrays hold MAX_VIS
        prog["u_vis_count"].value = count
        prog["u_vis_from_view"].write(_gl_matrix(np.concatenate(
            [maps.atlas_from_world @ camera.pose, np.zeros((pad, 4, 4))])))
        prog["u_vis_dir"].write(np.concatenate(
            [maps.directions @ camera.view()[:3, :3].T, np.zeros((pad, 3))]).astype("f4")
            .tobytes())
        prog["u_vis_weight"].write(np.concatenate([maps.weights, np.zeros(pad)]).astype("f4")
                                   .tobytes())
        # 1.5 texels along the normal, as for the sun's map.
        prog["u_vis_offset_m"].value = 1.5 * maps.texel_m
        prog["u_vis_solid_angle"].value = sky_solid_angle(count) * self._radiance_scale

    def _shadow_pass(self, camera: Camera, draws: list[_Draw]) -> np.ndarray | None:
        """Draw the sun's depth; return the shadow map's clip-from-world matrix (None: no
        shadows for this view)."""
        if not self.config.shadow_map_px or not draws or not self.lighting.sun_irradiance:
            return None
        light = shadow_matrix(camera, self.config, self.lighting.sun_direction)
        self.shadow_fbo.use()
        self.shadow_fbo.clear(depth=1.0)
        # Depth clamping keeps casters on the sun side of the map's range
        # (glsynth.world.sunlight).
        with _depth_state(self.ctx, offset=True, clamp=True):
            self._draw_depth(light, draws)
        return light

    def _label_pass(self, camera: Camera, placed: list[_Placed]) -> None:
        """Labels into label_target; in a view with cracks, every part through the crack
        variant, which also writes crack_target (a part without cracks writes 0)."""
        cracked = any(item.draw.cracks is not None for item in placed)
        self._view_has_cracks = cracked
        names = {item.draw.program("labels", cracked) for item in placed}
        self.label_fbo.use()
        self.label_fbo.clear(float(Component.NONBRIDGE), float(Damage.NO_DAMAGE),
                             camera.zfar, 0.0)
        if cracked:
            self.crack_fbo.clear(0.0, 0.0)
            self.label_crack_fbo.use()
        for prog in (self.programs.get(*key) for key in names):
            prog["u_projection"].write(_gl_matrix(camera.projection()))
        with _depth_state(self.ctx):
            for item in placed:
                draw = item.draw
                key = draw.program("labels", cracked)
                prog = self.programs.get(*key)
                prog["u_modelview"].write(item.modelview)
                prog["u_component"].value = draw.component
                prog["u_has_damage_mask"].value = draw.damage_mask is not None
                if draw.damage_mask is not None:
                    self.units.bind("u_damage_mask", draw.damage_mask)
                if cracked:
                    prog["u_has_cracks"].value = draw.cracks is not None
                    if draw.cracks is not None:
                        draw.crack_textures.bind(prog, self.units)
                if draw.zones is not None:
                    draw.zones.set(prog)
                draw.vaos[key].render()

    def _ao_pass(self, camera: Camera) -> None:
        """Occlusion from the label texture (drawn for this camera) into self.ao."""
        cfg, prog = self.config, self.programs.get("ssao")
        self.ctx.disable(moderngl.DEPTH_TEST)
        self.ao_raw_fbo.use()
        self.units.bind("u_labels", self.label_target)
        prog["u_intrinsics"].value = self._intrinsics(camera)
        prog["u_size"].value = (float(self.size[0]), float(self.size[1]))
        prog["u_radius"].value = cfg.ao_radius_m
        prog["u_samples"].value = cfg.ao_samples
        self._fullscreen("ssao")
        self.ao_fbo.use()
        self.units.bind("u_raw", self.ao_raw)
        self._fullscreen("ssao_blur")

    def _color_pass(self, camera: Camera, placed: list[_Placed], shadow: np.ndarray | None,
                    ao: bool, bands: int = 1, check: Callable[[], None] = lambda: None) -> None:
        """Colour of ``placed`` into color_target (and their shading normals into
        normal_target), then the sky where no part was drawn; in ``bands`` bands of rows
        (scissored: a pixel's colour does not depend on the others'), ``check()`` after
        each."""
        self._set_view_uniforms(camera, placed, shadow, ao)
        # Against the label pass's depth, unchanged: only the nearest surface passes "<=", so
        # each pixel is shaded once. Parts and triangles are drawn in reverse order, so that
        # where they tie in depth the last written is the first drawn, which the labels keep:
        # colour shows the very surface that the labels name.
        self.color_fbo.use()
        self.color_fbo.depth_mask = False
        self.color_fbo.clear(0.0, 0.0, 0.0, 1.0)
        edges = np.linspace(0, self.size[1], bands + 1).round().astype(int)
        try:
            for y0, y1 in zip(edges[:-1], edges[1:], strict=True):
                if bands > 1:
                    self.color_fbo.scissor = (0, int(y0), self.size[0], int(y1 - y0))
                self._draw_colors(camera, placed)
                check()
        finally:
            if bands > 1:
                self.color_fbo.scissor = None
            self.color_fbo.depth_mask = True

    def _draw_colors(self, camera: Camera, placed: list[_Placed]) -> None:
        """``placed`` and the sky into the bound colour framebuffer (_color_pass)."""
        with _depth_state(self.ctx, depth_func="<="):
            for item in reversed(placed):
                draw, mat = item.draw, item.draw.material
                key = draw.program("color", self._view_has_cracks)
                prog = self.programs.get(*key)
                prog["u_modelview"].write(item.modelview)
                prog["u_normal_matrix"].write(item.normal)
                prog["u_base_color"].value = tuple(float(c) for c in mat.base_color)
                prog["u_metallic"].value = float(mat.metallic)
                prog["u_roughness"].value = float(mat.roughness)
                prog["u_emissive"].value = tuple(float(c) for c in mat.emissive)
                prog["u_has_normal_map"].value = "normal" in draw.textures
                for slot, texture in (self._default_maps | draw.textures).items():
                    self.units.bind(_MATERIAL_SAMPLERS[slot], texture)
                if draw.zones is not None:
                    draw.zones.set(prog)
                    prog["u_intact_uv_ratio"].value = draw.zones.intact_uv_ratio
                if draw.detail is not None:
                    draw.detail.set(prog)
                if Variant.CRACKS in key[1]:
                    draw.crack_textures.bind_colour(prog, self.units)
                draw.vaos[key].render()
            self._draw_sky(camera)

    def _set_view_uniforms(self, camera: Camera, placed: list[_Placed],
                           shadow: np.ndarray | None, ao: bool) -> None:
        """The colour programs' inputs for one view (the targets of the passes before them:
        shadow map, ambient occlusion, sky visibility; the label pass's crack coverage) and
        their uniforms, in every variant the view's parts draw by."""
        inputs = {"u_shadow_map": self.shadow_map, "u_ao": self.ao,
                  **dict(zip(("u_sky_light", "u_sky_surface", "u_sky_open"), self.sky_targets,
                             strict=True))}
        if self._view_has_cracks:
            inputs["u_crack"] = self.crack_target
        for sampler, texture in inputs.items():
            self.units.bind(sampler, texture)
        keys = {("color", Variant.NONE)} | {item.draw.program("color", self._view_has_cracks)
                                            for item in placed}
        for key in keys:
            self._set_color_view_uniforms(self.programs.get(*key), camera, shadow, ao)

    def _set_color_view_uniforms(self, prog: moderngl.Program, camera: Camera,
                                 shadow: np.ndarray | None, ao: bool) -> None:
        """One colour program's uniforms for one view: the camera, the sun, which of the
        inputs that _set_view_uniforms binds it reads."""
        prog["u_projection"].write(_gl_matrix(camera.projection()))
        prog["u_sun_dir"].value = tuple(camera.view()[:3, :3] @ self.lighting.sun_direction)
        prog["u_world_from_view"].write(_gl_matrix(camera.pose[:3, :3]))
        prog["u_has_shadows"].value = shadow is not None
        prog["u_has_ao"].value = ao
        prog["u_vis_count"].value = 0 if self._sky_maps is None else len(
            self._sky_maps.directions)
        if shadow is not None:
            px = self.config.shadow_map_px
            prog["u_shadow_from_view"].write(_gl_matrix(_CLIP_TO_TEXTURE @ shadow @ camera.pose))
            prog["u_shadow_texel"].value = 1.0 / px
            # 1.5 texels along the normal lifts the lookup clear of the surface's own texels.
            prog["u_shadow_offset_m"].value = 1.5 * shadow_texel_m(shadow, px)

    def _draw_sky(self, camera: Camera) -> None:
        """The sky where the colour pass drew nothing (depth still at the far plane)."""
        prog = self.programs.get("sky")
        prog["u_intrinsics"].value = self._intrinsics(camera)
        prog["u_height"].value = float(self.size[1])
        prog["u_world_from_view"].write(_gl_matrix(camera.pose[:3, :3]))
        self._fullscreen("sky")

    def _msaa_pass(self, camera: Camera, placed: list[_Placed]) -> None:
        """Draw each sample's surface, then resolve the multisampled colour from the
        single-sample colour pass's pixels into resolve_fbo."""
        self.msaa_fbo.use()
        self.msaa_fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        with _depth_state(self.ctx):
            self._draw_surfaces("msaa", camera, placed)
        self.resolve_fbo.use()
        self.resolve_fbo.clear(depth=1.0)
        inputs = (("u_sample_surface", self.sample_targets[0]),
                  ("u_sample_depth", self.sample_targets[1]), ("u_labels", self.label_target),
                  ("u_normals", self.normal_target), ("u_shaded", self.color_target))
        for name, texture in inputs:
            self.units.bind(name, texture)
        with _depth_state(self.ctx, depth_func="1"):  # every pixel writes its mark
            for step in ("msaa_interior", "msaa_resolve"):
                self._fullscreen(step)
                self.ctx.depth_func = "<="  # the full resolve where the mark is 1

    def _read_back(self, passes: frozenset[str] | set[str]) -> RenderOutput:
        """The passes asked for, as arrays with image rows top to bottom."""
        width, height = self.size
        out: dict[str, np.ndarray] = {}
        if passes & LABEL_PASSES:
            raw = self.label_fbo.read(components=4, dtype="f4")
            labels = np.frombuffer(raw, np.float32).reshape(height, width, 4)[::-1]
            if "component" in passes:
                out["component"] = labels[..., 0].astype(np.uint8)
            if "damage" in passes:
                out["damage"] = labels[..., 1].astype(np.uint8)
            if "depth" in passes:
                out["depth"] = np.ascontiguousarray(labels[..., 2])
        if "damage" in passes:
            out["crack_width"] = self._read_crack_width()
        if "color" in passes:
            out["color"] = self._read_colour(self.resolve_fbo if self.config.msaa
                                             else self.color_fbo)
        return RenderOutput(**out)

    def _read_colour(self, fbo: moderngl.Framebuffer) -> np.ndarray:
        """(H, W, 3) uint8 of ``fbo``'s first attachment, rows top to bottom."""
        width, height = self.size
        raw = fbo.read(components=3, alignment=1)
        return np.ascontiguousarray(np.frombuffer(raw, np.uint8).reshape(height, width, 3)[::-1])

    def _read_crack_width(self) -> np.ndarray:
        """(H, W) float32 mm, rows top to bottom: the label pass's crack widths, or zeros in a
        view without cracks."""
        width, height = self.size
        if not self._view_has_cracks:
            return np.zeros((height, width), np.float32)
        raw = self.crack_fbo.read(components=2, dtype="f4")
        return np.ascontiguousarray(
            np.frombuffer(raw, np.float32).reshape(height, width, 2)[::-1, :, 0])
