"""GLSL programs from the shader files in glsynth.shaders (the top-level shaders/ folder): their
compile-time variants, the constants they share with Python, and their samplers' texture units.

After pyrender's ShaderProgramCache and ProgramFlags: a program is compiled once per set of
defines, a draw names its variant by Variant flags, and every sampler gets its texture unit
from one TextureUnits when its program is compiled, so no caller counts units by hand."""

import enum
import re
import typing
from collections.abc import Iterator
from functools import cache

import moderngl

from glsynth.appearance.crack_leachate import SHADER_CONSTANTS as LEACH_CONSTANTS
from glsynth.appearance.crack_paths import SHADER_CONSTANTS as CRACK_CONSTANTS
from glsynth.appearance.materials import MAX_ZONES
from glsynth.core.config import RenderConfig
from glsynth.core.paths import shader_dir
from glsynth.render.cracks_index import ROW


class Variant(enum.Flag):
    """The code compiled into a mesh program beyond its plain form, one ``#define`` each (the
    member's name): draws without cracks, damage zones or concrete detail run programs without
    any of that code. GROUND comes only with DETAIL: the ground's detail in place of
    concrete's (the ground has no cracks or damage zones)."""
    NONE = 0
    CRACKS = enum.auto()
    SPALL = enum.auto()
    DETAIL = enum.auto()
    GROUND = enum.auto()

    @classmethod
    def of(cls, cracks: bool = False, spall: bool = False, detail: bool = False,
           ground: bool = False) -> "Variant":
        """The flags of a draw with cracks, damage zones and concrete or ground detail as
        given."""
        if ground:
            return cls.DETAIL | cls.GROUND
        return ((cls.CRACKS if cracks else cls.NONE) | (cls.SPALL if spall else cls.NONE)
                | (cls.DETAIL if detail else cls.NONE))

    def compiled(self) -> bool:
        """Whether a program is compiled with these flags (GROUND only with DETAIL alone)."""
        return Variant.GROUND not in self or self == Variant.DETAIL | Variant.GROUND


PROGRAMS: dict[str, tuple[str, str, Variant]] = {
    "color": ("mesh.vert", "color.frag",
              Variant.CRACKS | Variant.SPALL | Variant.DETAIL | Variant.GROUND),
    "labels": ("mesh.vert", "labels.frag", Variant.CRACKS | Variant.SPALL),
    "msaa": ("mesh.vert", "msaa.frag", Variant.NONE),
    "msaa_interior": ("fullscreen.vert", "msaa_interior.frag", Variant.NONE),
    "msaa_resolve": ("fullscreen.vert", "msaa_resolve.frag", Variant.NONE),
    "sky_visibility": ("mesh.vert", "sky_visibility.frag", Variant.NONE),
    "shadow": ("shadow.vert", "shadow.frag", Variant.NONE),
    "sky": ("fullscreen.vert", "sky.frag", Variant.NONE),
    "ssao": ("fullscreen.vert", "ssao.frag", Variant.NONE),
    "ssao_blur": ("fullscreen.vert", "ssao_blur.frag", Variant.NONE)}
"""Program name -> (vertex shader file, fragment shader file, the variants it has: every
combination of these flags that Variant.compiled allows is compiled)."""

ProgramKey = tuple[str, Variant]
"""(program name, variant): one compiled program."""

MAX_VIS = max(typing.get_args(typing.get_type_hints(RenderConfig)["sky_visibility_maps"]))
"""The most sky-visibility maps a config may ask for: the length of the shaders' arrays."""
GLSL_CONSTANTS = {"MAX_ZONES": MAX_ZONES, "MAX_VIS": MAX_VIS, **CRACK_CONSTANTS,
                  **LEACH_CONSTANTS, "CRACK_ROW_BITS": ROW.bit_length() - 1}
"""Constants that the shaders read as macros, defined in Python only (here and in the modules
they come from)."""

_INCLUDE = re.compile(r'^#include "([\w.]+)"$', re.MULTILINE)
_SAMPLER = re.compile(r"^\s*uniform\s+[iu]?sampler\w*\s+(\w+)\s*;", re.MULTILINE)


def program_keys() -> Iterator[ProgramKey]:
    """Every program and variant, each program's plain form first."""
    for name, (_, _, flags) in PROGRAMS.items():
        members = list(flags)
        for bits in range(1 << len(members)):
            variant = Variant(sum(m.value for i, m in enumerate(members) if bits >> i & 1))
            if variant.compiled():
                yield name, variant


@cache
def shader_source(name: str) -> str:
    """A shader file with each ``#include "file"`` line replaced by that file (GLSL has no
    includes; this keeps shared functions, such as the tone map, in one file). Each included
    file is wrapped in an include guard, so a second inclusion adds nothing."""
    return _expand(name, ())


