"""Quality presets, from ``preview`` to ``reference``: what a render pays for fidelity
(``--quality`` on export, render, generate and ``bench blender``; measured by ``glsynth bench
quality``, glsynth/measure/quality_bench.py).

A preset sets these knobs of a config (each documented in README.md):
- render resolution, as a scale of the Tokaido image size (the format needs 1.0);
- MSAA samples for colour (labels and depth are never multisampled);
- texture resolution of repository materials, and of damage textures;
- noise octaves of the damage textures;
- tessellation of cylinders (poles and wires; rebar lives in the damage textures);
- the sun's shadow map size (0: no shadows);
- the sky-visibility maps (0, 4, 9 or 16) and screen-space ambient occlusion ("ssao"/"off").
"""

import dataclasses
from dataclasses import dataclass

from glsynth.core.config import Config, load_config
from glsynth.core.errors import UserError
from glsynth.data.tokaido import IMAGE_SIZE


@dataclass(frozen=True)
class Quality:
    render_scale: float
    """Render size as a scale of the Tokaido image size, IMAGE_SIZE."""
    msaa: int
    texture_size: int
    damage_resolution: int
    octaves: int
    cylinder_segments: int
    shadow_map_px: int
    sky_visibility_maps: int
    ao: str

    @classmethod
    def of(cls, config: Config) -> "Quality":
        """The knobs as ``config`` sets them."""
        r = config.render
        return cls(render_scale=r.width / IMAGE_SIZE[0], msaa=r.msaa,
                   texture_size=config.materials.texture_size,
                   damage_resolution=config.damage.resolution, octaves=config.damage.octaves,
                   cylinder_segments=config.environment.cylinder_segments,
                   shadow_map_px=r.shadow_map_px, sky_visibility_maps=r.sky_visibility_maps,
                   ao=r.ao)


QUALITY = {
    "preview": Quality(render_scale=0.25, msaa=0, texture_size=128, damage_resolution=256,
                       octaves=4, cylinder_segments=6, shadow_map_px=512, sky_visibility_maps=4,
                       ao="off"),
    "fast": Quality(render_scale=0.5, msaa=0, texture_size=256, damage_resolution=512,
                    octaves=6, cylinder_segments=8, shadow_map_px=1024, sky_visibility_maps=16,
                    ao="off"),
    "balanced": Quality(render_scale=1.0, msaa=0, texture_size=512, damage_resolution=1024,
                        octaves=8, cylinder_segments=12, shadow_map_px=2048,
                        sky_visibility_maps=16, ao="off"),
    "default": Quality.of(Config()),
    "high": Quality.of(load_config("paper")),
    "reference": Quality(render_scale=1.0, msaa=4, texture_size=1024, damage_resolution=2048,
                         octaves=8, cylinder_segments=24, shadow_map_px=4096,
                         sky_visibility_maps=16, ao="ssao"),
}
"""'default' is Config()'s own setting, 'high' the paper preset's (2048 px damage).
'reference' uses MSAA 4, the most llvmpipe offers (the renderer refuses more than the GL has),
and SSAO (every occlusion term on; it measured no closer to Cycles than without: docs/results.md,
"Lighting knobs"). 'preview' keeps sun shadows (without them, shade is wrong everywhere) on a
small map, and 4 sky maps."""


def apply_quality(config: Config, name: str) -> Config:
    """``config`` with every knob of preset ``name``."""
    if name not in QUALITY:
        raise UserError(f"quality {name!r}: choose one of {', '.join(QUALITY)}")
    q = QUALITY[name]
    width, height = (round(side * q.render_scale) for side in IMAGE_SIZE)
    return dataclasses.replace(
        config,
        render=dataclasses.replace(config.render, width=width, height=height, msaa=q.msaa,
                                   shadow_map_px=q.shadow_map_px,
                                   sky_visibility_maps=q.sky_visibility_maps, ao=q.ao),
        materials=dataclasses.replace(config.materials, texture_size=q.texture_size),
        damage=dataclasses.replace(config.damage, resolution=q.damage_resolution,
                                   octaves=q.octaves),
        environment=dataclasses.replace(config.environment,
                                        cylinder_segments=q.cylinder_segments))
