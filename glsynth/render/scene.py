"""The scene graph: a pyrender Scene holding every part as a named mesh node with its pose and
metallic-roughness material. Nothing here touches GL; glsynth.render.gl draws it.

pyrender 0.1.45 is pinned and used only as the scene graph (Scene, Node, Mesh, Primitive,
MetallicRoughnessMaterial with its factors). Its renderer is not used (glsynth.render.gl draws
faster and exactly, see the README), and its bounds/centroid helpers use np.infty, which numpy 2
removed: glsynth never calls them. Texture maps stay in glsynth's Material beside the node:
pyrender.Texture copies and converts every source array on construction, which cost seconds
per environment and defeated sharing one repository image between parts.
"""

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pyrender

from glsynth.appearance.materials import Material, factors
from glsynth.core.labels import Component
from glsynth.world.environment import Part


@dataclass(frozen=True)
class PartInfo:
    """What the passes need beyond the pyrender node: component id and the material's factors
    (without its maps where the material is deferred)."""

    component: Component
    material: Material


@dataclass(frozen=True)
class RenderScene:
    scene: pyrender.Scene
    parts: Mapping[str, PartInfo]
    """By node name."""
    materials: Mapping[str, Material]
    """The full materials by node name, for the uploads (deferred ones are built there)."""


def pyrender_material(material: Material) -> pyrender.MetallicRoughnessMaterial:
    """The material's factors, for anyone viewing the scene graph with pyrender itself."""
    return pyrender.MetallicRoughnessMaterial(
        baseColorFactor=material.base_color, metallicFactor=material.metallic,
        roughnessFactor=material.roughness, emissiveFactor=material.emissive)


def part_node(part: Part, material: Material) -> pyrender.Node:
    mesh = part.mesh
    primitive = pyrender.Primitive(
        positions=mesh.vertices.astype(np.float32),
        normals=mesh.vertex_normals.astype(np.float32),
        texcoord_0=(mesh.visual.uv * material.uv_scale).astype(np.float32),
        indices=mesh.faces.astype(np.uint32), material=pyrender_material(material))
    return pyrender.Node(name=part.name, mesh=pyrender.Mesh([primitive], name=part.name),
                         matrix=part.pose)


def build_scene(parts: list[Part] | tuple[Part, ...], materials: Mapping[str, Material]
                ) -> RenderScene:
    """A pyrender Scene of ``parts``; each part needs a material under its name. No deferred
    material is built here."""
    scene = pyrender.Scene()
    infos = {}
    for part in parts:
        if part.name not in materials:
            raise ValueError(f"part {part.name!r} has no material")
        material = factors(materials, part.name)
        scene.add_node(part_node(part, material))
        infos[part.name] = PartInfo(part.component, material)
    return RenderScene(scene, infos, materials)
