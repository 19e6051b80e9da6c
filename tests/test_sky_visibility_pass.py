"""The sky-visibility pass draws the depth first and then shades each pixel's nearest surface
once: its targets must be, bit for bit, those of one front-to-back pass that shades every
surface it draws (the pass before the depth pre-pass)."""

import moderngl
import numpy as np
import pytest
from glhelpers import loaded_renderer, render_config

from glsynth.core.config import Config
from glsynth.render.gl.renderer import Renderer
from glsynth.world.cameras import environment_camera

RC = render_config(320, 180)


@pytest.fixture(scope="module")
def loaded(env0):
    with loaded_renderer(env0, RC) as r:
        yield r


def _targets(r: Renderer) -> list[bytes]:
    return [t.read() for t in r.sky_targets]


def _single_pass(r: Renderer, camera, placed) -> list[bytes]:
    """The sky targets as one pass draws them: the parts nearest first, their triangles in
    mesh order, "<" against a cleared depth, every drawn fragment shaded."""
    r.sky_fbo.use()
    r.sky_fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
    r._set_sky_uniforms(camera)
    prog = r.programs.get("sky_visibility")
    prog["u_projection"].write(camera.projection().T.astype("f4").tobytes())
    r.ctx.enable(moderngl.DEPTH_TEST)
    r.ctx.disable(moderngl.CULL_FACE)
    r.ctx.depth_func = "<"
    for item in placed:
        vbo, ibo, _ = item.draw.buffers
        vao = r.ctx.vertex_array(prog, [(vbo, "3f 3f 8x", "in_position", "in_normal")], ibo, 4)
        prog["u_modelview"].write(item.modelview)
        prog["u_normal_matrix"].write(item.normal)
        vao.render()
        vao.release()
    return _targets(r)


@pytest.mark.parametrize("index", [0, 30, 55, 90])
def test_the_depth_pre_pass_keeps_the_sky_targets_to_the_bit(env0, loaded, index):
    camera = environment_camera(env0.trajectory, Config().cameras, RC, 0, 0, index).camera
    placed = loaded._place(camera, loaded._front_to_back(camera))
    assert len(placed) > 1  # parts hide one another
    loaded.make_current()
    loaded._sky_visibility_pass(camera, placed)
    with_pre_pass = _targets(loaded)
    # The pre-pass draws no colour, and the pass leaves every attachment writable again.
    assert loaded.sky_fbo.color_mask == ((True,) * 4,) * len(loaded.sky_targets)
    reference = _single_pass(loaded, camera, placed)
    assert with_pre_pass == reference
    surface = np.frombuffer(with_pre_pass[1], np.float32).reshape(-1, 4)
    assert (surface[:, 3] > 0).mean() > 0.3  # a view mostly of surfaces, not of sky
