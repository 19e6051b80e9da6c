"""Rendering one environment's cameras to files (glsynth render) and quick previews.

GL stays in glsynth.render.gl; this module only orchestrates: environment -> materials -> scene ->
renderer -> files. Every output is written atomically.
"""

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from glsynth.appearance.damage_bank import DamageBank
from glsynth.appearance.dressing import (
    Dressing,
    KnownCracks,
    crack_segments,
    dress,
    open_repository,
)
from glsynth.appearance.materials import surface_albedo
from glsynth.appearance.metering import PartBoxes, face_albedo, metered, part_boxes
from glsynth.core.config import Config
from glsynth.core.fileio import (
    BackgroundWriter,
    atomic_write_bytes,
    atomic_write_json,
    npy_bytes,
    png_bytes,
    write_files,
)
from glsynth.core.interrupts import RenderInterrupted
from glsynth.core.labels import Component
from glsynth.core.palette import COMPONENT_RGB, DAMAGE_RGB, depth_rgb, overlay
from glsynth.core.seeding import Stream, make_rng
from glsynth.render.camera_model import photograph
from glsynth.render.gl.renderer import PASSES, Renderer, RenderOutput
from glsynth.render.scene import RenderScene, build_scene
from glsynth.world.cameras import Camera, CameraPlacement
from glsynth.world.environment import Environment, build_environment, ground_parts
from glsynth.world.face_cameras import place_cameras
from glsynth.world.lighting import Lighting, environment_lighting
from glsynth.world.visibility import occlusion_extent, shadowing_parts, visible_parts


def _stage_report(progress: Callable[[str, float], None] | None,
                  interrupt: Callable[[], bool] | None) -> Callable[[str, float], None]:
    """An opening's report of a stage: ``interrupt()`` first (True raises RenderInterrupted),
    then ``progress``."""
    def report(stage: str, fraction: float) -> None:
        if interrupt is not None and interrupt():
            raise RenderInterrupted(f"the opening was interrupted before {stage}")
        if progress is not None:
            progress(stage, fraction)
    return report


def _loaded(renderer: Renderer, own: bool, scene: RenderScene, lighting: Lighting,
            extent: np.ndarray, interrupt: Callable[[], bool] | None) -> Renderer:
    """``renderer`` with ``scene`` loaded; if the load fails or is interrupted, a renderer
    the opening made itself (``own``) is released, since nothing else holds it."""
    try:
        renderer.load(scene, lighting, extent, interrupt)
    except BaseException:
        if own:
            renderer.release()
        raise
    return renderer


