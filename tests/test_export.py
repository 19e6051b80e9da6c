import io
import json
import shutil
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest
import trimesh

from glsynth.render.export import export_environment
from glsynth.render.tonemap import TONE_MAP_FORMULA

ROOT = Path(__file__).resolve().parents[1]
VALIDATOR = ROOT / ".tools" / "node_modules" / "gltf-validator"


@pytest.fixture(scope="module")
def exported(env0, tmp_path_factory):
    out = tmp_path_factory.mktemp("export") / "scene.glb"
    export_environment(env0, out)
    return env0, out


def test_glb_container_and_nodes(exported):
    env, glb = exported
    data = glb.read_bytes()
    magic, version, length = struct.unpack("<4sII", data[:12])
    assert (magic, version, length) == (b"glTF", 2, len(data))
    chunk_len, chunk_type = struct.unpack("<II", data[12:20])
    assert chunk_type == 0x4E4F534A  # JSON
    gltf = json.loads(data[20:20 + chunk_len])
    node_names = [n["name"] for n in gltf["nodes"] if "mesh" in n]
    assert sorted(node_names) == sorted(p.name for p in env.parts)
    first = gltf["meshes"][0]["primitives"][0]["attributes"]
    assert {"POSITION", "NORMAL", "TEXCOORD_0"} <= set(first)


def test_glb_reloads_with_the_same_geometry_in_y_up(exported):
    env, glb = exported
    scene = trimesh.load(glb, process=False)
    for part in env.parts[::17]:
        transform, geometry = scene.graph[part.name]
        loaded = trimesh.transform_points(scene.geometry[geometry].vertices, transform)
        world = part.world_vertices()
        # glTF is y-up: (x, y, z) -> (x, z, -y); vertices are stored as float32.
        expected = np.stack([world[:, 0], world[:, 2], -world[:, 1]], axis=1)
        assert np.allclose(loaded, expected, atol=1e-4), part.name


@pytest.mark.skipif(shutil.which("node") is None or not VALIDATOR.exists(),
                    reason="Khronos glTF validator not installed (scripts/setup.sh installs it "
                           "when npm is available)")
def test_khronos_validator_reports_no_errors_or_warnings(exported):
    _, glb = exported
    script = ("const v=require(process.argv[1]);const d=new Uint8Array(require('fs')"
              ".readFileSync(process.argv[2]));v.validateBytes(d).then(r=>console.log("
              "JSON.stringify(r.issues)))")
    out = subprocess.run(["node", "-e", script, str(VALIDATOR), str(glb)], check=True,
                         capture_output=True, text=True).stdout
    issues = json.loads(out)
    serious = [m for m in issues["messages"] if m["severity"] < 2]
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, serious[:5]


def test_scene_json_describes_every_viaduct(exported):
    env, glb = exported
    info = json.loads((glb.parent / "scene.json").read_text())  # strict JSON: no Infinity
    assert info["root_seed"] == 0 and info["env"] == 0
    assert len(info["viaducts"]) == len(env.viaducts)
    for v, vi in zip(info["viaducts"], env.viaducts):
        assert v["height_m"] == vi.height_m
        assert v["straight"] == (vi.radius_m > 5000)
        assert (v["radius_m"] is None) == (not np.isfinite(vi.radius_m))
        assert v["column_cm"] == list(vi.sections.column_cm)
        assert (v["intermediate_beam_cm"] is None) == (vi.height_m <= 10.0)
        footprint = np.array(v["footprint_xy_m"])
        assert footprint.shape[1] == 2 and len(footprint) >= 4
        for col in v["columns"]:  # columns stand inside the deck outline
            assert _inside(col["center_xy_m"], footprint)
    assert {p["name"] for p in info["parts"]} == {p.name for p in env.parts}
    assert not list(glb.parent.glob(".*tmp"))


def test_straight_radius_is_null_in_json(tmp_path):
    from conftest import env_config

    from glsynth.world.environment import build_environment
    env = build_environment(env_config(min_radius_m=(float("inf"), float("inf"))), 0, 0)
    export_environment(env, tmp_path / "s.glb")
    info = json.loads((tmp_path / "scene.json").read_text())
    assert all(v["radius_m"] is None and v["straight"] for v in info["viaducts"])
    assert info["trajectory"]["min_radius_m"] is None


