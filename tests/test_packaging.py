import subprocess
import sys
import zipfile
from importlib import resources
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_installed_package_finds_mapped_folders():
    for name in ("glsynth.shaders", "glsynth.textures", "glsynth.model"):
        assert resources.files(name).joinpath("__init__.py").is_file()


def test_wheel_maps_shaders_textures_and_model(tmp_path):
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
                    "-q", "-w", str(tmp_path), str(ROOT)], check=True, capture_output=True)
    wheel = next(tmp_path.glob("glsynth-*.whl"))
    names = set(zipfile.ZipFile(wheel).namelist())
    for required in ("glsynth/shaders/__init__.py", "glsynth/textures/__init__.py",
                     "glsynth/model/__init__.py", "glsynth/cli.py"):
        assert required in names
    shader_sources = {p.name for p in (ROOT / "shaders").iterdir()
                      if p.suffix in {".vert", ".frag", ".glsl"}}
    assert {f"glsynth/shaders/{n}" for n in shader_sources} <= names
    assert not any(n.startswith(("tests/", "bench/")) for n in names)
