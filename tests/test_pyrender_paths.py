"""The parts of pyrender 0.1.45 (pinned, unmaintained) that glsynth relies on: the scene graph
only. These keep working on our numpy; its renderer and bounds helpers are never called."""

import numpy as np
import pyrender
import pytest
from glhelpers import quad

from glsynth.appearance.materials import plain_material
from glsynth.core.labels import Component
from glsynth.render.scene import build_scene
from glsynth.world.environment import Part, PartKind


def test_pinned_version():
    from importlib.metadata import version

    assert version("pyrender") == "0.1.45"


def test_scene_graph_keeps_names_poses_and_vertex_data():
    pose = np.eye(4)
    pose[:3, 3] = (1.0, 2.0, 3.0)
    mesh = quad([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]])
    material = plain_material(Component.SLAB)
    scene = build_scene([Part("slab_0", PartKind.SLAB, None, mesh, pose)],
                        {"slab_0": material})
    assert isinstance(scene.scene, pyrender.Scene)
    (node,) = scene.scene.mesh_nodes
    assert node.name == "slab_0"
    assert np.array_equal(scene.scene.get_pose(node), pose)
    (primitive,) = node.mesh.primitives
    assert primitive.positions.dtype == np.float32
    assert np.array_equal(primitive.positions, mesh.vertices.astype(np.float32))
    assert np.allclose(primitive.normals, [0, 0, 1])
    assert np.array_equal(primitive.texcoord_0, mesh.visual.uv.astype(np.float32))
    assert np.array_equal(primitive.indices.reshape(-1, 3), mesh.faces)
    assert primitive.material.metallicFactor == pytest.approx(material.metallic)
    assert scene.parts["slab_0"].component == Component.SLAB


def test_a_part_without_material_is_an_error():
    mesh = quad([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    with pytest.raises(ValueError, match="has no material"):
        build_scene([Part("beam_0", PartKind.CROSS_BEAM, None, mesh, np.eye(4))], {})
