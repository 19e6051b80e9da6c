"""The scene every page of one ``glsynth view`` shares: a config (preset, config text,
quality, fixed lighting), one environment opened on the renderer, its sampled cameras and
their Section 3.4 verdicts. Opening and relighting run on the render thread."""

import dataclasses
import types
import typing
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from glsynth.appearance.caches import disk_caches
from glsynth.core.config import Config, config_from_dict, load_config, parse_toml
from glsynth.core.errors import UserError, shown
from glsynth.core.filters import removal_reason
from glsynth.data.quality import apply_quality
from glsynth.render.gl.renderer import Renderer
from glsynth.render.view import EnvironmentView
from glsynth.view.pick import PartPicker
from glsynth.view.protocol import LIGHTING_FIELDS
from glsynth.world.cameras import CameraPlacement
from glsynth.world.lighting import Lighting, environment_lighting


@dataclass(frozen=True)
class SceneSettings:
    preset: str
    seed: int
    env: int
    quality: str | None = None
    config_toml: str | None = None
    """Text of a config file overlaid on the preset (as ``--config`` overlays its file)."""
    page_toml: str | None = None
    """Text of a config file a page sent, overlaid on the above: it may change no setting
    that names a path or a disk cache's entries (check_page_config)."""
    lighting: dict[str, float] | None = None
    """Fixed values of LIGHTING_FIELDS; None: the environment's own draw."""


def with_lighting(config: Config, values: dict[str, float]) -> Config:
    """``config`` whose [lighting] ranges are fixed at ``values`` (what a TOML with
    ``sun_elevation_deg = [v, v]`` and so on gives, so a saved view can be rendered again)."""
    ranges = {k: [v, v] for k, v in values.items() if k != "exposure"}
    return config_from_dict({"lighting": {**ranges, "exposure": values["exposure"]}}, config)


def _overlay(config: Config, text: str) -> Config:
    return config_from_dict(parse_toml(text, "config file"), config)


def _finish(config: Config, settings: SceneSettings) -> Config:
    """``config`` at the settings' quality and lighting, checked for the viewer."""
    if settings.quality:
        config = apply_quality(config, settings.quality)
    if settings.lighting is not None:
        config = with_lighting(config, settings.lighting)
    if config.render.renderer != "gl":
        raise UserError(f'[render] renderer = "{config.render.renderer}": the viewer draws '
                        'with GL; set renderer = "gl"')
    return config


def scene_config(settings: SceneSettings) -> Config:
    """The config of ``settings``, or UserError (one line) before any work."""
    config = load_config(settings.preset)
    if settings.config_toml is not None:
        config = _overlay(config, settings.config_toml)
    if settings.page_toml is None:
        return _finish(config, settings)
    paged = _finish(_overlay(config, settings.page_toml), settings)
    check_page_config(_finish(config, settings), paged)
    return paged


def _names_path(hint: object) -> bool:
    """Whether a field of this type can hold a path: free text (``str``) or a Path, alone or
    in a union (a Literal's strings are fixed choices)."""
    options = typing.get_args(hint) if isinstance(hint, types.UnionType) else (hint,)
    return any(option in (str, Path) for option in options)


def _changes(base: Config, config: Config) -> list[tuple[str, str, object]]:
    """(section, field, new value) of each field ``config`` sets otherwise than ``base``."""
    found = []
    for section in dataclasses.fields(Config):
        old, new = getattr(base, section.name), getattr(config, section.name)
        found += [(section.name, f.name, getattr(new, f.name)) for f in dataclasses.fields(old)
                  if getattr(old, f.name) != getattr(new, f.name)]
    return found


def _moves_caches(base: Config, section: str, name: str, value: object) -> bool:
    """Whether setting this one field of ``base`` names other disk-cache entries (True too
    where the field cannot be set alone: only with others, which then decide)."""
    try:
        alone = dataclasses.replace(base, **{section: dataclasses.replace(
            getattr(base, section), **{name: value})})
    except UserError:
        return True
    return disk_caches(alone) != disk_caches(base)


