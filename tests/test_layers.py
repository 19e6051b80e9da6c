"""The package's layers (docs/design.md): every import points down or stays in its folder;
OpenGL only in glsynth.render.gl, torch only in model/, the ray cast independent of GL."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LAYERS = ["core", "world", "appearance", "render", "data", "assess", "measure", "view", "model",
          "cli"]


def _modules() -> dict[str, Path]:
    found = {f"glsynth.{p.relative_to(ROOT / 'glsynth').with_suffix('').as_posix()}"
             .replace("/", ".").removesuffix(".__init__"): p
             for p in (ROOT / "glsynth").rglob("*.py")}
    found.update({f"glsynth.model.{p.stem}".removesuffix(".__init__"): p
                  for p in (ROOT / "model").glob("*.py")})
    return found


def _imports(path: Path) -> set[str]:
    """Every module named in an import statement, at any depth (lazy imports count too)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
    return names


def _layer(module: str) -> str:
    """The layer of a module; the entry point (glsynth.__main__) is the command line's."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] != "__main__" else "cli"


@pytest.fixture(scope="module")
def modules() -> dict[str, set[str]]:
    """Each module's imports; parsed when this file runs, not when every worker collects it."""
    return {name: _imports(path) for name, path in _modules().items()}


def test_every_import_points_down_the_layers(modules):
    wrong = []
    for module, imports in modules.items():
        if module == "glsynth":
            continue
        own = LAYERS.index(_layer(module))
        for name in imports:
            if name.startswith("glsynth.") and LAYERS.index(_layer(name)) > own:
                wrong.append(f"{module} imports {name}")
    assert not wrong, wrong


def test_opengl_only_in_render_gl_and_torch_only_in_model(modules):
    for module, imports in modules.items():
        roots = {name.split(".")[0] for name in imports}
        if roots & {"moderngl", "glcontext", "OpenGL"}:
            assert module.startswith("glsynth.render.gl"), module
        if "torch" in roots:
            assert module.startswith("glsynth.model"), module


def test_the_ray_cast_does_not_depend_on_the_renderer_it_checks(modules):
    imports = modules["glsynth.render.raycast"]
    assert not any(name.startswith("glsynth.render.gl") for name in imports)


def test_the_model_settings_import_no_torch(modules):
    """The command line builds its train options from them without loading torch."""
    assert not {n.split(".")[0] for n in modules["glsynth.model.settings"]} & {"torch"}


def test_the_command_line_starts_without_torch_or_gl():
    """Generating data never needs torch; --help needs no GL."""
    import subprocess
    import sys

    code = ("import sys, glsynth.cli; glsynth.cli.build_parser(); "
            "print(sorted(m for m in ('torch', 'moderngl') if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)
    assert done.stdout.strip() == "[]"
