"""Offscreen renderer: draws a glsynth RenderScene (a pyrender Scene) with glsynth's programs.

Passes:
- shadow (before colour, when [render] shadow_map_px > 0): depth from the sun into a depth
  texture fitted to this camera's view (glsynth.world.sunlight);
- labels: one draw per part into one RGBA32F texture holding (component id, damage id, linear
  depth, hit), single-sampled; the ids are then exact and depth is float32 along the optical axis;
- ambient occlusion (before colour, when [render] ao = "ssao"): from the label texture's depth,
  then a 4x4 blur, into a one-channel texture the colour pass reads per pixel;
- sky visibility (before colour, when the scene has sky-visibility maps): the 16 sky-map
  lookups at every second pixel in each direction, into half-size targets the colour pass
  upsamples within each surface (shaders/sky_visibility.frag);
- colour: PBR into an RGBA8 texture, lit by the environment's Lighting
  (glsynth.world.lighting), tested against the label pass's depth so that each pixel is shaded
  once; the sky is drawn last, where no geometry was;
- multisampled colour (when msaa > 0): the geometry again into multisampled targets that keep
  each sample's surface (shaders/msaa.frag); a fullscreen pass gives a pixel whose samples all
  lie on its centre's surface that centre's colour (shaders/msaa_interior.frag), and a second,
  only at the other pixels, gives each sample the colour shaded at a pixel centre on its own
  surface and the pixel the mean of its samples (shaders/msaa_resolve.frag).
Only the passes asked for (and those they need) are drawn, and each draws only the parts whose
boxes may be in its frustum (the camera's; the sun's shadow map and the sky-visibility maps,
in x and y), which changes no byte. Pixels with no geometry read component 1 (Nonbridge),
damage 1 (no damage) and depth = zfar.
"""

from collections.abc import Callable
from dataclasses import dataclass

import cv2
import moderngl
import numpy as np

from glsynth.appearance.materials import Material, built_in_order, srgb_decode
from glsynth.core.config import RenderConfig
from glsynth.core.errors import UserError
from glsynth.core.labels import Component, Damage
from glsynth.render.gl.context import create_context
from glsynth.render.gl.programs import compile_programs
from glsynth.render.scene import RenderScene
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

PASSES = frozenset({"color", "component", "damage", "depth"})
_LABEL_PASSES = frozenset({"component", "damage", "depth"})
_GL_DEPTH_CLAMP = 0x864F  # core since GL 3.2; moderngl has no flag for it
_MAX_VIS = 16  # the length of the sky-visibility arrays in sky_visibility.frag
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


@dataclass
class _Draw:
    name: str
    pose: np.ndarray
    vaos: dict[str, moderngl.VertexArray]
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


@dataclass(frozen=True)
class _Placed:
    """A draw that the camera may see, with its matrices for that camera (float32 bytes),
    computed once for every pass of the view."""
    draw: _Draw
    modelview: bytes
    normal: bytes


def texture_data(array: np.ndarray, alpha: np.ndarray | None = None) -> np.ndarray:
    """The bytes to upload for image ``array`` (H, W[, C]) uint8, with ``alpha`` (H, W) as a
    fourth channel if given. Image rows run top to bottom and GL's t bottom to top: the rows
    are flipped so that uv (0, 0) is the image's bottom-left corner, as glTF and Blender
    define it. OpenCV's flip and channel copies: 4x faster than numpy's strided ones at
    2048 px (6 against 24 ms for colour plus alpha), the same bytes."""
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


