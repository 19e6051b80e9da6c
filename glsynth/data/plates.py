"""Pure-texture plate images (paper Section 3.4): a damage texture from the bank applied to a
plate without additional scaling, the plate rotated at random and photographed from a random
distance. Only the plate is built (nothing else is in the scene).

Plate N draws from make_rng(root_seed, 0, PLATES, N): severity, bank index, in-plane rotation
U[0, 2pi), tilt about a random in-plane axis U[0, max_tilt], focal length from the camera range,
and a distance U[near, far] x the distance at which the plate would just span the image width.
Its sun and sky are drawn like an environment's (glsynth.world.lighting, env 0, item N + 1).
"""

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import trimesh
from trimesh.visual import TextureVisuals

from glsynth.appearance.damage import SEVERITIES
from glsynth.appearance.damage_bank import DamageBank, damage_material
from glsynth.appearance.materials import Material
from glsynth.appearance.repository import TextureRepository
from glsynth.core.config import Config
from glsynth.core.seeding import Stream, make_rng
from glsynth.render.scene import RenderScene, build_scene
from glsynth.world.cameras import Camera
from glsynth.world.environment import Part, PartKind
from glsynth.world.lighting import Lighting, environment_lighting

MAX_TILT = math.radians(35.0)
DISTANCE_RANGE = (0.4, 1.0)
"""As a fraction of the distance at which the plate spans the image width: below 1 the plate
overfills the view, so rotated corners rarely show the background."""


@dataclass(frozen=True)
class PlateShot:
    index: int
    scene: RenderScene
    camera: Camera
    lighting: Lighting
    part: Part
    material: Material
    meta: dict


def plate_mesh(size_m: float) -> trimesh.Trimesh:
    """A square plate in the z = 0 plane facing +z, UVs [0, 1] over it (the texture exactly
    once: no additional scaling), v up."""
    h = size_m / 2
    mesh = trimesh.Trimesh([[-h, -h, 0], [h, -h, 0], [h, h, 0], [-h, h, 0]],
                           [[0, 1, 2], [0, 2, 3]], process=False)
    mesh.visual = TextureVisuals(uv=np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float))
    return mesh


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = axis / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def plate_shot(config: Config, root_seed: int, index: int, repository: TextureRepository,
               bank: DamageBank) -> PlateShot:
    rng = make_rng(root_seed, 0, Stream.PLATES, index)
    severity = SEVERITIES[int(rng.integers(len(SEVERITIES)))]
    bank_index = int(rng.integers(config.damage.bank_size))
    spin = rng.uniform(0.0, 2 * math.pi)
    tilt_axis_angle = rng.uniform(0.0, 2 * math.pi)
    tilt = rng.uniform(0.0, MAX_TILT)
    focal = rng.uniform(*config.cameras.focal_mm)
    fraction = rng.uniform(*DISTANCE_RANGE)

    entry = bank.entry(severity, bank_index, repository)
    size = config.damage.tile_m
    # The plate's UVs span [0, 1] over tile_m metres: scale tile_m gives uv_scale 1, the
    # texture exactly once.
    material = damage_material(entry, repository, config.damage, scale=size)
    pose = np.eye(4)
    tilt_axis = np.array([math.cos(tilt_axis_angle), math.sin(tilt_axis_angle), 0.0])
    pose[:3, :3] = _rotation(tilt_axis, tilt) @ _rotation(np.array([0.0, 0, 1]), spin)
    part = Part("column_plate", PartKind.COLUMN, None, plate_mesh(size), pose)
    scene = build_scene([part], {part.name: material})

    render = config.render
    fx = focal / config.cameras.sensor_mm * render.width
    distance = fraction * size * fx / render.width
    cam_pose = np.eye(4)
    cam_pose[2, 3] = distance  # on the plate's axis, looking down -z at its centre
    camera = Camera(render.width, render.height, float(focal), config.cameras.sensor_mm,
                    cam_pose, render.znear_m, render.zfar_m)
    meta = {"plate_index": index, "severity": severity, "bank_index": bank_index,
            "spin_rad": spin, "tilt_rad": tilt, "tilt_axis_rad": tilt_axis_angle,
            "focal_mm": float(focal), "distance_m": distance,
            "damage_params": dataclasses.asdict(entry.params), "images": list(entry.images)}
    lighting = environment_lighting(config.lighting, root_seed, 0, index + 1)
    return PlateShot(index, scene, camera, lighting, part, material, meta)
