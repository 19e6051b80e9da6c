"""Environment export: glTF binary (glsynth.render.gltf) and a scene.json description.

glTF is y-up; glsynth is z-up (as Blender, whose camera Euler angles the paper uses). Each node's
transform therefore includes the rotation (x, y, z) -> (x, z, -y). scene.json keeps glsynth's
z-up world coordinates and says so, and describes the sky, exposure and tone map that glTF
cannot hold.
"""

import dataclasses
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from glsynth.appearance.materials import Material
from glsynth.core.errors import UserError
from glsynth.core.fileio import atomic_write_bytes, atomic_write_json
from glsynth.core.labels import Component
from glsynth.render.gltf import gltf_binary
from glsynth.render.tonemap import TONE_MAP_FORMULA
from glsynth.world.environment import Environment, Part
from glsynth.world.lighting import Lighting

# Flat colours per component, for viewing the geometry without the dressing (and for Blender's
# label renders, which replace every material anyway).
_PREVIEW_RGBA = {
    Component.NONBRIDGE: (0.45, 0.55, 0.35, 1.0),
    Component.SLAB: (0.75, 0.75, 0.72, 1.0),
    Component.BEAM: (0.65, 0.62, 0.58, 1.0),
    Component.COLUMN: (0.82, 0.80, 0.76, 1.0),
    Component.NONSTRUCTURAL: (0.30, 0.45, 0.70, 1.0),
    Component.RAIL: (0.35, 0.33, 0.32, 1.0),
    Component.SLEEPER: (0.55, 0.42, 0.30, 1.0),
    Component.OTHER: (0.85, 0.45, 0.20, 1.0),
}


def preview_materials(parts: Sequence[Part]) -> dict[str, Material]:
    """One flat, matte material per component."""
    by_component = {c: Material(base_color=rgba, metallic=0.0, roughness=1.0)
                    for c, rgba in _PREVIEW_RGBA.items()}
    return {p.name: by_component[p.component] for p in parts}


def describe(env: Environment) -> dict[str, Any]:
    """The scene.json content: per viaduct design values and footprint, and the parts list."""
    traj = env.trajectory
    viaducts = []
    for v in env.viaducts:
        viaducts.append({
            "index": v.index,
            "start_s_m": v.start_s_m,
            "height_m": v.height_m,
            "radius_m": v.radius_m if math.isfinite(v.radius_m) else None,
            "curvature_per_m": float(traj.curvature[v.index]),
            "straight": v.sections.straight,
            "table3_row": v.sections.row,
            "column_cm": list(v.sections.column_cm),
            "intermediate_beam_cm": (list(v.sections.intermediate_beam_cm)
                                     if v.sections.intermediate_beam_cm else None),
            "footprint_xy_m": np.round(v.footprint_xy, 4).tolist(),
            "columns": [{"name": c.name, "center_xy_m": list(c.center_xy),
                         "bottom_z_m": c.bottom_z, "top_z_m": c.top_z,
                         "heading_rad": c.heading, "section_m": list(c.section_m)}
                        for c in v.columns],
        })
    return {
        "root_seed": env.root_seed,
        "env": env.env_index,
        "coordinates": "metres, z up, x along the initial track direction, y to its left "
                       "(the .glb is the same world rotated to glTF's y up)",
        "trajectory": {"min_radius_m": (traj.min_radius_m if math.isfinite(traj.min_radius_m)
                                        else None),
                       "initial_height_m": traj.initial_height_m,
                       "slopes": traj.slopes.tolist()},
        "viaducts": viaducts,
        "parts": [{"name": p.name, "component": p.component.name.lower(),
                   "component_id": int(p.component), "viaduct": p.viaduct,
                   "triangles": len(p.mesh.faces)} for p in env.parts],
        "config": {"environment": dataclasses.asdict(env.config.environment),
                   "design": dataclasses.asdict(env.config.design)},
    }


def describe_lighting(light: Lighting) -> dict[str, Any]:
    """The scene.json description of what lights the scene beyond the glTF's sun: enough to
    rebuild the sky and the tone map (glsynth.world.lighting, glsynth.render.tonemap)."""
    return {"sun_direction_zup": light.sun_direction.tolist(),
            "sun_elevation_deg": light.sun_elevation_deg,
            "sun_azimuth_deg": light.sun_azimuth_deg, "sun_irradiance": light.sun_irradiance,
            "sky": light.sky, "sky_strength": light.sky_strength,
            "preetham_turbidity": light.turbidity,
            "preetham_sun_direction_zup": light.sky_sun_direction.tolist(),
            "uniform_sky_rgb_linear": list(light.sky_rgb),
            "exposure": light.exposure, "tone_map_formula": TONE_MAP_FORMULA}


def glb_path(out: str | Path) -> Path:
    """``out`` as a Path, refused unless it names a .glb file; callers check it before they
    build anything, so a wrong path costs no environment."""
    out = Path(out)
    if out.suffix.lower() != ".glb":
        raise UserError(f"--out {str(out)!r}: the export is glTF binary; give a path ending "
                        "in .glb")
    return out


def export_environment(env: Environment, out: str | Path,
                       materials: Mapping[str, Material] | None = None,
                       light: Lighting | None = None) -> tuple[Path, Path]:
    """Write ``out`` (.glb) and scene.json beside it; both atomically. With ``materials`` (the
    dressing) and ``light`` (the environment's sun, sky and exposure) the export is the scene
    as glsynth renders it; without, flat colours per component and no light."""
    out = glb_path(out)
    data = gltf_binary(env.parts, materials or preview_materials(env.parts),
                       None if light is None else light.sun_direction,
                       1.0 if light is None else light.sun_irradiance)
    atomic_write_bytes(out, data)
    json_path = out.with_name("scene.json")
    info = describe(env)
    info["materials"] = "dressed" if materials else "flat colours per component"
    if light is not None:
        info["lighting"] = describe_lighting(light)
    atomic_write_json(json_path, info)
    return out, json_path
