import shutil
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
    # Built from a copy of the sources: setuptools writes build/ and *.egg-info beside the
    # project, and a stale build/lib in the checkout could hide a deleted file.
    source = tmp_path / "src"
    shutil.copytree(ROOT, source, ignore=shutil.ignore_patterns(
        ".git", ".venv", ".tools", "build", "out", "*.egg-info", "__pycache__", ".pytest_cache"))
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
                    "-q", "-w", str(tmp_path), str(source)], check=True, capture_output=True)
    wheel = next(tmp_path.glob("glsynth-*.whl"))
    names = set(zipfile.ZipFile(wheel).namelist())
    modules = {f"glsynth/{p.relative_to(ROOT / 'glsynth').as_posix()}"
               for p in (ROOT / "glsynth").rglob("*.py")}
    assert modules <= names, f"modules missing from the wheel: {sorted(modules - names)}"
    for required in ("glsynth/shaders/__init__.py", "glsynth/textures/__init__.py",
                     "glsynth/model/__init__.py", "glsynth/cli.py",
                     "glsynth/view/static/index.html", "glsynth/view/static/viewer.js"):
        assert required in names
    shader_sources = {p.name for p in (ROOT / "shaders").iterdir()
                      if p.suffix in {".vert", ".frag", ".glsl"}}
    assert {f"glsynth/shaders/{n}" for n in shader_sources} <= names
    assert not any(n.startswith(("tests/", "bench/")) for n in names)
