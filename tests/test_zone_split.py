"""The hinge zones in the glTF export and the Cycles twin (glsynth.render.zone_split): the
damage material, its mask and relief, only on the mesh's pieces inside the zones; intact
concrete outside, as the GL zone variants draw it (tests/test_spalling.py)."""

import json
import shutil
import struct

import numpy as np
import pytest
from glhelpers import LIGHT
from test_spalling import HEIGHT, SECTION, heights, side_camera, spalled

from glsynth.core.labels import Component
from glsynth.render.cycles import render_linear
from glsynth.render.gltf import gltf_binary
from glsynth.render.zone_split import zone_pieces
from glsynth.world.environment import Part, PartKind
from glsynth.world.meshes import box

ZONES = ((-2.0, -1.4), (-1.4, -0.9), (0.3, 0.8), (1.2, 2.0))
"""Four spans' zones, two of them touching."""
INSIDE = ((-2.0, -0.9), (0.3, 0.8), (1.2, 2.0))


def _glb(data: bytes) -> tuple[dict, bytes]:
    length = struct.unpack("<I", data[12:16])[0]
    return json.loads(data[20:20 + length]), data[20 + length + 8:]


def _positions(gltf: dict, binary: bytes, accessor: int) -> np.ndarray:
    a = gltf["accessors"][accessor]
    v = gltf["bufferViews"][a["bufferView"]]
    start = v.get("byteOffset", 0)
    return np.frombuffer(binary[start:start + v["byteLength"]], np.float32).reshape(-1, 3)


def within(z: np.ndarray, intervals, tol: float = 1e-6) -> np.ndarray:
    return np.any([(z >= z0 - tol) & (z <= z1 + tol) for z0, z1 in intervals], axis=0)


def face_points(mesh, normal) -> tuple[np.ndarray, np.ndarray]:
    """Positions and UVs of the corners of ``mesh``'s faces facing ``normal``."""
    faces = mesh.faces[np.all(np.isclose(mesh.face_normals, normal), axis=1)].ravel()
    return mesh.vertices[faces], mesh.visual.uv[faces]


def test_pieces_cover_the_mesh_once_split_at_the_zones_ends():
    mesh = box((*SECTION, HEIGHT))
    material, _ = spalled(0, "severe", ZONES)
    inside, outside = zone_pieces(mesh, material.zones)
    assert len(inside) == 3 and len(outside) == 2  # the zones reach both ends
    assert sum(p.area for p in inside + outside) == pytest.approx(mesh.area, rel=1e-9)
    lateral = 2 * (SECTION[0] + SECTION[1])
    caps = 2 * SECTION[0] * SECTION[1]  # both ends lie in zones
    assert sum(p.area for p in inside) == pytest.approx(lateral * 2.4 + caps, rel=1e-9)
    for piece in inside:
        assert within(piece.vertices[:, 2], INSIDE).all()
    gaps = ((-0.9, 0.3), (0.8, 1.2))
    for piece in outside:
        assert within(piece.vertices[:, 2], gaps).all()
    # UVs carry on across a cut: on each lateral face the box's UVs are affine in the
    # position, and the pieces' UVs follow the same map.
    for normal in ([1.0, 0, 0], [0, 1.0, 0], [-1.0, 0, 0], [0, -1.0, 0]):
        xyz, uv = face_points(mesh, normal)
        affine = np.linalg.lstsq(np.c_[xyz, np.ones(len(xyz))], uv, rcond=None)[0]
        for piece in inside + outside:
            xyz, uv = face_points(piece, normal)
            assert len(xyz) and np.allclose(np.c_[xyz, np.ones(len(xyz))] @ affine, uv)


def test_the_glb_confines_the_damage_material_to_the_zones():
    material, _ = spalled(1, "medium", ZONES)
    part = Part("column", PartKind.COLUMN, None, box((*SECTION, HEIGHT)), np.eye(4))
    gltf, binary = _glb(gltf_binary([part], {"column": material}))
    (mesh,) = gltf["meshes"]
    damaged, intact = [], []
    for primitive in mesh["primitives"]:
        m = gltf["materials"][primitive["material"]]
        z = _positions(gltf, binary, primitive["attributes"]["POSITION"])[:, 2]
        if "extras" in m:  # the damage mask travels with the damage material only
            assert "normalTexture" in m and "metallicRoughnessTexture" in m["pbrMetallicRoughness"]
            damaged.append(z)
        else:
            assert "normalTexture" not in m and m["pbrMetallicRoughness"]["metallicFactor"] == 0
            assert "TANGENT" not in primitive["attributes"]
            intact.append(z)
    assert len(damaged) == 3 and len(intact) == 2
    assert within(np.concatenate(damaged), INSIDE, 1e-5).all()
    z = np.concatenate(intact)
    assert not np.any([(z > z0 + 1e-5) & (z < z1 - 1e-5) for z0, z1 in INSIDE])


BLENDER = shutil.which("blender")


@pytest.mark.slow
@pytest.mark.skipif(BLENDER is None, reason="Blender is not installed")
def test_the_cycles_twin_shows_spalling_only_in_the_zones(tmp_path):
    """The twin of a spalled column against the twin of its intact concrete: outside the
    zones the same light (one seed: the same samples), inside them the damage."""
    material, concrete = spalled(2, "severe", ZONES)
    part = Part("column", PartKind.COLUMN, None, box((*SECTION, HEIGHT)), np.eye(4))
    cam = side_camera()
    out = {name: render_linear([part], {"column": m}, LIGHT, [cam], [3], 16,
                               tmp_path / name, BLENDER).linear[0]
           for name, m in (("spalled", material), ("concrete", concrete))}
    from glsynth.render.raycast import ray_cast
    truth = ray_cast([part], {"column": material}, cam)
    z = heights(cam, truth.depth)
    hit = truth.component == Component.COLUMN
    margin = 0.05
    near = np.any([np.abs(z - e) < margin for zone in ZONES for e in zone], axis=0)
    inside = within(z, INSIDE, 0.0)
    change = np.abs(out["spalled"] - out["concrete"]).max(2)
    outside = hit & ~inside & ~near
    # Outside: the same light but what the spalled zones bounce onto it (1e-4 of it).
    level = out["concrete"][hit].max()
    assert outside.sum() > 1000 and change[outside].max() <= 1e-3 * level
    assert change[hit & inside & ~near].mean() > 0.02 * level
