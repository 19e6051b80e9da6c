"""Small scenes and cameras for GL tests."""

import contextlib
import dataclasses
from collections.abc import Iterator

import numpy as np
import trimesh
from trimesh.visual import TextureVisuals

from glsynth.appearance.materials import Material, plain_material
from glsynth.core.config import Config, RenderConfig, load_config
from glsynth.core.labels import Component
from glsynth.render.gl.renderer import PASSES, Renderer, RenderOutput
from glsynth.render.scene import RenderScene, build_scene
from glsynth.world.cameras import Camera
from glsynth.world.environment import Environment, Part, PartKind
from glsynth.world.lighting import Lighting

LIGHT = Lighting(sun_elevation_deg=50.0, sun_azimuth_deg=30.0, sun_irradiance=3.0,
                 sky="preetham", turbidity=3.0, sky_strength=1.0, sky_rgb=(0.62, 0.74, 0.88),
                 ground_albedo=(0.2, 0.2, 0.2), exposure=1.0)
"""A fixed sun and sky for small GL scenes."""


def quad(corners: np.ndarray, uv: np.ndarray | None = None) -> trimesh.Trimesh:
    """Two triangles over 4 corners given counter-clockwise as seen from the front."""
    mesh = trimesh.Trimesh(np.asarray(corners, float), [[0, 1, 2], [0, 2, 3]], process=False)
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float) if uv is None else uv
    mesh.visual = TextureVisuals(uv=uv)
    return mesh


def scene_of(*items: tuple[str, Component, trimesh.Trimesh, Material]):
    """A scene of plain parts; each is of the first part kind labelled with its component
    (these scenes need a part's label, not what it is)."""
    parts = [Part(name, _first_kind(comp), None, mesh, np.eye(4))
             for name, comp, mesh, _ in items]
    return build_scene(parts, {name: mat for name, _, _, mat in items})


def _first_kind(component: Component) -> PartKind:
    return next(k for k in PartKind if k.component is component)


def camera(width: int = 64, height: int = 48, focal_mm: float = 36.0,
           pose: np.ndarray | None = None, zfar: float = 2000.0) -> Camera:
    """Default: at the origin, looking down -z (fx = width)."""
    return Camera(width, height, focal_mm, 36.0, np.eye(4) if pose is None else pose,
                  0.05, zfar)


def pixel_plate(cam: Camera, depth: float) -> trimesh.Trimesh:
    """A plate facing ``cam`` (at the origin, looking down -z) at ``depth`` metres, its corners
    on the image's outer pixel edges: with the default uvs, texel (c, r) of a texture the
    image's size covers pixel (c, r) exactly (pixel c spans u in [c / width, (c + 1) / width],
    row 0 is the top, v = 1)."""
    k = cam.K
    x0, x1 = (-0.5 - k[0, 2]) / k[0, 0] * depth, (cam.width - 0.5 - k[0, 2]) / k[0, 0] * depth
    y1 = -(-0.5 - k[1, 2]) / k[1, 1] * depth
    y0 = -(cam.height - 0.5 - k[1, 2]) / k[1, 1] * depth
    return quad([[x0, y0, -depth], [x1, y0, -depth], [x1, y1, -depth], [x0, y1, -depth]])


def render_once(scene: RenderScene, config: RenderConfig, cam: Camera | None = None,
                passes: frozenset[str] | set[str] = PASSES,
                platform: str | None = None) -> RenderOutput:
    """``scene`` under LIGHT from ``cam`` (default: camera()) by a renderer of its own (on
    ``platform`` if given), released however the render ends; GL must report no error."""
    with Renderer(config, platform) as r:
        assert platform is None or r.platform == platform
        r.load(scene, LIGHT)
        out = r.render(cam or camera(), passes)
        assert r.ctx.error == "GL_NO_ERROR"
    return out


def render_config(width: int = 64, height: int = 48, msaa: int = 0) -> RenderConfig:
    return dataclasses.replace(RenderConfig(), width=width, height=height, msaa=msaa)


def plain_materials(env: Environment) -> dict[str, Material]:
    """Untextured materials for every part of an environment (scene panels emissive)."""
    return {p.name: plain_material(p.component, emissive=p.kind is PartKind.SCENE)
            for p in env.parts}


@contextlib.contextmanager
def loaded_renderer(env: Environment, config: RenderConfig) -> Iterator[Renderer]:
    """A renderer with ``env`` loaded under plain materials and LIGHT; on leaving, GL must
    have reported no error."""
    with Renderer(config) as r:
        r.load(build_scene(env.parts, plain_materials(env)), LIGHT)
        yield r
        assert r.ctx.error == "GL_NO_ERROR"


def half_inspection(small_sky: bool = False) -> Config:
    """The inspection preset at half its image size and half its face_crack_px, which keeps
    its cameras where they stand (their distance cap is the image's width over face_crack_px),
    with MSAA off: a quarter of the shading, for tests of what a surface shows rather than of
    MSAA. ``small_sky``: 4 sky-visibility maps of 256 px, for tests that compare views with
    each other (the sky's occlusion, and so a shaded face's exposure, is then coarser)."""
    inspection = load_config("inspection")
    sky = {"sky_visibility_maps": 4, "sky_visibility_px": 256} if small_sky else {}
    return dataclasses.replace(
        inspection, render=dataclasses.replace(inspection.render, width=960, height=540, msaa=0,
                                               **sky),
        cameras=dataclasses.replace(inspection.cameras,
                                    face_crack_px=inspection.cameras.face_crack_px / 2))
