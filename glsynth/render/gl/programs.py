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


def variant(base: str, cracks: bool, spall: bool, detail: bool = False) -> str:
    """The name of program ``base`` ("color" or "labels") with crack, zone and concrete detail
    code as asked."""
    return base + "_cracks" * cracks + "_spall" * spall + "_detail" * detail


_VARIANT_MACROS = {"color": ("CRACKS", "SPALL", "DETAIL"), "labels": ("CRACKS", "SPALL")}
"""The macros each program has variants for (the labels have no concrete detail)."""
VARIANTS = {variant(base, *(m in chosen for m in ("CRACKS", "SPALL", "DETAIL"))): (base, chosen)
            for base, macros in _VARIANT_MACROS.items()
            for chosen in (tuple(m for i, m in enumerate(macros) if bits >> i & 1)
                           for bits in range(1, 1 << len(macros)))}
"""Variant name -> (program, the macros it defines): compile-time variants, so that draws
without cracks, damage zones or concrete detail run the programs without any of that code."""
_INCLUDE = re.compile(r'^#include "([\w.]+)"$', re.MULTILINE)


@cache
def shader_source(name: str) -> str:
    """A shader file with each ``#include "file"`` line replaced by that file (GLSL has no
    includes; this keeps shared functions, such as the tone map, in one file)."""
    path = shader_dir() / name
    if not path.is_file():
        raise FileNotFoundError(f"shader {name!r} is missing from glsynth.shaders")
    return _INCLUDE.sub(lambda m: shader_source(m.group(1)), path.read_text(encoding="utf-8"))


def with_define(source: str, *macros: str) -> str:
    """``source`` with ``#define macro`` for each of ``macros`` after its #version line (which
    must come first)."""
    version, rest = source.split("\n", 1)
    defines = "".join(f"#define {macro}\n" for macro in macros)
    return f"{version}\n{defines}{rest}"


def compile_programs(ctx: moderngl.Context) -> dict[str, moderngl.Program]:
    """Compile every program and variant for one context (a GLSL error names the files that
    failed)."""
    builds = {name: (vert, frag, ()) for name, (vert, frag) in PROGRAMS.items()}
    builds |= {name: (*PROGRAMS[base], macros) for name, (base, macros) in VARIANTS.items()}
    programs = {}
    for name, (vert, frag, macros) in builds.items():
        sources = [shader_source(vert), shader_source(frag)]
        if macros:
            sources = [with_define(source, *macros) for source in sources]
        try:
            programs[name] = ctx.program(vertex_shader=sources[0], fragment_shader=sources[1])
        except moderngl.Error as err:
            raise RuntimeError(f"GLSL program {name!r} ({vert} + {frag}) failed: {err}") from err
    return programs