def _expand(name: str, within: tuple[str, ...]) -> str:
    """File ``name`` with its includes expanded; ``within``: the files that include it."""
    if name in within:
        raise RuntimeError(f"shader {name!r} includes itself through {' -> '.join(within)}")
    path = shader_dir() / name
    if not path.is_file():
        raise FileNotFoundError(f"shader {name!r} is missing from glsynth.shaders")

    def include(match: re.Match) -> str:
        guard = "GLSYNTH_" + re.sub(r"\W", "_", match.group(1)).upper()
        body = _expand(match.group(1), (*within, name))
        return f"#ifndef {guard}\n#define {guard}\n{body.rstrip()}\n#endif"
    return _INCLUDE.sub(include, path.read_text(encoding="utf-8"))


def settings_constants(config: RenderConfig) -> dict[str, int]:
    """Constants that a renderer's settings fix for its programs' life: MSAA_SAMPLES, the
    samples per pixel ([render] msaa), which the resolve's loops then run a known number of
    times: unrolled, with the same bytes and less work on llvmpipe (docs/results.md,
    "Dataset generation")."""
    return {"MSAA_SAMPLES": config.msaa}


def defines(variant: Variant = Variant.NONE, settings: dict[str, int] | None = None) -> str:
    """The ``#define`` lines of the shared constants, of ``settings`` (settings_constants) and
    of ``variant``'s flags."""
    lines = [f"#define {name} {value}\n"
             for name, value in (GLSL_CONSTANTS | (settings or {})).items()]
    return "".join(lines + [f"#define {flag.name}\n" for flag in variant])


def with_defines(source: str, variant: Variant = Variant.NONE,
                 settings: dict[str, int] | None = None) -> str:
    """``source`` with defines(variant, settings) after its #version line (which must come
    first)."""
    version, rest = source.split("\n", 1)
    return f"{version}\n{defines(variant, settings)}{rest}"


class TextureUnits:
    """One texture unit per sampler name, for all of a context's programs, handed out in the
    order the names are first met. pyrender's _bind_texture counts units per draw; one unit
    per name instead means that no program's samplers share a unit (GL forbids it for samplers
    of different types, even unread ones) and a texture bound once for a view serves every
    program that reads it."""

    def __init__(self, limit: int) -> None:
        """``limit``: the first unit not to hand out (moderngl binds textures it creates or
        writes at ctx.default_texture_unit, the last one)."""
        self._limit = limit
        self._units: dict[str, int] = {}

    def unit(self, sampler: str) -> int:
        if sampler not in self._units:
            if len(self._units) >= self._limit:
                raise RuntimeError(f"no texture unit left for {sampler!r}: the programs have "
                                   f"more than {self._limit} sampler names")
            self._units[sampler] = len(self._units)
        return self._units[sampler]

    def wire(self, prog: moderngl.Program, source: str) -> None:
        """Point each sampler that ``source`` declares, and ``prog`` kept, at its unit."""
        for name in _SAMPLER.findall(source):
            uniform = prog.get(name, None)
            if uniform is not None:
                uniform.value = self.unit(name)

    def bind(self, sampler: str, texture: moderngl.Texture) -> None:
        """``texture`` into the unit of ``sampler``."""
        texture.use(self.unit(sampler))


class Programs:
    """A context's programs, each compiled once per set of defines (program_keys)."""

    def __init__(self, ctx: moderngl.Context, units: TextureUnits,
                 settings: dict[str, int] | None = None) -> None:
        """Compile every program and variant with ``settings`` (settings_constants; a GLSL
        error names the files that failed)."""
        self._programs = {key: _compile(ctx, units, *key, settings or {})
                          for key in program_keys()}

    def get(self, name: str, variant: Variant = Variant.NONE) -> moderngl.Program:
        return self._programs[name, variant]

    def keys(self) -> list[ProgramKey]:
        return list(self._programs)

    def variants(self, name: str) -> list[tuple[Variant, moderngl.Program]]:
        """Program ``name``'s variants, the plain form first."""
        return [(v, prog) for (n, v), prog in self._programs.items() if n == name]


def _compile(ctx: moderngl.Context, units: TextureUnits, name: str, variant: Variant,
             settings: dict[str, int]) -> moderngl.Program:
    vert, frag, _ = PROGRAMS[name]
    sources = [with_defines(shader_source(file), variant, settings) for file in (vert, frag)]
    try:
        prog = ctx.program(vertex_shader=sources[0], fragment_shader=sources[1])
    except moderngl.Error as err:
        raise RuntimeError(f"GLSL program {name!r} {variant} ({vert} + {frag}) failed: "
                           f"{err}") from err
    for source in sources:
        units.wire(prog, source)
    return prog