@dataclass
class EnvironmentView:
    """An environment loaded into a renderer, ready for its cameras."""

    config: Config
    environment: Environment
    dressing: Dressing
    scene: RenderScene
    lighting: Lighting
    renderer: Renderer
    placements: list[CameraPlacement] | None = None
    """The environment's sampled cameras, placed once when it was opened; None where it was
    opened for cameras given instead (a flight's)."""
    _albedo: dict[str, float] = field(default_factory=dict)
    """Metered members' albedo (glsynth.appearance.metering.face_albedo), found once each."""
    _part_boxes: PartBoxes | None = None
    """The environment's parts' boxes for the face meter (metering.part_boxes), found once."""

    @classmethod
    def open(cls, config: Config, root_seed: int, env_index: int,
             renderer: Renderer | None = None, cull: bool = True, anywhere: bool = False,
             progress: Callable[[str, float], None] | None = None,
             cameras: Sequence[Camera] | None = None,
             bank_dir: Path | None = None,
             rendering: Sequence[int] | None = None,
             interrupt: Callable[[], bool] | None = None) -> "EnvironmentView":
        """Build, dress and upload environment ``env_index``. Only parts that some camera of
        the environment (all of them, not only those rendered now) can see, or that can shadow
        such a view, are uploaded, and only the seen columns get damage textures, so a camera
        renders the same bytes alone or in a batch, and the same as with ``cull=False``
        (everything uploaded; for measuring). ``anywhere`` uploads every part and damages
        every column, for cameras placed anywhere (glsynth view, render --camera-json).
        ``cameras`` (a flight's) are culled by in place of the environment's sampled ones.
        ``rendering``: the indices of the only sampled cameras this view will render (glsynth
        render --camera): culled by those alone, the same bytes for a fraction of the upload.
        ``progress(stage, fraction)`` hears of each stage. ``bank_dir``: where the damage
        bank caches its textures (default: the cache, glsynth.core.paths.cache_root).
        ``interrupt()``, asked at each stage and before each part's upload: True raises
        RenderInterrupted, the renderer given left empty (a viewer stopping mid-opening)."""
        report = _stage_report(progress, interrupt)
        if renderer is not None:
            # Free the previous environment's textures (and the arrays behind them) before
            # dressing this one: a worker then peaks at one environment, not two.
            renderer.release_scene()
        report("building the environment", 0.0)
        env = build_environment(config, root_seed, env_index)
        placements = None
        known: KnownCracks = {}
        if cameras is None:
            cracks = crack_segments(env, config, known) \
                if config.cameras.face_crack_share else None
            placements = place_cameras(env, config.cameras, config.render,
                                       range(config.cameras.total), cracks)
            chosen = placements if rendering is None else [placements[i] for i in rendering]
            cameras = [p.camera for p in chosen]
        cameras = list(cameras)
        visible = {p.name for p in env.parts} if anywhere else visible_parts(env.parts, cameras)
        report("dressing: materials and damage", 0.3)
        dressing = dress(env, config, open_repository(config, interrupt),
                         DamageBank(config.damage, root_seed, bank_dir), visible, known)
        ground = ground_parts(env.parts)
        lighting = environment_lighting(config.lighting, root_seed, env_index, ground_albedo=(
            surface_albedo(ground, dressing.materials) if ground else None))
        needed = visible | shadowing_parts(env.parts, cameras, config.render, lighting)
        parts = [p for p in env.parts if p.name in needed] if cull else env.parts
        report("uploading to GL", 0.6)
        scene = build_scene(parts, dressing.materials)
        renderer = _loaded(renderer or Renderer(config.render), renderer is None, scene,
                           lighting, occlusion_extent(env.parts), interrupt)
        if progress is not None:
            progress("ready", 1.0)
        return cls(config, env, dressing, scene, lighting, renderer, placements)

    def camera(self, index: int) -> CameraPlacement:
        """Sampled camera ``index`` of the environment (each placed from its own generator,
        so the same as placing it alone)."""
        if self.placements is None:
            raise ValueError("this view was opened for given cameras; it has no sampled ones")
        if not 0 <= index < len(self.placements):
            raise ValueError(f"camera index = {index}: must be in "
                             f"[0, {len(self.placements) - 1}]")
        return self.placements[index]

    def render(self, index: int, passes: frozenset[str] = PASSES, photo: bool = True,
               defer_colour: bool = False) -> tuple[CameraPlacement, RenderOutput]:
        """Sampled camera ``index``'s ``passes``, exposed as [lighting] metering says; its
        colour as [sensor]'s camera photographs it (``photo``; glsynth.render.camera_model),
        or the render's own. ``defer_colour`` (with ``photo`` False): no colour yet, the
        renderer's deferred_colour() reads it (Renderer.render)."""
        if defer_colour and photo:
            raise ValueError("defer_colour leaves no colour to photograph: pass photo=False "
                             "and photograph the deferred colour")
        placement = self.camera(index)
        lighting = self.exposure(placement)
        if lighting is not self.renderer.lighting:
            self.renderer.relight(lighting)
        if photo and self.config.sensor.enabled and "color" in passes:
            passes = passes | {"depth"}  # defocus reads the depth
        output = self.renderer.render(placement.camera, passes, defer_colour=defer_colour)
        return placement, self.photograph(output, placement.camera, index) if photo else output

    def photograph(self, output: RenderOutput, camera: Camera, item: int,
                   velocity_mps: np.ndarray | None = None) -> RenderOutput:
        """``output`` with its colour photographed by [sensor]'s camera, drawn from the
        view's own generator (Stream.SENSOR, ``item``: the camera or frame index); labels and
        depth stay the render's. ``velocity_mps``: camera_model.photograph's."""
        if not self.config.sensor.enabled or output.color is None:
            return output
        rng = make_rng(self.environment.root_seed, self.environment.env_index, Stream.SENSOR,
                       item)
        return replace(output, color=photograph(output.color, output.depth, camera,
                                                self.config.sensor, rng, velocity_mps))

    def exposure(self, placement: CameraPlacement) -> Lighting:
        """The lighting ``placement`` is rendered under: the environment's, or under
        [lighting] metering = "face" for a camera aimed at a face, metered on that face
        (glsynth.appearance.metering)."""
        aim = placement.face
        if self.config.lighting.metering == "scene" or aim is None:
            return self.lighting
        if aim.member not in self._albedo:
            member = next(p for p in self.environment.parts if p.name == aim.member)
            self._albedo[aim.member] = face_albedo(member, self.dressing.materials[aim.member])
        if self._part_boxes is None:
            self._part_boxes = part_boxes(self.environment.parts)
        return metered(self.lighting, aim, self.environment.parts, self._albedo[aim.member],
                       self._part_boxes)


