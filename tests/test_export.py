import json
import shutil
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest
import trimesh

from glsynth.render.export import export_environment

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
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, issues["messages"][:5]


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