def check_page_config(base: Config, config: Config) -> None:
    """Refuse, naming the field, a page's ``config`` that sets a path on the server's machine
    (the page would read its files back rendered) or that names disk-cache entries ``base``,
    the server's own config, does not (the page would fill the server's disk outside
    ``--out``). Both are found from the config dataclasses' types and the caches' names
    (glsynth.appearance.caches), not from a list of fields."""
    changes = _changes(base, config)
    for section, name, _value in changes:
        if _names_path(typing.get_type_hints(type(getattr(base, section)))[name]):
            raise UserError(f"[{section}] {name}: a page may not set a path on the server's "
                            "machine; give it in the file of glsynth view --config")
    if disk_caches(config) == disk_caches(base):
        return
    movers = [c for c in changes if _moves_caches(base, *c)] or changes
    section, name, value = movers[0]
    raise UserError(f"[{section}] {name} = {shown(value, 40)}: a page may not change what the "
                    "server caches on disk; give it in the file of glsynth view --config")


def lighting_values(lighting: Lighting) -> dict[str, float]:
    return {k: float(getattr(lighting, k)) for k in LIGHTING_FIELDS}


def camera_summary(placement: CameraPlacement) -> dict:
    """What the page lists of a sampled camera, with the pose it jumps to."""
    return {"index": placement.index, "kind": placement.kind,
            "focal_mm": placement.camera.focal_mm, "s_m": placement.s_m,
            "side": placement.side, "distance_m": placement.distance_m,
            "height_m": placement.height_m,
            "euler_deg": [float(np.degrees(a)) for a in placement.euler_xyz_rad],
            "pose": placement.camera.pose.tolist()}


@dataclass
class Scene:
    settings: SceneSettings
    config: Config
    view: EnvironmentView
    cameras: list[CameraPlacement]
    picker: PartPicker
    verdicts: dict[int, str] = field(default_factory=dict)
    """Camera index -> "kept" or the Section 3.4 reason it is removed."""

    @property
    def full_size(self) -> tuple[int, int]:
        return self.config.render.width, self.config.render.height

    def summary(self) -> dict:
        s = self.settings
        return {"type": "scene", "preset": s.preset, "seed": s.seed, "env": s.env,
                "quality": s.quality, "size": list(self.full_size),
                "sensor_mm": self.config.cameras.sensor_mm,
                "lighting": lighting_values(self.view.lighting),
                "cameras": [camera_summary(p) for p in self.cameras],
                "verdicts": {str(k): v for k, v in self.verdicts.items()}}

    def relight(self, values: dict[str, float]) -> None:
        """The same environment under fixed lighting ``values`` (UserError if out of range)."""
        config = with_lighting(self.config, values)
        env = self.view.environment
        lighting = environment_lighting(config.lighting, env.root_seed, env.env_index,
                                        ground_albedo=np.array(self.view.lighting.ground_albedo))
        self.view.renderer.relight(lighting)
        self.view.lighting = lighting
        self.config = self.view.config = config
        self.settings = dataclasses.replace(self.settings, lighting=dict(values))

    def verdict(self, index: int, interrupt: Callable[[], bool] | None = None,
                bands: int = 1) -> str:
        """Camera ``index`` rendered at full size, through the Section 3.4 filters; the
        renderer must be at the full size. ``interrupt`` and ``bands``: Renderer.render's."""
        output = self.view.renderer.render(self.cameras[index].camera, interrupt=interrupt,
                                           bands=bands)
        return removal_reason(output.color, output.component, output.depth) or "kept"


def _same_targets(renderer: Renderer, config: Config) -> bool:
    """Whether ``renderer`` was made for this [render] section, but for the image size."""
    strip = {"width": 1, "height": 1}
    return dataclasses.replace(renderer.config, **strip) == dataclasses.replace(config.render,
                                                                                **strip)


def open_scene(settings: SceneSettings, renderer: Renderer | None,
               progress: Callable[[str, float], None], bank_dir: Path | None = None,
               interrupt: Callable[[], bool] | None = None) -> Scene:
    """Open ``settings``' environment on ``renderer`` (a new one if its [render] section
    differs, the old one released first: one context at a time). A failed or interrupted
    opening releases the context it had, so a retry makes one afresh and none is left
    behind. ``bank_dir``, ``interrupt``: EnvironmentView.open's."""
    config = scene_config(settings)
    if renderer is not None and not _same_targets(renderer, config):
        renderer.release()
        renderer = None
    renderer = renderer or Renderer(config.render)
    try:
        renderer.resize(config.render.width, config.render.height)
        view = EnvironmentView.open(config, settings.seed, settings.env, renderer, cull=False,
                                    anywhere=True, progress=progress, bank_dir=bank_dir,
                                    interrupt=interrupt)
        cameras = [view.camera(i) for i in range(config.cameras.total)]
    except BaseException:
        renderer.release()  # nothing else holds it: the old scene was let go before
        raise
    return Scene(settings, config, view, cameras, PartPicker(view.environment.parts))