class Renderer:
    """One GL context, its programs and framebuffers; load a scene, then render cameras."""

    def __init__(self, config: RenderConfig, platform: str | None = None) -> None:
        self.config = config
        self.ctx, self.platform = create_context(platform)
        self.programs = compile_programs(self.ctx)
        self.size = (config.width, config.height)
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
        self.lighting: Lighting | None = None
        self._make_framebuffers()
        # Fullscreen passes: one triangle from gl_VertexID, no vertex buffer.
        self._fullscreen_vaos = {name: self.ctx.vertex_array(self.programs[name], [])
                                 for name in ("sky", "ssao", "ssao_blur", "msaa_interior",
                                              "msaa_resolve")}

    # --- resources --------------------------------------------------------------------------
    def _make_framebuffers(self) -> None:
        ctx, size, samples = self.ctx, self.size, self.config.msaa
        if samples > ctx.max_samples:
            raise UserError(f"[render] msaa = {samples}: this GL ({self.platform}) supports at "
                             f"most {ctx.max_samples} samples; set msaa to {ctx.max_samples} "
                             "or less")
        # The colour pass tests against the label pass's depth: they share its depth buffer.
        # Under MSAA it also keeps its shading normals for the multisampled pass.
        label_depth = ctx.depth_renderbuffer(size)
        self.color_target = ctx.texture(size, 4)
        self.normal_target = ctx.texture(size, 4, dtype="f2")
        for target in (self.color_target, self.normal_target):
            target.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.color_fbo = ctx.framebuffer(
            [self.color_target, self.normal_target][:2 if samples else 1], label_depth)
        if samples:
            # Each sample's surface (normal and coverage, linear depth) for the resolve pass.
            self.sample_targets = [ctx.texture(size, 4, samples=samples, dtype="f2"),
                                   ctx.texture(size, 1, samples=samples, dtype="f4")]
            self.msaa_fbo = ctx.framebuffer(self.sample_targets,
                                            ctx.depth_renderbuffer(size, samples=samples))
            # Its depth marks the pixels the full resolve weighs (msaa_interior.frag).
            self.resolve_fbo = ctx.framebuffer([ctx.renderbuffer(size, 4)],
                                               ctx.depth_renderbuffer(size))
        self.label_target = ctx.texture(size, 4, dtype="f4")
        self.label_target.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.label_fbo = ctx.framebuffer([self.label_target], label_depth)
        self.ao_raw, self.ao = (ctx.texture(size, 1, dtype="f2") for _ in range(2))
        self.ao_raw_fbo = ctx.framebuffer([self.ao_raw])
        self.ao_fbo = ctx.framebuffer([self.ao])
        # Without shadows a 1x1 map stays bound, so the shadow sampler always has a depth texture.
        side = self.config.shadow_map_px or 1
        self.shadow_map = ctx.depth_texture((side, side))
        self.shadow_map.compare_func = "<="  # sampler2DShadow: the hardware compares (and
        self.shadow_map.filter = (moderngl.LINEAR, moderngl.LINEAR)  # filters 2x2 of) results
        self.shadow_map.repeat_x = self.shadow_map.repeat_y = False
        self.shadow_fbo = ctx.framebuffer(depth_attachment=self.shadow_map)
        # Sky-visibility maps: tiles x tiles maps of sky_visibility_px in one depth atlas.
        count = self.config.sky_visibility_maps
        self.vis_tiles = round(count ** 0.5)
        side = self.vis_tiles * self.config.sky_visibility_px if count else 1
        self.vis_map = ctx.depth_texture((side, side))
        self.vis_map.compare_func = "<="
        self.vis_map.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.vis_map.repeat_x = self.vis_map.repeat_y = False
        # Beside each map's depth, the emitted radiance of the part it sees, over the
        # scene's brightest (8 bits are plenty for the panels' low-contrast light).
        self.vis_radiance = ctx.texture((side, side), 4)
        self.vis_radiance.repeat_x = self.vis_radiance.repeat_y = False
        self.vis_fbo = ctx.framebuffer([self.vis_radiance], depth_attachment=self.vis_map)
        # Each camera's sky visibility at every second pixel in each direction: the light, the
        # surface (normal, depth) and the mean openness (sky_visibility.frag).
        half = ((size[0] + 1) // 2, (size[1] + 1) // 2) if count else (1, 1)
        self.sky_targets = [ctx.texture(half, channels, dtype="f4") for channels in (4, 4, 1)]
        for target in self.sky_targets:
            target.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.sky_fbo = ctx.framebuffer(self.sky_targets, ctx.depth_renderbuffer(half))
        self._radiance_scale = 1.0
        self._vis: tuple[np.ndarray, np.ndarray, np.ndarray, float] | None = None

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
             extent: np.ndarray | None = None) -> None:
        """Upload the geometry and textures of every mesh node (replacing any earlier scene),
        lit by ``lighting``. The sky-visibility maps are fitted to the points ``extent`` (N, 3)
        (default: the uploaded meshes' boxes)."""
        self.make_current()
        self.release_scene()
        self.lighting = lighting
        self._set_lighting(lighting)
        scene = render_scene.scene
        nodes = sorted(scene.mesh_nodes, key=lambda n: n.name)
        # Deferred materials are built here, the next one while this one uploads.
        built = built_in_order(render_scene.materials, [n.name for n in nodes])
        for node, mat in zip(nodes, built, strict=True):
            info = render_scene.parts[node.name]
            for primitive in node.mesh.primitives:
                data = np.hstack([primitive.positions, primitive.normals,
                                  primitive.texcoord_0]).astype(np.float32)
                vbo = self.ctx.buffer(data.tobytes())
                triangles = primitive.indices.astype(np.uint32).reshape(-1, 3)
                ibo = self.ctx.buffer(triangles.tobytes())
                # The colour pass draws the parts and their triangles in reverse order (see
                # _color_pass), each triangle's corners as they are.
                reversed_ibo = self.ctx.buffer(triangles[::-1].tobytes())
                vaos = {
                    "color": self.ctx.vertex_array(
                        self.programs["color"],
                        [(vbo, "3f 3f 2f", "in_position", "in_normal", "in_uv")],
                        reversed_ibo, 4),
                    "labels": self.ctx.vertex_array(
                        self.programs["labels"],
                        [(vbo, "3f 12x 2f", "in_position", "in_uv")], ibo, 4),
                    "shadow": self.ctx.vertex_array(
                        self.programs["shadow"], [(vbo, "3f 20x", "in_position")], ibo, 4),
                    **{name: self.ctx.vertex_array(
                        self.programs[name],
                        [(vbo, "3f 3f 8x", "in_position", "in_normal")], ibo, 4)
                       for name in ("msaa", "sky_visibility")},
                }
                textures = {slot: self._upload_texture(array) for slot, array in (
                    ("emissive", mat.emissive_map), ("normal", mat.normal_map))
                    if array is not None}
                base = self._base_texture(mat)
                if base is not None:
                    textures["base"] = base
                mask = (self._upload_texture(mat.damage_mask, integer=True)
                        if mat.damage_mask is not None else None)
                pose = scene.get_pose(node)
                box = np.array([primitive.positions.min(0), primitive.positions.max(0)])
                center = pose[:3, :3] @ box.mean(0) + pose[:3, 3]
                self._draws.append(_Draw(node.name, pose, vaos, (vbo, ibo, reversed_ibo),
                                         info.material,
                                         textures, float(info.component), mask, center,
                                         _emitted(mat), box_corners(box, pose)))
            if mat is not info.material:
                # Built for this upload: its maps go now, one column's at a time.
                self._detach(mat)
        # Kept textures of earlier scenes that this one does not draw.
        self._free_textures(lambda key, _: key in self._used)
        self._bake_sky_visibility(extent)

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
        self._free_textures(lambda _, sources: not any(
            a is not None and a.flags.writeable for a in sources))
        for tex in self._scene_textures:
            tex.release()
        self._scene_textures = []
        self._draws = []
        self._used = set()

    def release(self) -> None:
        self.release_scene()
        self._free_textures(lambda *_: False)
        for tex in self._defaults.values():
            tex.release()
        self.ctx.release()

    # --- drawing ----------------------------------------------------------------------------
    def _bake_sky_visibility(self, extent: np.ndarray | None) -> None:
        """Depth maps of the whole loaded scene seen from sky directions, once per scene."""
        self._vis = None
        if not self.vis_tiles or not self._draws:
            return
        cfg = self.config
        directions = sky_directions(self.vis_tiles ** 2)
        corners = extent if extent is not None else np.concatenate(
            [d.corners for d in self._draws])
        matrices = occlusion_matrices(corners, directions)
        self._radiance_scale = max(1e-6, max(float(d.radiance.max()) for d in self._draws))
        self.vis_fbo.use()
        self.vis_fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.disable(moderngl.CULL_FACE)
        self.ctx.polygon_offset = (2.0, 4.0)
        px = cfg.sky_visibility_px
        for k, light in enumerate(matrices):
            tx, ty = k % self.vis_tiles, k // self.vis_tiles
            self.vis_fbo.viewport = (tx * px, ty * px, px, px)
            self._draw_depth(light, self._draws)
        self.ctx.polygon_offset = (0.0, 0.0)
        self.vis_fbo.viewport = (0, 0, *self.vis_map.size)
        # Atlas coordinates: the tile's [0, 1] square scaled into its place.
        atlas = []
        for k, light in enumerate(matrices):
            tile = np.eye(4)
            tile[0, 0] = tile[1, 1] = 1.0 / self.vis_tiles
            tile[0, 3], tile[1, 3] = (k % self.vis_tiles, k // self.vis_tiles) / np.float64(
                self.vis_tiles)
            atlas.append(tile @ _CLIP_TO_TEXTURE @ light)
        weights = self.lighting.sky_radiance(directions) @ LUMINANCE
        texel = max(shadow_texel_m(m, px) for m in matrices)
        self._vis = (np.array(atlas), directions, np.maximum(weights, 1e-6), texel)

    def _front_to_back(self, camera: Camera) -> list[_Draw]:
        """Nearest parts first: llvmpipe's early depth test then skips hidden fragments."""
        eye = camera.pose[:3, 3]
        return sorted(self._draws, key=lambda d: float(np.sum((d.center - eye) ** 2)))

    @staticmethod
    def _matrices(view: np.ndarray, pose: np.ndarray) -> tuple[bytes, bytes]:
        modelview = view @ pose  # float64, then float32 for GL
        normal = np.linalg.inv(modelview[:3, :3]).T
        return (modelview.astype("f4").T.tobytes(), normal.astype("f4").T.tobytes())

    def _draw_depth(self, light: np.ndarray, draws: list[_Draw]) -> None:
        """Depth of ``draws`` through the clip-from-world matrix ``light`` into the bound
        framebuffer (sun shadows, sky visibility)."""
        prog = self.programs["shadow"]
        # Parts wholly beyond the map's sides make no fragment.
        inside = in_clip_xy(np.stack([d.corners for d in draws]), light) if draws else []
        for draw in (d for d, keep in zip(draws, inside, strict=True) if keep):
            prog["u_light_mvp"].write((light @ draw.pose).astype("f4").T.tobytes())
            prog["u_radiance"].value = tuple(draw.radiance / self._radiance_scale)
            draw.vaos["shadow"].render()

    def _shadow_pass(self, camera: Camera, draws: list[_Draw]) -> np.ndarray | None:
        """Draw the sun's depth; return the shadow map's clip-from-world matrix."""
        if not self.config.shadow_map_px or not draws or not self.lighting.sun_irradiance:
            return None
        light = shadow_matrix(camera, self.config, self.lighting.sun_direction)
        self.shadow_fbo.use()
        self.shadow_fbo.clear(depth=1.0)
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.disable(moderngl.CULL_FACE)
        # Slope-scaled offset against shadow acne on surfaces grazed by the sun; depth clamping
        # keeps casters on the sun side of the map's range (glsynth.world.sunlight).
        self.ctx.polygon_offset = (2.0, 4.0)
        self.ctx.enable_direct(_GL_DEPTH_CLAMP)
        self._draw_depth(light, draws)
        self.ctx.disable_direct(_GL_DEPTH_CLAMP)
        self.ctx.polygon_offset = (0.0, 0.0)
        return light

    def _set_lighting(self, lighting: Lighting) -> None:
        """The uniforms that stay the same for every camera of an environment: all of them
        from ``lighting`` (the SH ambient light, the sky, the sun's strength, the exposure)."""
        color, sky = self.programs["color"], self.programs["sky"]
        for prog in (color, sky):
            prog["u_exposure"].value = lighting.exposure
        color["u_sun_color"].value = (lighting.sun_irradiance,) * 3
        sky_sh, ground_sh = lighting.irradiance_sh()
        color["u_sh_sky"].write(sky_sh.astype("f4").tobytes())
        color["u_sh_ground"].write(ground_sh.astype("f4").tobytes())
        sky["u_sky_model"].value = 0 if lighting.sky == "preetham" else 1
        sky["u_sky_strength"].value = lighting.sky_strength
        sky["u_sky_uniform"].value = tuple(lighting.sky_strength * np.array(lighting.sky_rgb))
        model = lighting.preetham()
        sky["u_sky_zenith"].value = tuple(model.zenith)
        sky["u_sky_perez"].write(model.perez.astype("f4").tobytes())
        sky["u_sky_sun"].value = tuple(lighting.sky_sun_direction)

    def _fullscreen(self, program: str) -> None:
        self._fullscreen_vaos[program].render(moderngl.TRIANGLES, vertices=3)

    @staticmethod
    def _intrinsics(camera: Camera) -> tuple[float, float, float, float]:
        k = camera.K
        return (float(k[0, 0]), float(k[1, 1]), float(k[0, 2]), float(k[1, 2]))

    def _ao_pass(self, camera: Camera) -> None:
        """Occlusion from the label texture (drawn for this camera) into self.ao."""
        cfg, prog = self.config, self.programs["ssao"]
        self.ctx.disable(moderngl.DEPTH_TEST)
        self.ao_raw_fbo.use()
        self.label_target.use(0)
        prog["u_labels"].value = 0
        prog["u_intrinsics"].value = self._intrinsics(camera)
        prog["u_size"].value = (float(self.size[0]), float(self.size[1]))
        prog["u_radius"].value = cfg.ao_radius_m
        prog["u_samples"].value = cfg.ao_samples
        self._fullscreen("ssao")
        self.ao_fbo.use()
        self.ao_raw.use(0)
        self.programs["ssao_blur"]["u_raw"].value = 0
        self._fullscreen("ssao_blur")

    def _draw_sky(self, camera: Camera) -> None:
        """The sky where the colour pass drew nothing (depth still at the far plane)."""
        prog = self.programs["sky"]
        prog["u_intrinsics"].value = self._intrinsics(camera)
        prog["u_height"].value = float(self.size[1])
        prog["u_world_from_view"].write(camera.pose[:3, :3].astype("f4").T.tobytes())
        self.ctx.depth_func = "<="
        self._fullscreen("sky")
        self.ctx.depth_func = "<"

    def _draw_surfaces(self, program: str, camera: Camera, placed: list[_Placed]) -> None:
        """``placed`` through ``program`` (mesh.vert, positions and normals) from ``camera``,
        into the bound framebuffer, with no per-part uniforms beyond the matrices."""
        prog = self.programs[program]
        prog["u_projection"].write(camera.projection().astype("f4").T.tobytes())
        for item in placed:
            prog["u_modelview"].write(item.modelview)
            prog["u_normal_matrix"].write(item.normal)
            item.draw.vaos[program].render()

    def _multisample(self, camera: Camera, placed: list[_Placed]) -> moderngl.Framebuffer:
        """Draw each sample's surface, then resolve the multisampled colour from the
        single-sample colour pass's pixels; return the framebuffer that holds the result."""
        self.msaa_fbo.use()
        self.msaa_fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        self.ctx.enable(moderngl.DEPTH_TEST)
        self._draw_surfaces("msaa", camera, placed)
        self.resolve_fbo.use()
        self.resolve_fbo.clear(depth=1.0)
        inputs = (("u_sample_surface", self.sample_targets[0]),
                  ("u_sample_depth", self.sample_targets[1]), ("u_labels", self.label_target),
                  ("u_normals", self.normal_target), ("u_shaded", self.color_target))
        for unit, (_, texture) in enumerate(inputs):
            texture.use(unit)
        self.ctx.depth_func = "1"  # every pixel writes its mark
        for step in ("msaa_interior", "msaa_resolve"):
            prog = self.programs[step]
            for unit, (name, _) in enumerate(inputs):
                prog[name].value = unit
            prog["u_samples"].value = self.config.msaa
            self._fullscreen(step)
            self.ctx.depth_func = "<="  # the full resolve where the mark is 1
        self.ctx.depth_func = "<"
        return self.resolve_fbo

    def _sky_visibility_pass(self, camera: Camera, placed: list[_Placed]) -> None:
        """The sky visibility of the surfaces seen at every second pixel (sky_targets)."""
        if self._vis is None:
            return
        prog = self.programs["sky_visibility"]
        self.sky_fbo.use()
        self.sky_fbo.clear(0.0, 0.0, 0.0, 0.0)
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.disable(moderngl.CULL_FACE)
        prog["u_vis_map"].value = 0
        self.vis_map.use(0)
        prog["u_vis_radiance"].value = 1
        self.vis_radiance.use(1)
        atlas, directions, weights, texel = self._vis
        pad = _MAX_VIS - len(directions)  # the shader's arrays hold 16
        prog["u_vis_count"].value = len(directions)
        view = camera.view()
        from_view = (atlas @ camera.pose).transpose(0, 2, 1)
        prog["u_vis_from_view"].write(np.concatenate(
            [from_view, np.zeros((pad, 4, 4))]).astype("f4").tobytes())
        prog["u_vis_dir"].write(np.concatenate(
            [directions @ view[:3, :3].T, np.zeros((pad, 3))]).astype("f4").tobytes())
        prog["u_vis_weight"].write(np.concatenate([weights, np.zeros(pad)]).astype("f4")
                                   .tobytes())
        # 1.5 texels along the normal, as for the sun's map.
        prog["u_vis_offset_m"].value = 1.5 * texel
        prog["u_vis_solid_angle"].value = (sky_solid_angle(len(directions))
                                           * self._radiance_scale)
        self._draw_surfaces("sky_visibility", camera, placed)

    def _color_pass(self, camera: Camera, placed: list[_Placed], casters: list[_Draw],
                    ao: bool) -> np.ndarray:
        """Colour of ``placed``, shadowed by ``casters`` (parts out of view cast shadows)."""
        cfg, prog = self.config, self.programs["color"]
        self._sky_visibility_pass(camera, placed)
        light = self._shadow_pass(camera, casters)
        # Against the label pass's depth, unchanged: only the nearest surface passes "<=", so
        # each pixel is shaded once. Parts and triangles are drawn in reverse order, so that
        # where they tie in depth the last written is the first drawn, which the labels keep:
        # colour shows the very surface that the labels name.
        fbo = self.color_fbo
        fbo.use()
        fbo.depth_mask = False
        fbo.clear(0.0, 0.0, 0.0, 1.0)
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.disable(moderngl.CULL_FACE)
        self.ctx.depth_func = "<="
        view = camera.view()
        view3 = view[:3, :3]
        prog["u_projection"].write(camera.projection().astype("f4").T.tobytes())
        prog["u_sun_dir"].value = tuple(view3 @ self.lighting.sun_direction)
        prog["u_world_from_view"].write(camera.pose[:3, :3].astype("f4").T.tobytes())
        for unit, name in enumerate(("u_base_color_map", "u_emissive_map", "u_normal_map",
                                     "u_shadow_map", "u_ao")):
            prog[name].value = unit
        prog["u_has_shadows"].value = light is not None
        self.shadow_map.use(3)
        prog["u_has_ao"].value = ao
        self.ao.use(4)
        prog["u_vis_count"].value = 0 if self._vis is None else len(self._vis[1])
        for unit, (name, target) in enumerate(zip(("u_sky_light", "u_sky_surface", "u_sky_open"),
                                                   self.sky_targets, strict=True), start=5):
            prog[name].value = unit
            target.use(unit)
        if light is not None:
            shadow_from_view = _CLIP_TO_TEXTURE @ light @ camera.pose
            prog["u_shadow_from_view"].write(shadow_from_view.astype("f4").T.tobytes())
            prog["u_shadow_texel"].value = 1.0 / cfg.shadow_map_px
            # 1.5 texels along the normal lifts the lookup clear of the surface's own texels.
            prog["u_shadow_offset_m"].value = 1.5 * shadow_texel_m(light, cfg.shadow_map_px)
        for item in reversed(placed):
            draw = item.draw
            prog["u_modelview"].write(item.modelview)
            prog["u_normal_matrix"].write(item.normal)
            mat = draw.material
            prog["u_base_color"].value = tuple(float(c) for c in mat.base_color)
            prog["u_metallic"].value = float(mat.metallic)
            prog["u_roughness"].value = float(mat.roughness)
            prog["u_emissive"].value = tuple(float(c) for c in mat.emissive)
            prog["u_has_normal_map"].value = "normal" in draw.textures
            tex = draw.textures
            tex.get("base", self._defaults["white"]).use(0)
            tex.get("emissive", self._defaults["white"]).use(1)
            tex.get("normal", self._defaults["flat"]).use(2)
            draw.vaos["color"].render()
        self._draw_sky(camera)
        fbo.depth_mask = True
        if cfg.msaa:
            fbo = self._multisample(camera, placed)
        raw = fbo.read(components=3, alignment=1)
        return np.frombuffer(raw, np.uint8).reshape(self.size[1], self.size[0], 3)[::-1]

    def _label_pass(self, camera: Camera, placed: list[_Placed]) -> None:
        prog = self.programs["labels"]
        self.label_fbo.use()
        self.label_fbo.clear(float(Component.NONBRIDGE), float(Damage.NO_DAMAGE),
                             camera.zfar, 0.0)
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.disable(moderngl.CULL_FACE)
        prog["u_projection"].write(camera.projection().astype("f4").T.tobytes())
        prog["u_damage_mask"].value = 0
        for item in placed:
            draw = item.draw
            prog["u_modelview"].write(item.modelview)
            prog["u_component"].value = draw.component
            prog["u_has_damage_mask"].value = draw.damage_mask is not None
            if draw.damage_mask is not None:
                draw.damage_mask.use(0)
            draw.vaos["labels"].render()

    def render(self, camera: Camera, passes: frozenset[str] | set[str] = PASSES) -> RenderOutput:
        unknown = set(passes) - PASSES
        if unknown:
            raise ValueError(f"passes {sorted(unknown)}: choose from {sorted(PASSES)}")
        if (camera.width, camera.height) != self.size:
            raise ValueError(f"camera size {camera.width}x{camera.height} differs from the "
                             f"renderer's {self.size[0]}x{self.size[1]}: make the camera with "
                             "the same [render] width and height")
        if self.lighting is None:
            raise ValueError("no scene loaded: call load(scene, lighting) first")
        self.make_current()
        draws = self._front_to_back(camera)
        # Parts wholly outside the view make no fragment: only the sun's shadow pass draws them.
        view = camera.view()
        seen = seen_by(np.stack([d.corners for d in draws]), camera) if draws else []
        placed = [_Placed(d, *self._matrices(view, d.pose))
                  for d, s in zip(draws, seen, strict=True) if s]
        ao = "color" in passes and self.config.ao == "ssao"
        out: dict[str, np.ndarray] = {}
        self._label_pass(camera, placed)  # the colour pass tests against its depth
        if passes & _LABEL_PASSES:
            raw = self.label_fbo.read(components=4, dtype="f4")
            labels = np.frombuffer(raw, np.float32).reshape(self.size[1], self.size[0], 4)[::-1]
            if "component" in passes:
                out["component"] = labels[..., 0].astype(np.uint8)
            if "damage" in passes:
                out["damage"] = labels[..., 1].astype(np.uint8)
            if "depth" in passes:
                out["depth"] = np.ascontiguousarray(labels[..., 2])
        if ao:
            self._ao_pass(camera)
        color = self._color_pass(camera, placed, draws, ao) if "color" in passes else None
        return RenderOutput(color=None if color is None else np.ascontiguousarray(color), **out)