def free_camera_json(camera: Camera, meta: dict) -> dict:
    """camera.json of a bare Camera (placed by hand or flown): kind "free" unless ``meta``
    names another."""
    return {**camera.to_json(), "kind": "free", **meta}


def write_render(out_dir: str | Path, placement: CameraPlacement | Camera,
                 output: RenderOutput, meta: dict) -> None:
    """image.png, component.png, damage.png (uint8 ids), crack_width.npy (float32 mm, 0
    where no crack is: RenderOutput.crack_width), depth.npy (float32), camera.json. A bare
    Camera (placed by hand or flown, not sampled) records kind "free" unless ``meta`` names
    another, and no sampled values."""
    out = Path(out_dir)
    # The colour's PNG, two thirds of the files' time, is encoded and written by the
    # background writer while this thread writes the rest (OpenCV's encoder and the writes
    # release the GIL); leaving the block waits for it and raises its failure, so
    # camera.json still comes last.
    with BackgroundWriter() as writer:
        writer.submit(write_files, out, {"image.png": (output.color, "PNG")}, {})
        atomic_write_bytes(out / "component.png", png_bytes(output.component))
        atomic_write_bytes(out / "damage.png", png_bytes(output.damage))
        atomic_write_bytes(out / "crack_width.npy", npy_bytes(output.crack_width))
        atomic_write_bytes(out / "depth.npy", npy_bytes(output.depth))
    if isinstance(placement, Camera):
        atomic_write_json(out / "camera.json", free_camera_json(placement, meta))
        return
    info = placement.camera.to_json()
    info.update(camera_index=placement.index, kind=placement.kind, s_m=placement.s_m,
                side=placement.side, distance_m=placement.distance_m,
                height_m=placement.height_m,
                euler_xyz_rad=list(placement.euler_xyz_rad), **meta)
    if placement.face is not None:
        info["face"] = placement.face.to_json()
    atomic_write_json(out / "camera.json", info)


def preview_sheet(view: EnvironmentView, cameras: list[int]) -> np.ndarray:
    """Rows of (colour, component overlay, damage overlay, depth) for each camera."""
    rows = []
    for index in cameras:
        _, out = view.render(index)
        comp = overlay(out.color, out.component, COMPONENT_RGB, 0.55)
        dmg = overlay(out.color, out.damage, DAMAGE_RGB, 0.8, skip=(1,))
        rows.append(np.concatenate([out.color, comp, dmg, depth_rgb(out.depth)], axis=1))
    return np.concatenate(rows, axis=0)


def preview_config(config: Config, width: int) -> Config:
    """The same scene at a preview width (same aspect), without MSAA, with 256-pixel damage
    and repository textures and at most a 1024-pixel shadow map: geometry, cameras and damage
    placement are unchanged."""
    height = max(1, round(width * config.render.height / config.render.width))
    return replace(config,
                   render=replace(config.render, width=width, height=height, msaa=0,
                                  shadow_map_px=min(1024, config.render.shadow_map_px)),
                   damage=replace(config.damage, resolution=min(256, config.damage.resolution)),
                   materials=replace(config.materials,
                                     texture_size=min(256, config.materials.texture_size)))


def describe_output(output: RenderOutput) -> str:
    ids = sorted(Component(int(i)).name.lower() for i in np.unique(output.component))
    return f"components {ids}, depth {output.depth.min():.2f}-{output.depth.max():.2f} m"
