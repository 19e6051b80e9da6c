"""GLSL programs from the shader files in glsynth.shaders (the top-level shaders/ folder)."""

import re
from functools import cache

import moderngl

from glsynth.core.paths import shader_dir

# Program name -> (vertex shader file, fragment shader file).
PROGRAMS = {"color": ("mesh.vert", "color.frag"), "labels": ("mesh.vert", "labels.frag"),
            "msaa": ("mesh.vert", "msaa.frag"),
            "msaa_interior": ("fullscreen.vert", "msaa_interior.frag"),
            "msaa_resolve": ("fullscreen.vert", "msaa_resolve.frag"),
            "sky_visibility": ("mesh.vert", "sky_visibility.frag"),
            "shadow": ("shadow.vert", "shadow.frag"), "sky": ("fullscreen.vert", "sky.frag"),
            "ssao": ("fullscreen.vert", "ssao.frag"),
            "ssao_blur": ("fullscreen.vert", "ssao_blur.frag")}
_INCLUDE = re.compile(r'^#include "([\w.]+)"$', re.MULTILINE)


@cache
def shader_source(name: str) -> str:
    """A shader file with each ``#include "file"`` line replaced by that file (GLSL has no
    includes; this keeps shared functions, such as the tone map, in one file)."""
    path = shader_dir() / name
    if not path.is_file():
        raise FileNotFoundError(f"shader {name!r} is missing from glsynth.shaders")
    return _INCLUDE.sub(lambda m: shader_source(m.group(1)), path.read_text(encoding="utf-8"))


def compile_programs(ctx: moderngl.Context) -> dict[str, moderngl.Program]:
    """Compile every program for one context (a GLSL error names the file that failed)."""
    programs = {}
    for name, (vert, frag) in PROGRAMS.items():
        try:
            programs[name] = ctx.program(vertex_shader=shader_source(vert),
                                         fragment_shader=shader_source(frag))
        except moderngl.Error as err:
            raise RuntimeError(f"GLSL program {name!r} ({vert} + {frag}) failed: {err}") from err
    return programs
