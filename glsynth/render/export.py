"""Environment export: glTF binary (one node per part) and a scene.json description.

glTF is y-up; glsynth is z-up (as Blender, whose camera Euler angles the paper uses). Each node's
transform therefore includes the rotation (x, y, z) -> (x, z, -y). scene.json keeps glsynth's
z-up world coordinates and says so.
"""

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np
import trimesh
from trimesh.visual import TextureVisuals
from trimesh.visual.material import PBRMaterial

from glsynth.core.errors import UserError
from glsynth.core.fileio import atomic_write_bytes, atomic_write_json
from glsynth.core.labels import Component
from glsynth.world.environment import Environment

Z_UP_TO_Y_UP = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]], dtype=float)

# Flat preview colours so that a glTF viewer shows the components apart (not the PBR materials).
_PREVIEW_RGBA = {
    Component.NONBRIDGE: (0.45, 0.55, 0.35, 1.0),
    Component.SLAB: (0.75, 0.75, 0.72, 1.0),
    Component.BEAM: (0.65, 0.62, 0.58, 1.0),
    Component.COLUMN: (0.82, 0.80, 0.76, 1.0),
    Component.NONSTRUCTURAL: (0.30, 0.45, 0.70, 1.0),
    Component.RAIL: (0.35, 0.33, 0.32, 1.0),
    Component.SLEEPER: (0.55, 0.42, 0.30, 1.0),
}


def to_gltf_scene(env: Environment) -> trimesh.Scene:
    scene = trimesh.Scene()
    for part in env.parts:
        mesh = part.mesh.copy()
        material = PBRMaterial(name=part.component.name.lower(),
                               baseColorFactor=_PREVIEW_RGBA[part.component],
                               metallicFactor=0.0, roughnessFactor=1.0)
        mesh.visual = TextureVisuals(uv=part.mesh.visual.uv, material=material)
        scene.add_geometry(mesh, node_name=part.name, geom_name=part.name,
                           transform=Z_UP_TO_Y_UP @ part.pose)
    return scene


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


def export_environment(env: Environment, out: str | Path) -> tuple[Path, Path]:
    """Write ``out`` (.glb) and scene.json beside it; both atomically."""
    out = Path(out)
    if out.suffix.lower() != ".glb":
        raise UserError(f"--out {str(out)!r}: the export is glTF binary; give a path ending "
                        "in .glb")
    data = to_gltf_scene(env).export(file_type="glb", include_normals=True)
    atomic_write_bytes(out, data)
    json_path = out.with_name("scene.json")
    atomic_write_json(json_path, describe(env))
    return out, json_path
