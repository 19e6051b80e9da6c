"""The scene graph: a pyrender Scene holding every part as a named mesh node with its pose and
metallic-roughness material. Nothing here touches GL; glsynth.gl draws it.

pyrender 0.1.45 is pinned and used only as the scene graph (Scene, Node, Mesh, Primitive,
MetallicRoughnessMaterial, Texture). Its renderer is not used (glsynth.gl draws faster and
exactly, see the README), and its bounds/centroid helpers use np.infty, which numpy 2 removed:
glsynth never calls them.
"""

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pyrender

from glsynth.environment import Environment, Part
from glsynth.labels import Component
from glsynth.materials import Material, plain_material


@dataclass(frozen=True)
class PartLabel:
    """What the label pass needs beyond the pyrender node."""

    component: Component
    damage_mask: np.ndarray | None


@dataclass(frozen=True)
class RenderScene:
    scene: pyrender.Scene
    labels: Mapping[str, PartLabel]
    """By node name."""


def _texture(array: np.ndarray | None, *, srgb: bool = False) -> pyrender.Texture | None:
    if array is None:
        return None
    sampler = pyrender.Sampler(magFilter=0x2601, minFilter=0x2703)  # linear, trilinear mipmaps
    return pyrender.Texture(source=array, source_channels="RGB", sampler=sampler)


def pyrender_material(material: Material) -> pyrender.MetallicRoughnessMaterial:
    return pyrender.MetallicRoughnessMaterial(
        baseColorFactor=material.base_color, metallicFactor=material.metallic,
        roughnessFactor=material.roughness, emissiveFactor=material.emissive,
        baseColorTexture=_texture(material.base_color_map),
        metallicRoughnessTexture=_texture(material.metallic_roughness_map),
        emissiveTexture=_texture(material.emissive_map),
        normalTexture=_texture(material.normal_map))


def part_node(part: Part, material: Material) -> pyrender.Node:
    mesh = part.mesh
    primitive = pyrender.Primitive(
        positions=mesh.vertices.astype(np.float32),
        normals=mesh.vertex_normals.astype(np.float32),
        texcoord_0=(mesh.visual.uv * material.uv_scale).astype(np.float32),
        indices=mesh.faces.astype(np.uint32), material=pyrender_material(material))
    return pyrender.Node(name=part.name, mesh=pyrender.Mesh([primitive], name=part.name),
                         matrix=part.pose)


def default_materials(env: Environment) -> dict[str, Material]:
    return {p.name: plain_material(p.component, emissive=p.name.startswith("scene"))
            for p in env.parts}


def build_scene(parts: list[Part] | tuple[Part, ...], materials: Mapping[str, Material]
                ) -> RenderScene:
    """A pyrender Scene of ``parts``; each part needs a material under its name."""
    scene = pyrender.Scene()
    labels = {}
    for part in parts:
        if part.name not in materials:
            raise ValueError(f"part {part.name!r} has no material")
        material = materials[part.name]
        scene.add_node(part_node(part, material))
        labels[part.name] = PartLabel(part.component, material.damage_mask)
    return RenderScene(scene, labels)
