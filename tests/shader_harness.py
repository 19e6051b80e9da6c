"""Runs GLSL functions alone over a grid of inputs: a fullscreen pass in which each pixel reads
its inputs from float textures (one vec4 per texture), evaluates one GLSL expression and writes
a vec4 into an RGBA32F target, read back as one row per input. The shader unit tests compare
the results with numpy references of the same functions."""

from collections.abc import Callable

import moderngl
import numpy as np

from glsynth.render.gl.context import create_context
from glsynth.render.gl.programs import TextureUnits, defines, shader_source

WIDTH = 64
"""Inputs per row of the grid."""


class GlslHarness:
    """One GL context; ``run`` compiles a program per expression (kept) and evaluates it. The
    library is compiled with the renderer's shared constants (programs.defines), and its
    samplers get their units from ``units`` as the renderer's do."""

    def __init__(self, library: str) -> None:
        """``library``: the shader file whose functions the expressions call."""
        self.ctx, _ = create_context(None)
        self.library = shader_source(library)
        self._programs: dict[tuple[str, int], moderngl.Program] = {}
        # Targets by their rows, kept: moderngl rebinds the framebuffer bound before it when it
        # makes a new one, and a released one is then a GL error.
        self._targets: dict[int, moderngl.Framebuffer] = {}
        self.units = TextureUnits(self.ctx.default_texture_unit)

    def __enter__(self) -> "GlslHarness":
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.ctx.release()

    def _program(self, expression: str, inputs: int) -> moderngl.Program:
        key = (expression, inputs)
        if key not in self._programs:
            samplers = "".join(f"uniform sampler2D u_in{i};\n" for i in range(inputs))
            reads = "".join(f"    vec4 in{i} = texelFetch(u_in{i}, px, 0);\n"
                            for i in range(inputs))
            fragment = (f"#version 330 core\n{defines()}{self.library}\n{samplers}"
                        "out vec4 f_out;\n"
                        "void main() {\n    ivec2 px = ivec2(gl_FragCoord.xy);\n"
                        f"{reads}    f_out = vec4({expression});\n}}\n")
            prog = self.ctx.program(vertex_shader=shader_source("fullscreen.vert"),
                                    fragment_shader=fragment)
            self.units.wire(prog, fragment)
            self._programs[key] = prog
        return self._programs[key]

    def run(self, expression: str, *inputs: np.ndarray,
            setup: Callable[[moderngl.Program], None] | None = None) -> np.ndarray:
        """``expression`` (a vec4, or what vec4() takes) of in0, in1, ... (vec4s: row k of
        each of ``inputs``, (n, 4)) for every k: (n, 4) float32. ``setup(program)`` sets any
        other uniforms and textures (bound by ``units``)."""
        n = len(inputs[0])
        rows = -(-n // WIDTH)
        prog = self._program(expression, len(inputs))
        textures = []
        for unit, values in enumerate(inputs):
            grid = np.zeros((rows * WIDTH, 4), np.float32)
            grid[:n] = values
            texture = self.ctx.texture((WIDTH, rows), 4, grid.tobytes(), dtype="f4")
            texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self.units.bind(f"u_in{unit}", texture)
            textures.append(texture)
        if setup is not None:
            setup(prog)
        if rows not in self._targets:
            self._targets[rows] = self.ctx.framebuffer(
                [self.ctx.texture((WIDTH, rows), 4, dtype="f4")])
        fbo = self._targets[rows]
        fbo.use()
        vao = self.ctx.vertex_array(prog, [])
        vao.render(moderngl.TRIANGLES, vertices=3)
        out = np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32).reshape(-1, 4)[:n]
        for obj in (vao, *textures):
            obj.release()
        assert self.ctx.error == "GL_NO_ERROR"
        return out.copy()