def test_export_path_must_be_glb(env0, tmp_path):
    with pytest.raises(ValueError, match=r"ending in \.glb"):
        export_environment(env0, tmp_path / "scene.gltf")


def _inside(point, polygon) -> bool:
    from matplotlib.path import Path as MplPath
    return bool(MplPath(polygon).contains_point(point))


# --- the dressed export: the scene as glsynth renders it ------------------------------------
def _glb_parts(data: bytes) -> tuple[dict, bytes]:
    chunk_len = struct.unpack("<I", data[12:16])[0]
    gltf = json.loads(data[20:20 + chunk_len])
    binary = data[20 + chunk_len + 8:]
    return gltf, binary


def _view_bytes(gltf: dict, binary: bytes, view: int) -> bytes:
    v = gltf["bufferViews"][view]
    return binary[v.get("byteOffset", 0):v.get("byteOffset", 0) + v["byteLength"]]


def _accessor(gltf: dict, binary: bytes, index: int) -> np.ndarray:
    a = gltf["accessors"][index]
    width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[a["type"]]
    dtype = np.uint32 if a["componentType"] == 5125 else np.float32
    return np.frombuffer(_view_bytes(gltf, binary, a["bufferView"]), dtype).reshape(-1, width)


@pytest.fixture(scope="module")
def dressed(tmp_path_factory):
    import dataclasses

    from glsynth.appearance.damage_bank import DamageBank
    from glsynth.appearance.dressing import dress, open_repository
    from glsynth.core.config import load_config
    from glsynth.world.environment import build_environment

    config = load_config("demo")
    config = dataclasses.replace(
        config, damage=dataclasses.replace(config.damage, resolution=64),
        materials=dataclasses.replace(config.materials, texture_size=32))
    env = build_environment(config, 0, 0)
    dressing = dress(env, config, open_repository(config), DamageBank(config.damage, 0),
                     {p.name for p in env.parts})
    out = tmp_path_factory.mktemp("dressed") / "scene.glb"
    from glsynth.world.lighting import environment_lighting

    export_environment(env, out, dressing.materials, environment_lighting(config.lighting, 0, 0))
    return env, dressing.materials, config, out


def test_dressed_export_round_trips_every_texture(dressed):
    from PIL import Image

    from glsynth.world.environment import PartKind

    env, materials, _, glb = dressed
    gltf, binary = _glb_parts(glb.read_bytes())
    nodes = {n["name"]: n for n in gltf["nodes"] if "mesh" in n}
    assert set(nodes) == {p.name for p in env.parts}
    # Shared repository images are written once; a deferred (damage) material's maps are its
    # own: built for the export, each written once.
    sources, own = set(), 0
    for name in materials:
        m = materials[name]
        maps = [a for a in (m.base_color_map, m.metallic_map, m.normal_map, m.emissive_map,
                            m.damage_mask) if a is not None]
        if m is materials.factors(name):
            sources |= {id(a) for a in maps}
        else:
            own += len(maps)
    assert own > 0
    assert len(gltf["images"]) == len(sources) + own

    def image(texture: dict) -> np.ndarray:
        source = gltf["textures"][texture["index"]]["source"]
        data = _view_bytes(gltf, binary, gltf["images"][source]["bufferView"])
        return np.asarray(Image.open(io.BytesIO(data)))

    damaged = [p for p in env.parts if materials[p.name].damage_mask is not None]
    assert damaged
    for part in damaged[:3] + [p for p in env.parts if p.kind is PartKind.SLAB][:2]:
        m = materials[part.name]
        node = nodes[part.name]
        assert node["extras"] == {"component": part.component.name.lower(),
                                  "component_id": int(part.component)}
        primitive = gltf["meshes"][node["mesh"]]["primitives"][0]
        mat = gltf["materials"][primitive["material"]]
        pbr = mat["pbrMetallicRoughness"]
        assert np.array_equal(image(pbr["baseColorTexture"]), m.base_color_map)
        assert pbr["metallicFactor"] == m.metallic and pbr["roughnessFactor"] == m.roughness
        assert mat["doubleSided"] is True
        uv = _accessor(gltf, binary, primitive["attributes"]["TEXCOORD_0"])
        if m.zones is None:  # a zoned member is cut at its zones (tests/test_zone_split.py)
            expected = part.mesh.visual.uv * m.uv_scale
            assert np.allclose(uv[:, 0], expected[:, 0], atol=1e-5)
            assert np.allclose(uv[:, 1], 1 - expected[:, 1], atol=1e-5)  # glTF: v from the top
        if m.damage_mask is not None:
            assert np.array_equal(image(mat["extras"]["glsynth_damage_mask"]), m.damage_mask)
            packed = image(pbr["metallicRoughnessTexture"])  # glTF: G roughness, B metallic
            assert np.all(packed[..., 1] == 255)
            assert np.array_equal(packed[..., 2], m.metallic_map)
            assert np.array_equal(image(mat["normalTexture"]), m.normal_map)
            tangent = _accessor(gltf, binary, primitive["attributes"]["TANGENT"])
            normal = _accessor(gltf, binary, primitive["attributes"]["NORMAL"])
            assert np.allclose(np.sum(tangent[:, :3] * normal, axis=1), 0, atol=1e-5)
            assert set(np.unique(tangent[:, 3])) <= {-1.0, 1.0}


def test_dressed_export_carries_the_sun_and_the_sky(dressed):
    from glsynth.world.lighting import environment_lighting

    _, _, config, glb = dressed
    lighting = environment_lighting(config.lighting, 0, 0)  # the environment's own sun
    gltf, _ = _glb_parts(glb.read_bytes())
    (light,) = gltf["extensions"]["KHR_lights_punctual"]["lights"]
    assert light["type"] == "directional" and light["intensity"] == lighting.sun_irradiance
    node = next(n for n in gltf["nodes"] if "extensions" in n)
    x, y, z, w = node["rotation"]
    rotation = np.array([  # quaternion to matrix
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    sun = lighting.sun_direction
    travel_y_up = -np.array([sun[0], sun[2], -sun[1]])
    assert np.allclose(rotation @ [0, 0, -1], travel_y_up, atol=1e-9)
    info = json.loads((glb.parent / "scene.json").read_text())
    assert info["materials"] == "dressed"
    assert info["lighting"]["sky"] == "preetham"
    assert info["lighting"]["preetham_turbidity"] == lighting.turbidity
    assert info["lighting"]["sun_elevation_deg"] == lighting.sun_elevation_deg
    assert info["lighting"]["exposure"] == config.lighting.exposure
    assert info["lighting"]["tone_map_formula"] == TONE_MAP_FORMULA


@pytest.mark.skipif(shutil.which("node") is None or not VALIDATOR.exists(),
                    reason="Khronos glTF validator not installed (scripts/setup.sh installs it "
                           "when npm is available)")
def test_khronos_validator_passes_the_dressed_export(dressed):
    script = ("const v=require(process.argv[1]);const d=new Uint8Array(require('fs')"
              ".readFileSync(process.argv[2]));v.validateBytes(d).then(r=>console.log("
              "JSON.stringify(r.issues)))")
    out = subprocess.run(["node", "-e", script, str(VALIDATOR), str(dressed[3])], check=True,
                         capture_output=True, text=True).stdout
    issues = json.loads(out)
    serious = [m for m in issues["messages"] if m["severity"] < 2]
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, serious[:5]
    # Information only: the damage masks are referenced from extras, which glTF does not read.
    assert {m["code"] for m in issues["messages"]} <= {"UNUSED_OBJECT"}


def test_tangents_follow_u_and_know_their_handedness():
    from glsynth.render.gltf import tangents

    vertices = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    normals = np.tile([0.0, 0.0, 1.0], (4, 1))
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    uv = vertices[:, :2].copy()
    assert np.allclose(tangents(vertices, normals, uv, faces), [[1, 0, 0, 1]] * 4)
    mirrored = uv * [1, -1]  # v runs the other way: left-handed frame
    assert np.allclose(tangents(vertices, normals, mirrored, faces), [[1, 0, 0, -1]] * 4)
    flat = np.zeros((4, 2))  # no u gradient: any unit tangent orthogonal to the normal
    t = tangents(vertices, normals, flat, faces)
    assert np.allclose(np.linalg.norm(t[:, :3], axis=1), 1) and np.allclose(t[:, 2], 0)
